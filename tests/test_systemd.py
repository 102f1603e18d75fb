"""The systemd unit: verified by systemd-analyze where it is available."""

from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
UNIT = ROOT / "companion" / "systemd" / "companion.service"


def test_unit_has_the_promised_settings():
    text = UNIT.read_text()
    for line in (
        "Type=notify",
        "WatchdogSec=",
        "Restart=on-failure",
        "User=companion",
        "SupplementaryGroups=dialout",
        "NoNewPrivileges=yes",
        "ProtectSystem=strict",
        "PrivateTmp=yes",
    ):
        assert line in text, line


@pytest.mark.skipif(shutil.which("systemd-analyze") is None, reason="systemd-analyze not installed")
def test_systemd_analyze_verify_is_clean(tmp_path):
    # verify needs the ExecStart binary to exist: point it at this interpreter's script
    exe = Path(sys.executable).parent / "companion"
    if not exe.exists():
        exe = Path(shutil.which("companion") or sys.executable)
    unit = tmp_path / "companion.service"
    unit.write_text(UNIT.read_text().replace("/opt/companion/venv/bin/companion", str(exe)))
    out = subprocess.run(
        ["systemd-analyze", "verify", str(unit)], capture_output=True, text=True, timeout=60
    )
    problems = [
        line
        for line in (out.stdout + out.stderr).splitlines()
        if "companion.service" in line and "Documentation" not in line
    ]
    assert out.returncode == 0 and not problems, out.stdout + out.stderr
