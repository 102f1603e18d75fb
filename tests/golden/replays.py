"""Replay every golden case and compare its outputs with the recorded ones; record again.

    python -m tests.golden.replays               # compare: per case the largest difference
    python -m tests.golden.replays --record      # the same, then record what moved or is new
    python -m tests.golden.replays -k taxi -k nominal/default   # only the cases named so

Each case (:mod:`tests.golden.cases`) is replayed with the code of this checkout and its
outputs compared with ``tests/golden/replays/<case>.*`` by the rules of
:mod:`tests.golden.rules`. One line per case: ``same`` (no value differs), ``agrees``
(within tolerance; the largest difference relative to its tolerance), ``MOVED`` (beyond:
the largest differences, field by field) or ``new``. ``--record`` then writes the cases
that moved or are new, and only those: a case within tolerance keeps its reference.
Record after a change of the outputs that is meant, once this listing has shown that
what moved is what the change should move; say so in the commit.
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
from pathlib import Path
from typing import Any

from tests.golden import cases as golden_cases
from tests.golden.compare import Difference, compare, failures
from tests.golden.record import ReplayRecord, files_of, from_output, load, save, summary_dict

GOLDEN_DIR = Path(__file__).with_name("replays")
"""Where the recorded outputs are."""


def _relative(path: str | None) -> str | None:
    if path is None:
        return None
    for base in (golden_cases.ROOT, golden_cases.REALDATA.parent):
        try:
            return str(Path(path).resolve().relative_to(base))
        except ValueError:
            continue
    return Path(path).name


def evaluation_dict(out_tlog: Path, truth_csv: Path) -> dict[str, Any]:
    """``companion evaluate``'s figures (its JSON) without the paths of this machine."""
    from companion.evaluate import evaluate

    figures = evaluate(out_tlog, truth_csv).to_dict()
    figures.pop("out_tlog", None)
    for key in ("truth_csv", "events_json"):
        figures[key] = _relative(figures.get(key))
    return json.loads(json.dumps(figures))


def replay_case(
    name: str, tlog: Path, cfg: str, **changes: dict[str, Any]
) -> tuple[ReplayRecord, bytes]:
    """Replay one case (its configuration with ``changes``, ``{block: {key: value}}``);
    its record and the output tlog's bytes. A bundled flight replayed with the defaults
    is evaluated against its truth too."""
    from companion.replay import replay

    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "out.tlog"
        summary = replay(tlog, out, golden_cases.config_for(cfg, **changes))
        truth = tlog.with_suffix(".truth.csv")
        evaluation = evaluation_dict(out, truth) if cfg == "default" and truth.exists() else None
        record = from_output(
            out,
            case=name,
            input=_relative(str(tlog)),
            config=cfg,
            changes=changes,
            summary=summary_dict(summary),
            evaluation=evaluation,
        )
        return record, out.read_bytes()


def recorded(name: str) -> ReplayRecord | None:
    """The recorded outputs of a case, None if it has none."""
    return load(GOLDEN_DIR, golden_cases.file_stem(name))


def check(name: str, tlog: Path, cfg: str) -> tuple[ReplayRecord, list[Difference]]:
    """Replay a case and compare it with its record: its new record and the differences
    (empty also when it has no record: see :func:`recorded`)."""
    new, _ = replay_case(name, tlog, cfg)
    ref = recorded(name)
    return new, ([] if ref is None else compare(ref, new))


def golden_size_bytes() -> int:
    """The size of the recorded outputs on disk."""
    return sum(p.stat().st_size for p in GOLDEN_DIR.glob("*") if p.is_file())


def _stale(names: set[str]) -> list[Path]:
    """Recorded files of cases that no longer exist (a real flight's only when the real
    flights are here to say so)."""
    stems = {golden_cases.file_stem(n) for n in names}
    real_here = golden_cases.REALDATA.is_dir()
    out = []
    for path in sorted(GOLDEN_DIR.glob("*.json")):
        stem = path.name.removesuffix(".json")
        if stem not in stems and (real_here or not stem.startswith("real__")):
            out += [p for p in files_of(GOLDEN_DIR, stem) if p.exists()]
    return out


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--record", action="store_true", help="record what moved or is new")
    parser.add_argument(
        "-k", action="append", default=[], metavar="TEXT", help="only cases whose name has TEXT"
    )
    parser.add_argument("--show", type=int, default=5, help="fields listed per moved case")
    args = parser.parse_args(argv)
    every = golden_cases.cases() + golden_cases.realdata_cases()
    chosen = [c for c in every if not args.k or any(k in c[0] for k in args.k)]
    to_write: list[tuple[str, ReplayRecord]] = []
    moved = 0
    for name, tlog, cfg in chosen:
        ref = recorded(name)
        new, _ = replay_case(name, tlog, cfg)
        if ref is None:
            print(f"new      {name}", flush=True)
            to_write.append((name, new))
            continue
        differences = compare(ref, new)
        bad = failures(differences)
        if not differences:
            print(f"same     {name}", flush=True)
        elif not bad:
            print(f"agrees   {name}: largest {differences[0].describe()}", flush=True)
        else:
            moved += 1
            to_write.append((name, new))
            print(f"MOVED    {name}: {len(bad)} beyond tolerance", flush=True)
            for d in bad[: args.show]:
                print(f"    {d.describe()}")
            if len(bad) > args.show:
                print(f"    ... {len(bad) - args.show} more")
    stale = _stale({c[0] for c in every}) if not args.k else []
    for path in stale:
        print(f"stale    {path.name}")
    print(
        f"{len(chosen)} cases: {moved} moved, {sum(recorded(n) is None for n, _ in to_write)} new"
    )
    if not args.record:
        return 1 if moved else 0
    for name, record in to_write:
        save(record, GOLDEN_DIR, golden_cases.file_stem(name))
    for path in stale:
        path.unlink()
    print(
        f"recorded {len(to_write)} case(s), removed {len(stale)} stale file(s); "
        f"{GOLDEN_DIR} holds {golden_size_bytes() / 1e6:.2f} MB"
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
