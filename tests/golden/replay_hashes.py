"""SHA-256 of the replay of every bundled flight under a set of configurations.

The restructuring of the package must not change an estimate, an alert or a byte
of a replay: ``tests/test_replay_hashes.py`` replays every case below and compares
the output's hash with the one recorded in ``replay_hashes.json`` before the code
was moved. Record again only after ``bench/compare_replays.py`` has shown that a
change of the outputs is intended (or that a new numpy changed the last bits):

    python -m tests.golden.replay_hashes --record
"""

from __future__ import annotations

import argparse
import dataclasses
import hashlib
import json
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
FIXTURES = ROOT / "sitl_fixtures"
REALDATA = ROOT.parent / "shared" / "realdata" / "flights"
HASHES = Path(__file__).with_name("replay_hashes.json")

# configuration name -> (TOML file or None, {block: {key: value}} overrides)
CONFIGS: dict[str, tuple[Path | None, dict[str, dict[str, object]]]] = {
    "default": (None, {}),
    "tactical": (FIXTURES / "tactical.toml", {}),
    "combine": (
        FIXTURES / "tactical.toml",
        {"engine": {"potential_combine": True, "potential_fix_test": True}},
    ),
    "singer": (None, {"engine": {"navigator": "singer"}}),
    "passthrough": (None, {"engine": {"navigator": "passthrough"}}),
}
# which configurations each flight is replayed with
FIXTURE_CONFIGS = ("default", "tactical")
EXTRA_CASES = (
    ("approach_rtk20", "combine"),
    ("cruise_gnss_loss", "combine"),
    ("cruise_gnss_loss", "singer"),
    ("stale_fix", "passthrough"),
    ("taxi", "combine"),
)


def cases() -> list[tuple[str, Path, str]]:
    """(case name, input tlog, configuration name) for every bundled fixture."""
    out = []
    for tlog in sorted(FIXTURES.glob("*.tlog")):
        for cfg in FIXTURE_CONFIGS:
            out.append((f"{tlog.stem}/{cfg}", tlog, cfg))
    for stem, cfg in EXTRA_CASES:
        out.append((f"{stem}/{cfg}", FIXTURES / f"{stem}.tlog", cfg))
    return out


def realdata_cases() -> list[tuple[str, Path, str]]:
    """The same for the real flights beside the repository, where they are."""
    if not REALDATA.is_dir():
        return []
    return [
        (f"real/{tlog.stem}/{cfg}", tlog, cfg)
        for tlog in sorted(REALDATA.glob("*/*.tlog"))
        for cfg in ("default", "tactical")
    ]


def config_for(name: str):  # -> Config
    from companion.config import Config, load_config

    path, overrides = CONFIGS[name]
    config = load_config(path) if path is not None else Config()
    for block, values in overrides.items():
        config = dataclasses.replace(
            config, **{block: dataclasses.replace(getattr(config, block), **values)}
        )
    return config


def _sha(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()


def replay_hash(tlog: Path, cfg: str) -> str:
    """Replay ``tlog`` with configuration ``cfg``; the SHA-256 of the output tlog, and
    for a bundled flight with its defaults also of its evaluation against the truth."""
    from companion.replay import replay

    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "out.tlog"
        summary = replay(tlog, out, config_for(cfg))
        parts = [out.read_bytes(), summary.to_text().split("\n", 1)[1].encode()]
        truth = tlog.with_suffix(".truth.csv")
        if cfg == "default" and truth.exists():
            from companion.evaluate import evaluate

            evaluation = evaluate(out, truth)
            for text in (evaluation.to_text(), json.dumps(evaluation.to_dict(), sort_keys=True)):
                text = text.replace(str(out), "OUT").replace(str(FIXTURES), "FIXTURES")
                parts.append(text.encode())
        return _sha(b"\0".join(parts))


def other_hashes() -> dict[str, str]:
    """Three simulated flights (tlog, truth, sidecar)."""
    from companion import sim

    found = {}
    for scenario in ("approach_rtk20", "px4_rotorcraft", "taxi"):
        with tempfile.TemporaryDirectory() as tmp:
            paths = sim.write_scenario(scenario, Path(tmp), seed=3, duration_s=60.0)
            found[f"simulate/{scenario}"] = _sha(
                b"\0".join(Path(p).read_bytes() for p in sorted(paths))
            )
    return found


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--record", action="store_true", help="write replay_hashes.json")
    args = parser.parse_args()
    recorded = json.loads(HASHES.read_text()) if HASHES.exists() else {}
    found = {}
    bad = 0
    for name, tlog, cfg in cases() + realdata_cases():
        h = replay_hash(tlog, cfg)
        found[name] = h
        state = "same" if recorded.get(name) == h else ("new" if name not in recorded else "DIFF")
        bad += state == "DIFF"
        print(f"{state:5s} {name}", flush=True)
    for name, h in other_hashes().items():
        found[name] = h
        state = "same" if recorded.get(name) == h else ("new" if name not in recorded else "DIFF")
        bad += state == "DIFF"
        print(f"{state:5s} {name}", flush=True)
    if args.record:
        HASHES.write_text(json.dumps(found, indent=1, sort_keys=True) + "\n")
        print(f"recorded {len(found)} hashes in {HASHES}")
    return 1 if bad and not args.record else 0


if __name__ == "__main__":
    sys.exit(main())
