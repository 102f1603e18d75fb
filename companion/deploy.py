"""The files a companion computer needs beside the package, shipped in it as package data.

``companion/systemd/companion.service`` (the systemd unit) and
``companion/systemd/companion.toml`` (the example configuration: ``companion
config-template`` output) are read with :mod:`importlib.resources`, so they are there
however the package was installed (wheel, editable, source tree). ``companion
install-unit`` prints or writes the unit with its ``ExecStart`` pointed at the
installation it runs from. The steps for a Raspberry Pi or a Jetson: ``docs/deploy.md``.
"""

from __future__ import annotations

import sys
from importlib import resources
from pathlib import Path

UNIT_NAME = "companion.service"
"""File name of the systemd unit (in the package and once installed)."""
EXAMPLE_CONFIG_NAME = "companion.toml"
"""File name of the example configuration in the package."""
PACKAGED_EXECUTABLE = "/opt/companion/venv/bin/companion"
"""The ``companion`` executable the packaged unit names (the layout docs/deploy.md uses)."""
SYSTEMD_UNIT_DIR = Path("/etc/systemd/system")
"""Where ``companion install-unit`` writes the unit by default."""


def packaged_text(name: str) -> str:
    """The text of one file of the package's ``systemd`` folder (FileNotFoundError if absent)."""
    return (resources.files("companion") / "systemd" / name).read_text(encoding="utf-8")


def installed_executable() -> str | None:
    """The ``companion`` script of the environment this interpreter runs in, if it has one
    (a venv's ``bin/companion`` beside its ``python``)."""
    candidate = Path(sys.executable).parent / "companion"
    return str(candidate) if candidate.is_file() else None


def unit_text(executable: str | None = None) -> str:
    """The systemd unit, its ``ExecStart`` running ``executable`` (``None``: as packaged,
    :data:`PACKAGED_EXECUTABLE`)."""
    text = packaged_text(UNIT_NAME)
    if executable is None or executable == PACKAGED_EXECUTABLE:
        return text
    if any(c.isspace() for c in executable):
        raise ValueError(f"the executable path must not contain white space: {executable!r}")
    return text.replace(f"ExecStart={PACKAGED_EXECUTABLE} ", f"ExecStart={executable} ")


def install_unit(directory: Path, executable: str | None = None) -> Path:
    """Write the unit into ``directory`` (normally :data:`SYSTEMD_UNIT_DIR`); its path.

    Raises ValueError with one line when the folder cannot be written (not root, missing).
    """
    path = Path(directory) / UNIT_NAME
    try:
        path.write_text(unit_text(executable), encoding="utf-8")
    except OSError as exc:
        raise ValueError(f"cannot write {path}: {exc.strerror}") from None
    path.chmod(0o644)
    return path
