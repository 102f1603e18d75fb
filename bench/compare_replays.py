"""Compare the replays of every fixture between two versions of the code.

    python bench/compare_replays.py --replay OUT_DIR      # replay every fixture into OUT_DIR
    python bench/compare_replays.py REF_DIR NEW_DIR       # compare two such directories
    python bench/compare_replays.py REF_DIR NEW_DIR --added NAMED_VALUE_FLOAT:CMP_HDGS

``--replay`` runs ``companion.replay.replay`` on each ``sitl_fixtures/*.tlog``
(``approach_rtk20`` with ``sitl_fixtures/tactical.toml``, as its README says),
writing ``OUT_DIR/<fixture>.tlog``. Run it once with the reference code and
once with the changed code (e.g. from two checkouts), then compare.

The comparison, per fixture: byte-identical output files pass at once. Otherwise both
are read back and compared as the golden replay test compares a replay with its
recorded outputs (``tests/golden/record.py``, ``tests/golden/compare.py``), by the same
rules (``tests/golden/rules.py``: positions to their resolution or 1 % of their published
1-sigma, accuracies and other floats to a relative 1e-5, alerts and texts within two
samples, counts exactly). Prints a table with each fixture's largest difference relative
to its tolerance; exits 1 if one is beyond. (``python -m tests.golden.replays`` compares
this checkout's replays with the recorded ones directly.)

``--added TYPE[:PREFIX]`` (repeatable) names messages the new code adds on purpose
(a new status value, a new alert): those of the new replay, of that type and whose
text field (NAMED_VALUE_FLOAT's name, STATUSTEXT's text) starts with PREFIX, are
counted and left out before the comparison, so that the rest must still agree.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from tests.golden.compare import compare, failures  # noqa: E402
from tests.golden.record import from_output  # noqa: E402

FIXTURES = ROOT / "sitl_fixtures"
CONFIGS = {"approach_rtk20": FIXTURES / "tactical.toml"}
"""Fixtures replayed with a configuration file (the rest with the defaults)."""
_SKIP_FIELDS = frozenset({"mavpackettype"})


def replay_all(out_dir: Path) -> None:
    """Replay every fixture with the code importable from this checkout into ``out_dir``."""
    from companion.config import Config, load_config
    from companion.replay import replay

    out_dir.mkdir(parents=True, exist_ok=True)
    for tlog in sorted(FIXTURES.glob("*.tlog")):
        cfg_path = CONFIGS.get(tlog.stem)
        config = load_config(cfg_path) if cfg_path is not None else Config()
        print(f"replaying {tlog.name} ...", file=sys.stderr, flush=True)
        t0 = time.perf_counter()
        summary = replay(tlog, out_dir / tlog.name, config)
        print(
            f"  {summary.messages_in} in, {summary.messages_out} out, "
            f"{time.perf_counter() - t0:.1f} s",
            file=sys.stderr,
            flush=True,
        )


def _is_added(msg: Any, added: tuple[str, ...]) -> bool:
    """``msg`` matches one of the ``TYPE[:PREFIX]`` patterns of ``--added``."""
    for pattern in added:
        kind, _, prefix = pattern.partition(":")
        if msg.get_type() != kind:
            continue
        fields = msg.to_dict().items()
        texts = [v for k, v in fields if isinstance(v, str) and k not in _SKIP_FIELDS]
        if not prefix or any(t.startswith(prefix) for t in texts):
            return True
    return False


def compare_file(ref: Path, new: Path, added: tuple[str, ...] = ()) -> tuple[str, int, list[Any]]:
    """Verdict (``identical``, ``agrees`` or ``DIFFERS``), the number of messages of ``new``
    left out as ``added``, and the differences (largest first)."""
    if ref.read_bytes() == new.read_bytes():
        return "identical", 0, []
    n_added = 0

    def keep(msg: Any) -> bool:
        nonlocal n_added
        if added and _is_added(msg, added):
            n_added += 1
            return False
        return True

    differences = compare(from_output(ref), from_output(new, keep=keep))
    return ("DIFFERS" if failures(differences) else "agrees"), n_added, differences


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("dirs", nargs="*", type=Path, help="REF_DIR NEW_DIR")
    parser.add_argument("--replay", type=Path, help="replay every fixture into this directory")
    parser.add_argument(
        "--added",
        action="append",
        default=[],
        metavar="TYPE[:PREFIX]",
        help="messages the new code adds on purpose: left out of NEW_DIR before comparing",
    )
    args = parser.parse_args()
    if args.replay is not None:
        replay_all(args.replay)
        if not args.dirs:
            return 0
    if len(args.dirs) != 2:
        parser.error("give REF_DIR and NEW_DIR (or --replay OUT_DIR)")
    ref_dir, new_dir = args.dirs
    failing = 0
    print(f"{'fixture':<28} {'verdict':<10} {'differing':>9} {'beyond':>7}  largest difference")
    for ref in sorted(ref_dir.glob("*.tlog")):
        new = new_dir / ref.name
        if not new.exists():
            print(f"{ref.stem:<28} MISSING")
            failing += 1
            continue
        print(f"comparing {ref.name} ...", file=sys.stderr, flush=True)
        verdict, n_added, differences = compare_file(ref, new, tuple(args.added))
        failing += verdict == "DIFFERS"
        bad = failures(differences)
        largest = differences[0].describe() if differences else ""
        print(f"{ref.stem:<28} {verdict:<10} {len(differences):>9} {len(bad):>7}  {largest}")
        if n_added:
            print(f"    {n_added} added messages left out ({', '.join(args.added)})")
        for d in bad[1:6]:
            print(f"    {d.describe()}")
    print(f"{failing} fixture(s) beyond tolerance")
    return 1 if failing else 0


if __name__ == "__main__":
    sys.exit(main())
