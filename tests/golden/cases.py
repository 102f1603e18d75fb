"""The golden cases: every bundled flight under the configurations it is replayed with.

A case is ``(name, input log, configuration name)``; its recorded outputs are
``tests/golden/replays/<name with / as __>.json`` and ``.npz.xz``
(:mod:`tests.golden.record`). The real flights beside the repository
(``../shared/realdata/flights``) are cases too where they are present.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[2]
FIXTURES = ROOT / "sitl_fixtures"
REALDATA = ROOT.parent / "shared" / "realdata" / "flights"

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
FIXTURE_CONFIGS = ("default", "tactical")
"""The configurations every bundled flight is replayed with."""
EXTRA_CASES = (
    ("approach_rtk20", "combine"),
    ("cruise_gnss_loss", "combine"),
    ("cruise_gnss_loss", "singer"),
    ("stale_fix", "passthrough"),
    ("taxi", "combine"),
)
"""Flights replayed with one more configuration (the navigators and the potential filter)."""
REAL_CONFIGS = ("default", "tactical")

Case = tuple[str, Path, str]


def cases() -> list[Case]:
    """(case name, input tlog, configuration name) for every bundled fixture."""
    out = []
    for tlog in sorted(FIXTURES.glob("*.tlog")):
        for cfg in FIXTURE_CONFIGS:
            out.append((f"{tlog.stem}/{cfg}", tlog, cfg))
    for stem, cfg in EXTRA_CASES:
        out.append((f"{stem}/{cfg}", FIXTURES / f"{stem}.tlog", cfg))
    return out


def realdata_cases() -> list[Case]:
    """The same for the real flights beside the repository, where they are."""
    if not REALDATA.is_dir():
        return []
    return [
        (f"real/{tlog.stem}/{cfg}", tlog, cfg)
        for tlog in sorted(REALDATA.glob("*/*.tlog"))
        for cfg in REAL_CONFIGS
    ]


def config_for(name: str, **changes: dict[str, Any]) -> Any:
    """The :class:`companion.config.Config` of a configuration name, with ``changes``
    (``{block: {key: value}}``) applied on top of it."""
    from companion.config import Config, load_config

    path, overrides = CONFIGS[name]
    config = load_config(path) if path is not None else Config()
    for block, values in list(overrides.items()) + list(changes.items()):
        config = dataclasses.replace(
            config, **{block: dataclasses.replace(getattr(config, block), **values)}
        )
    return config


def file_stem(name: str) -> str:
    """A case's name as a file name: ``nominal/default`` -> ``nominal__default``."""
    return name.replace("/", "__")
