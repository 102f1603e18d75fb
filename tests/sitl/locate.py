"""Where the autopilot simulators are: ``$COMPANION_SITL_DIR`` or ``../shared/sitl`` beside
the project, holding ``private-net`` and the SITL binaries (``arduplane``, ``arducopter``,
``px4/``). Imported by the pytest configuration and by the scenario runners."""

from __future__ import annotations

import os
import shutil
from pathlib import Path
from typing import Any

PROJECT_ROOT = Path(__file__).resolve().parents[2]
ENV_VAR = "COMPANION_SITL_DIR"
DEFAULT_DIR = PROJECT_ROOT.parent / "shared" / "sitl"


def sitl_dir() -> Path:
    """The simulators' folder (it may not exist)."""
    env = os.environ.get(ENV_VAR)
    return Path(env) if env else DEFAULT_DIR


def missing(*binaries: str) -> str | None:
    """Why the SITL tests needing ``binaries`` (paths inside :func:`sitl_dir`) cannot run,
    or None when they can."""
    folder = sitl_dir()
    where = f"{folder} (set {ENV_VAR} to another folder)"
    if not folder.is_dir():
        return f"no autopilot simulators at {where}"
    for name in ("private-net", *binaries):
        path = folder / name
        if not (path.is_file() and os.access(path, os.X_OK)):
            return f"{name} not found (or not executable) in {where}"
    if shutil.which("unshare") is None:
        return "unshare (util-linux) not found: private-net needs it"
    if hasattr(os, "geteuid") and os.geteuid() != 0:
        return "private-net needs root (a private network namespace)"
    return None


def skip_unless(*binaries: str) -> Any:
    """A pytest ``skipif`` mark: skipped, with the reason, when :func:`missing` says so."""
    import pytest

    reason = missing(*binaries)
    return pytest.mark.skipif(reason is not None, reason=reason or "")
