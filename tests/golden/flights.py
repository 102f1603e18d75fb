"""A simulated flight flown again today compared with the committed fixture.

    python -m tests.golden.flights                 # fly the compared fixtures, compare
    python -m tests.golden.flights --record        # the same, then write what moved
    python -m tests.golden.flights -k taxi         # only those whose name has "taxi"

``companion simulate <name> --seed 1`` writes three files; each is compared with the
one in ``sitl_fixtures/`` by the rules of :mod:`tests.golden.rules`:

* the ``.tlog`` message by message (the same types in the same order, record times
  within a microsecond, every field by its rule: integers within a unit, floats within
  a relative ``FLOAT_REL_TOL``);
* the ``.truth.csv`` row by row and column by column: the same header, words and
  number of decimals, each number within one unit of its last printed digit;
* the ``.json`` sidecar: the same keys and words, its numbers within ``JSON_REL_TOL``.

``--record`` writes the flights that moved into ``sitl_fixtures/`` (after a change of
the simulator that is meant; the replays of those fixtures then move too:
``python -m tests.golden.replays --record``).
"""

from __future__ import annotations

import argparse
import json
import math
import shutil
import sys
import tempfile
from pathlib import Path

from tests.golden import rules
from tests.golden.cases import FIXTURES
from tests.golden.compare import Difference, compare_messages, failures

COMPARED = (
    "approach_rtk20",
    "px4_rotorcraft",
    "taxi",
    "taxi_realistic",
    "approach_rtk20_realistic",
    "cruise_gnss_loss_realistic",
    "nominal_realistic",
    "copter_realistic",
    "copter_radio_realistic",
    "px4_rotorcraft_realistic",
)
"""The fixtures flown again by the tests: every realistic one (their streams have no
fixed message count) and three plain ones, an ArduPilot plane's approach and taxi and a
PX4 multirotor."""
EXTENSIONS = (".tlog", ".truth.csv", ".json")


def compare_tlog(ref: Path, new: Path) -> list[Difference]:
    """Two tlogs message by message (:func:`tests.golden.compare.compare_messages`)."""
    from companion.mavlink.readback import read_tlog

    return compare_messages(read_tlog(ref).records, read_tlog(new).records)


def compare_truth(ref: list[str], new: list[str]) -> list[Difference]:
    """Two truth CSVs (lines) column by column; ``t_s`` of the row says when."""
    if len(ref) != len(new) or not ref or ref[0] != new[0]:
        first = next((i for i, (a, b) in enumerate(zip(ref, new, strict=False)) if a != b), None)
        where = "truth rows" if first is None else f"truth row {first}"
        return [Difference(where, None, len(ref), len(new), math.inf)]
    header = ref[0].split(",")
    worst: dict[str, Difference] = {}
    beyond: dict[str, int] = {}
    for row_a, row_b in zip(ref[1:], new[1:], strict=True):
        if row_a == row_b:
            continue
        cells_a, cells_b = row_a.split(","), row_b.split(",")
        t_s = float(cells_a[0])
        if len(cells_a) != len(cells_b):
            return [Difference("truth row", t_s, row_a, row_b, math.inf)]
        for col, a, b in zip(header, cells_a, cells_b, strict=True):
            ok, size = rules.texts_agree(a, b)
            excess = size if ok else math.inf
            if excess == 0.0:
                continue
            where = f"truth.{col}"
            beyond[where] = beyond.get(where, 0) + (excess > 1.0)
            if where not in worst or excess > worst[where].excess:
                worst[where] = Difference(where, t_s, a, b, excess, note="units of the last digit")
    n = len(ref) - 1
    return sorted(
        (
            Difference(d.where, d.t_s, d.ref, d.new, d.excess, beyond[w], n, d.note)
            for w, d in worst.items()
        ),
        key=lambda d: -d.excess,
    )


def compare_sidecar(ref: dict[str, object], new: dict[str, object]) -> list[Difference]:
    """Two JSON sidecars by :func:`tests.golden.rules.json_agree`."""
    return [
        Difference(f"json.{path}", None, a, b, excess)
        for path, a, b, excess in rules.json_agree(ref, new)
    ]


def compare_flight(ref_dir: Path, new_dir: Path, name: str) -> list[Difference]:
    """The three files of flight ``name`` in ``new_dir`` against those in ``ref_dir``."""
    out = compare_tlog(ref_dir / f"{name}.tlog", new_dir / f"{name}.tlog")
    out += compare_truth(
        (ref_dir / f"{name}.truth.csv").read_text().splitlines(),
        (new_dir / f"{name}.truth.csv").read_text().splitlines(),
    )
    out += compare_sidecar(
        json.loads((ref_dir / f"{name}.json").read_text()),
        json.loads((new_dir / f"{name}.json").read_text()),
    )
    return sorted(out, key=lambda d: -d.excess)


def fly(name: str, out_dir: Path) -> None:
    """``companion simulate <name> --out <out_dir> --seed 1``, as the fixture was made."""
    from companion import sim

    sim.write_scenario(name, out_dir, seed=1)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--record", action="store_true", help="write what moved")
    parser.add_argument("-k", action="append", default=[], metavar="TEXT")
    parser.add_argument("--all", action="store_true", help="every committed fixture")
    args = parser.parse_args(argv)
    names = sorted(p.name.removesuffix(".json") for p in FIXTURES.glob("*.json"))
    chosen = [
        n for n in (names if args.all else COMPARED) if not args.k or any(k in n for k in args.k)
    ]
    moved = []
    with tempfile.TemporaryDirectory() as tmp:
        for name in chosen:
            fly(name, Path(tmp))
            differences = compare_flight(FIXTURES, Path(tmp), name)
            bad = failures(differences)
            if not differences:
                print(f"same     {name}", flush=True)
            elif not bad:
                print(f"agrees   {name}: largest {differences[0].describe()}", flush=True)
            else:
                moved.append(name)
                print(f"MOVED    {name}: {len(bad)} beyond tolerance", flush=True)
                for d in bad[:5]:
                    print(f"    {d.describe()}")
            if args.record and name in moved:
                for ext in EXTENSIONS:
                    shutil.copyfile(Path(tmp) / f"{name}{ext}", FIXTURES / f"{name}{ext}")
                print(f"recorded {name} in {FIXTURES}")
    return 1 if moved and not args.record else 0


if __name__ == "__main__":
    sys.exit(main())
