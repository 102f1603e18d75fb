"""Compare the replays of every fixture between two versions of the code.

    python bench/compare_replays.py --replay OUT_DIR      # replay every fixture into OUT_DIR
    python bench/compare_replays.py REF_DIR NEW_DIR       # compare two such directories
    python bench/compare_replays.py REF_DIR NEW_DIR --added NAMED_VALUE_FLOAT:CMP_HDGS

``--replay`` runs ``companion.replay.replay`` on each ``sitl_fixtures/*.tlog``
(``approach_rtk20`` with ``sitl_fixtures/tactical.toml``, as its README says),
writing ``OUT_DIR/<fixture>.tlog``. Run it once with the reference code and
once with the changed code (e.g. from two checkouts), then compare.

The comparison, per fixture: byte-identical output files pass at once.
Otherwise both are read (``companion.mavlink.tlog.TlogReader``) and compared message by message
(same count, types, order and record times); each field must agree to the
resolution MAVLink gives it:

* integer fields (1e-7 deg, mm, cm/s, cdeg ...) exactly, or by one least
  significant unit: a *rounding-boundary flip* (the value sat within a
  rounding error of a half unit), counted and reported;
* float32 fields to a relative 1e-5 or an absolute 1e-6 (NAMED_VALUE_FLOAT
  accuracies, GPS_INPUT accuracies and velocities), counted when not bit-equal;
* text fields (STATUSTEXT) exactly, except numbers in them, which may differ
  in their last printed digit (counted).

Anything else is a failure. Prints a table; exits 1 on any failure.

``--added TYPE[:PREFIX]`` (repeatable) names messages the new code adds on purpose
(a new status value, a new alert): those of the new replay, of that type and whose
text field (NAMED_VALUE_FLOAT's name, STATUSTEXT's text) starts with PREFIX, are
counted and left out before the comparison, so that the rest must still agree.
"""

from __future__ import annotations

import argparse
import math
import re
import sys
import time
from collections import Counter
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parent.parent
FIXTURES = ROOT / "sitl_fixtures"
CONFIGS = {"approach_rtk20": FIXTURES / "tactical.toml"}
"""Fixtures replayed with a configuration file (the rest with the defaults)."""
FLOAT_REL_TOL = 1e-5
"""float32 fields: relative agreement required (float32 itself resolves 6e-8)."""
FLOAT_ABS_TOL = 1e-6
"""float32 fields: absolute agreement that always suffices (m, m/s: far below the mm and
cm/s resolution of the integer position and velocity fields)."""
_NUMBER_RE = re.compile(r"-?\d+(?:\.\d+)?")
_SKIP_FIELDS = frozenset({"mavpackettype"})


def replay_all(out_dir: Path) -> None:
    """Replay every fixture with the code importable from this checkout into ``out_dir``."""
    sys.path.insert(0, str(ROOT))
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


def _records(path: Path) -> list[tuple[float, Any]]:
    """``(record time, pymavlink message)`` of every record, with the service's tlog reader."""
    sys.path.insert(0, str(ROOT))
    from companion.mavlink.tlog import TlogReader

    return list(TlogReader(path))


def _compare_values(a: Any, b: Any, stats: Counter[str]) -> bool:
    """True if ``a`` and ``b`` agree to MAVLink resolution; counts the kind of agreement."""
    if isinstance(a, (list, tuple)):
        if not isinstance(b, (list, tuple)) or len(a) != len(b):
            return False
        return all(_compare_values(x, y, stats) for x, y in zip(a, b, strict=True))
    if isinstance(a, bool) or isinstance(b, bool):
        return a == b
    if isinstance(a, int) and isinstance(b, int):
        if a == b:
            return True
        if abs(a - b) == 1:
            stats["int_lsb_flips"] += 1
            return True
        return False
    if isinstance(a, float) and isinstance(b, float):
        if a == b or (math.isnan(a) and math.isnan(b)):
            return True
        if abs(a - b) <= max(FLOAT_REL_TOL * max(abs(a), abs(b)), FLOAT_ABS_TOL):
            stats["float_within_tol"] += 1
            return True
        return False
    if isinstance(a, (str, bytes)) and isinstance(b, (str, bytes)):
        if a == b:
            return True
        sa, sb = str(a), str(b)
        if _NUMBER_RE.sub("#", sa) != _NUMBER_RE.sub("#", sb):
            return False
        for x, y in zip(_NUMBER_RE.findall(sa), _NUMBER_RE.findall(sb), strict=True):
            if x == y:
                continue
            decimals = len(x.split(".")[1]) if "." in x else 0
            if abs(float(x) - float(y)) > 1.0001 * 10.0**-decimals:
                return False
        stats["text_last_digit"] += 1
        return True
    return bool(a == b)


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


