"""IMU-grade presets: generated from the grade table, equal to sitl_fixtures/tactical.toml,
printed in full by ``config-template --grade``, and the base ``--config`` overrides."""

from __future__ import annotations

from pathlib import Path

import pytest

from companion import sim
from companion.cli import main
from companion.config import Config, ConfigError, load_config, template
from companion.nav.grades import IMU_GRADES
from companion.presets import GRADES, grade_config, grade_template

ROOT = Path(__file__).resolve().parent.parent
TACTICAL_TOML = ROOT / "sitl_fixtures" / "tactical.toml"


def test_mems_preset_is_the_default_configuration() -> None:
    assert grade_config("mems") == Config()


def test_tactical_preset_is_exactly_the_fixture_file() -> None:
    """sitl_fixtures/tactical.toml (the bundled flights' configuration, hashed by the replay
    goldens) and the preset generated from the grade table are the same configuration,
    to the last bit of every float."""
    assert load_config(TACTICAL_TOML) == grade_config("tactical")


def test_tactical_preset_takes_the_grade_tables_figures() -> None:
    g = IMU_GRADES["tactical"]
    cfg = grade_config("tactical")
    assert cfg.blend.gyro_arw_rad_rts == g.gyro_noise_density_radps_rthz
    assert cfg.blend.accel_vrw_mps_rts == g.acc_noise_density_mps2_rthz
    assert cfg.blend.accel_bias_sigma_mps2 == g.acc_bias_sigma_mps2
    assert cfg.blend.gyro_bias_sigma_radps == g.gyro_bias_sigma_radps
    assert cfg.coast.acc_vrw_mps_rts == g.acc_noise_density_mps2_rthz
    assert cfg.blend.mode == "strapdown" and cfg.engine.inertial_reference
    assert cfg.blend != Config().blend and cfg.coast != Config().coast


@pytest.mark.parametrize("grade", GRADES)
def test_grade_template_loads_back_to_the_preset(tmp_path: Path, grade: str) -> None:
    path = tmp_path / f"{grade}.toml"
    path.write_text(grade_template(grade))
    assert load_config(path) == grade_config(grade)


def test_config_file_keys_override_the_grade(tmp_path: Path) -> None:
    path = tmp_path / "site.toml"
    path.write_text('[blend]\nmode = "attitude_aided"\n[link]\nmaster = "udpin:127.0.0.1:14550"\n')
    cfg = load_config(path, grade_config("tactical"))
    assert cfg.blend.mode == "attitude_aided" and cfg.link.master == "udpin:127.0.0.1:14550"
    tactical = grade_config("tactical")
    assert cfg.blend.gyro_arw_rad_rts == tactical.blend.gyro_arw_rad_rts  # kept from the grade
    assert cfg.coast == tactical.coast and cfg.engine == tactical.engine


def test_unknown_grade_is_a_config_error() -> None:
    with pytest.raises(ConfigError, match="unknown IMU grade 'navigation' .*mems, tactical"):
        grade_config("navigation")


def test_cli_config_template_grade(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["config-template", "--grade", "tactical"]) == 0
    out = capsys.readouterr().out
    assert out.strip() == grade_template("tactical").strip()
    assert 'mode = "strapdown"' in out and "inertial_reference = true" in out
    assert main(["config-template"]) == 0
    assert capsys.readouterr().out.strip() == template().strip()
    assert main(["config-template", "--grade", "consumer"]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "unknown IMU grade 'consumer'" in err[0]


def test_cli_replay_grade_is_the_fixture_file(tmp_path: Path) -> None:
    """``replay --grade tactical`` sends the same bytes as ``--config tactical.toml``, and
    not the default configuration's."""
    tlog = next(
        p for p in sim.write_scenario("approach_rtk20", tmp_path, seed=1, duration_s=15.0)
        if p.suffix == ".tlog"
    )  # fmt: skip
    outputs = {}
    for name, args in {
        "grade": ["--grade", "tactical"],
        "file": ["--config", str(TACTICAL_TOML)],
        "default": [],
    }.items():
        out = tmp_path / f"{name}.out.tlog"
        assert main(["replay", "-q", str(tlog), "-o", str(out), *args]) == 0
        outputs[name] = out.read_bytes()
    assert outputs["grade"] == outputs["file"]
    assert outputs["grade"] != outputs["default"]
