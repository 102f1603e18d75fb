"""Packaging for a companion computer: matplotlib is an optional extra, the systemd unit and
the example configuration are package data, ``companion install-unit`` writes the unit."""

from __future__ import annotations

import ast
import stat
import subprocess
import sys
from pathlib import Path

import pytest

from companion import deploy
from companion.cli import main
from companion.config import template
from companion.evaluate.plot import PlotUnavailableError, plot_evaluation
from tests.test_evaluate import event_case, make_truth

if sys.version_info >= (3, 11):
    import tomllib
else:
    import tomli as tomllib

ROOT = Path(__file__).resolve().parent.parent


def _hide_matplotlib(monkeypatch: pytest.MonkeyPatch) -> None:
    """Make ``import matplotlib`` (and any ``matplotlib.x``) fail as if it were not installed."""
    for name in [m for m in sys.modules if m == "matplotlib" or m.startswith("matplotlib.")]:
        monkeypatch.delitem(sys.modules, name)
    monkeypatch.setitem(sys.modules, "matplotlib", None)


# --------------------------------------------------------------------------- plot extra


def test_evaluate_plot_without_matplotlib_is_one_line(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    event_case(tmp_path, make_truth())  # writes out.tlog, case.truth.csv, case.json
    out, truth = tmp_path / "out.tlog", tmp_path / "case.truth.csv"
    png = tmp_path / "report.png"
    _hide_matplotlib(monkeypatch)

    status = main(["evaluate", str(out), "--truth", str(truth), "--plot", str(png)])
    captured = capsys.readouterr()
    assert status != 0
    lines = captured.err.strip().splitlines()
    assert len(lines) == 1, captured.err
    assert "pip install 'companion[plot]'" in lines[0]
    assert lines[0].startswith("companion evaluate: error:")
    assert captured.out == "" and not png.exists()  # refused before any work

    # Without --plot the evaluation works with matplotlib missing.
    assert main(["evaluate", str(out), "--truth", str(truth)]) == 0
    captured = capsys.readouterr()
    assert captured.out.startswith(f"companion evaluate: {out} vs {truth}")
    assert "Position error" in captured.out
    assert captured.err == ""


def test_inspect_plot_without_matplotlib_is_one_line(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    ubx = ROOT / "tests" / "data" / "walk_0827" / "gnss_1730_cut.ubx"
    csv, png = tmp_path / "track.csv", tmp_path / "track.png"
    _hide_matplotlib(monkeypatch)
    status = main(["inspect", str(ubx), "-o", str(csv), "--plot", str(png)])
    captured = capsys.readouterr()
    assert status != 0
    lines = captured.err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("companion inspect: error:")
    assert "pip install 'companion[plot]'" in lines[0]
    assert not csv.exists() and not png.exists()  # refused before any work


def test_plot_evaluation_names_the_extra(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    evaluation = event_case(tmp_path, make_truth())
    _hide_matplotlib(monkeypatch)
    with pytest.raises(PlotUnavailableError, match=r"pip install 'companion\[plot\]'"):
        plot_evaluation(evaluation, tmp_path / "report.png")


def test_no_module_imports_matplotlib_at_import_time() -> None:
    """Every module of the package imports with matplotlib absent (a fresh interpreter)."""
    code = (
        "import importlib, pkgutil, sys\n"
        "sys.modules['matplotlib'] = None\n"
        "import companion\n"
        "names = [m.name for m in pkgutil.walk_packages(companion.__path__, 'companion.')\n"
        "         if not m.name.endswith('__main__')]\n"
        "for name in names:\n"
        "    importlib.import_module(name)\n"
        "print(len(names))\n"
    )
    done = subprocess.run(
        [sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=120
    )
    assert done.returncode == 0, done.stderr
    assert int(done.stdout) > 50  # the walk found the package's modules


def test_matplotlib_is_only_in_the_plot_extra() -> None:
    with open(ROOT / "pyproject.toml", "rb") as fh:
        project = tomllib.load(fh)["project"]
    assert not any(d.startswith("matplotlib") for d in project["dependencies"])
    assert any(d.startswith("matplotlib") for d in project["optional-dependencies"]["plot"])


# --------------------------------------------------------------------------- package data


def test_packaged_files_are_declared_as_package_data() -> None:
    """Every file of companion/systemd/ is listed in pyproject's package data (so it is in
    the wheel), and nothing listed is missing."""
    with open(ROOT / "pyproject.toml", "rb") as fh:
        package_data = tomllib.load(fh)["tool"]["setuptools"]["package-data"]
    declared = set(package_data["companion.systemd"])
    present = {p.name for p in (ROOT / "companion" / "systemd").iterdir() if p.is_file()}
    assert declared == present


def test_packaged_example_config_is_the_template() -> None:
    assert deploy.packaged_text(deploy.EXAMPLE_CONFIG_NAME).strip() == template().strip()


def test_install_unit_print_points_at_the_executable(
    capsys: pytest.CaptureFixture[str],
) -> None:
    assert main(["install-unit", "--print", "--exec", "/usr/local/bin/companion"]) == 0
    out = capsys.readouterr().out
    assert out == deploy.unit_text("/usr/local/bin/companion")
    exec_lines = [ln for ln in out.splitlines() if ln.startswith("ExecStart=")]
    assert exec_lines == [
        "ExecStart=/usr/local/bin/companion --log-level info run "
        "--config /etc/companion/companion.toml"
    ]
    packaged = deploy.packaged_text(deploy.UNIT_NAME)
    assert deploy.unit_text(None) == packaged
    assert out.replace("/usr/local/bin/companion", deploy.PACKAGED_EXECUTABLE) == packaged


def test_install_unit_writes_the_unit(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["install-unit", "--dir", str(tmp_path), "--exec", "/opt/x/bin/companion"]) == 0
    path = tmp_path / deploy.UNIT_NAME
    assert capsys.readouterr().out.strip() == str(path)
    assert path.read_text() == deploy.unit_text("/opt/x/bin/companion")
    assert stat.S_IMODE(path.stat().st_mode) == 0o644


def test_install_unit_into_a_missing_folder_is_one_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["install-unit", "--dir", str(tmp_path / "absent")]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "cannot write" in err[0]


def test_install_unit_refuses_an_executable_path_with_spaces(
    capsys: pytest.CaptureFixture[str],
) -> None:
    assert main(["install-unit", "--print", "--exec", "/opt/my venv/bin/companion"]) == 1
    assert "white space" in capsys.readouterr().err


# --------------------------------------------------------------------------- Python 3.10


def test_async_code_catches_asyncio_timeout_error() -> None:
    """Python 3.10 (JetPack 6): ``asyncio.wait_for`` raises ``asyncio.TimeoutError``, which
    only became the builtin ``TimeoutError`` in 3.11; an ``async def`` that names the builtin
    misses the timeout there (ruff's py311 rule UP041 rewrites one into the other)."""
    found = []
    for path in [
        *sorted((ROOT / "companion").rglob("*.py")),
        *sorted((ROOT / "tests").rglob("*.py")),
    ]:
        tree = ast.parse(path.read_text(encoding="utf-8"))
        for func in ast.walk(tree):
            if not isinstance(func, ast.AsyncFunctionDef):
                continue
            for node in ast.walk(func):
                if isinstance(node, ast.Name) and node.id == "TimeoutError":
                    found.append(f"{path.relative_to(ROOT)}:{node.lineno}")
    assert found == [], "use asyncio.TimeoutError in async code:\n" + "\n".join(found)