def compare_file(
    ref: Path, new: Path, added: tuple[str, ...] = ()
) -> tuple[str, Counter[str], list[str]]:
    """Verdict (``identical``, ``agrees`` or ``DIFFERS``), counts and the first problems;
    messages of ``new`` matching ``added`` are counted (``added``) and left out."""
    if ref.read_bytes() == new.read_bytes():
        return "identical", Counter(), []
    stats: Counter[str] = Counter()
    problems: list[str] = []
    a_recs, b_recs = _records(ref), _records(new)
    if added:
        kept = [(t, m) for t, m in b_recs if not _is_added(m, added)]
        stats["added"] = len(b_recs) - len(kept)
        b_recs = kept
    if len(a_recs) != len(b_recs):
        problems.append(f"message count {len(a_recs)} vs {len(b_recs)}")
    for i, ((ta, ma), (tb, mb)) in enumerate(zip(a_recs, b_recs, strict=False)):
        if ma.get_type() != mb.get_type() or abs(ta - tb) > 1e-6:
            problems.append(f"record {i}: {ma.get_type()}@{ta:.6f} vs {mb.get_type()}@{tb:.6f}")
            break
        stats["messages"] += 1
        da, db = ma.to_dict(), mb.to_dict()
        if da == db:
            continue
        stats["messages_differing"] += 1
        for key, va in da.items():
            if key in _SKIP_FIELDS:
                continue
            if not _compare_values(va, db.get(key), stats):
                stats["fields_failing"] += 1
                if len(problems) < 10:
                    problems.append(f"record {i} {ma.get_type()}.{key}: {va!r} vs {db.get(key)!r}")
    ok = not problems and stats["fields_failing"] == 0
    return ("agrees" if ok else "DIFFERS"), stats, problems


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
    failures = 0
    header = f"{'fixture':<20} {'verdict':<10} {'messages':>9} {'differing':>10}"
    print(f"{header} {'int LSB flips':>14} {'float~':>7} {'text~':>6}")
    totals: Counter[str] = Counter()
    for ref in sorted(ref_dir.glob("*.tlog")):
        new = new_dir / ref.name
        if not new.exists():
            print(f"{ref.stem:<20} MISSING")
            failures += 1
            continue
        print(f"comparing {ref.name} ...", file=sys.stderr, flush=True)
        verdict, stats, problems = compare_file(ref, new, tuple(args.added))
        totals.update(stats)
        failures += verdict == "DIFFERS"
        print(
            f"{ref.stem:<20} {verdict:<10} {stats['messages']:>9} "
            f"{stats['messages_differing']:>10} {stats['int_lsb_flips']:>14} "
            f"{stats['float_within_tol']:>7} {stats['text_last_digit']:>6}"
        )
        if stats["added"]:
            print(f"    {stats['added']} added messages left out ({', '.join(args.added)})")
        for p in problems:
            print(f"    {p}")
    print(
        f"total: {totals['int_lsb_flips']} integer rounding-boundary flips, "
        f"{totals['float_within_tol']} float32 fields within {FLOAT_REL_TOL:g}, "
        f"{totals['text_last_digit']} texts differing in a last digit; "
        f"{failures} fixture(s) failing"
    )
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
