"""Configuration: defaults, TOML loading, one-line errors that name the key."""

from __future__ import annotations

import sys

import pytest

if sys.version_info >= (3, 11):
    import tomllib
else:
    import tomli as tomllib

from companion.config import Config, ConfigError, config_from_dict, load_config, template


def test_defaults_are_valid():
    cfg = load_config(None)
    assert cfg == Config()
    assert cfg.engine.publish_rate_hz == 10.0


def test_template_round_trips_to_the_defaults(tmp_path):
    path = tmp_path / "c.toml"
    path.write_text(template())
    assert load_config(path) == Config()
    # every key carries its documentation line
    text = template()
    assert "# GLOBAL_POSITION_INT / GPS_INPUT rate" in text


def test_values_are_taken(tmp_path):
    path = tmp_path / "c.toml"
    path.write_text('[engine]\npublish_rate_hz = 5\n[link]\nmaster = "udpin:0.0.0.0:14550"\n')
    cfg = load_config(path)
    assert cfg.engine.publish_rate_hz == 5.0 and isinstance(cfg.engine.publish_rate_hz, float)
    assert cfg.link.master == "udpin:0.0.0.0:14550"


@pytest.mark.parametrize(
    ("data", "message"),
    [
        ({"nope": {}}, "unknown block [nope]"),
        ({"engine": {"publish_hz": 5}}, "[engine] unknown key 'publish_hz'"),
        ({"engine": {"publish_rate_hz": "fast"}}, "[engine] publish_rate_hz must be a number"),
        ({"engine": {"publish_rate_hz": -1.0}}, "[engine] publish_rate_hz must be in"),
        ({"outage": {"reacquire_fixes": 1.5}}, "[outage] reacquire_fixes must be an integer"),
        ({"link": {"master": ""}}, "[link] master must name a link"),
        ({"link": {"baud": 0}}, "[link] baud must be > 0, got 0"),
        ({"link": {"heartbeat_rate_hz": 20}}, "[link] heartbeat_rate_hz must be in [0.1, 10]"),
        ({"streams": {"raw_imu_hz": -1}}, "[streams] raw_imu_hz must be in [0, 1000], got -1.0"),
        ({"engine": {"navigator": "kalman"}}, "[engine] navigator must be one of"),
        ({"engine": {"status_rate_hz": 20}}, "[engine] status_rate_hz must be <= publish_rate_hz"),
        ({"engine": {"primary_receiver": 2}}, "[engine] primary_receiver must be one of [0, 1]"),
    ],
)
def test_bad_values_are_one_line_errors_naming_the_key(data, message):
    with pytest.raises(ConfigError) as err:
        config_from_dict(data)
    assert message in str(err.value)
    assert "\n" not in str(err.value)


def test_missing_and_malformed_files(tmp_path):
    with pytest.raises(ConfigError, match="not found"):
        load_config(tmp_path / "missing.toml")
    bad = tmp_path / "bad.toml"
    bad.write_text("[engine\n")
    with pytest.raises(ConfigError, match="not valid TOML"):
        load_config(bad)


def test_example_config_in_systemd_folder_is_loadable():
    from pathlib import Path

    example = Path(__file__).resolve().parent.parent / "companion" / "systemd" / "companion.toml"
    with open(example, "rb") as fh:
        tomllib.load(fh)
    load_config(example)


def test_example_config_is_the_current_template():
    """companion/systemd/companion.toml is `companion config-template` output: regenerate it
    when a block gains a key."""
    from pathlib import Path

    example = Path(__file__).resolve().parent.parent / "companion" / "systemd" / "companion.toml"
    assert example.read_text().strip() == template().strip()


def test_tactical_fixture_config_is_the_tactical_grade():
    """sitl_fixtures/tactical.toml spells out the tactical grade's figures for the blend and
    the coasting references: they must be the grade profile's, not a copy that drifted."""
    from pathlib import Path

    from companion.integrity.coast import CoastConfig
    from companion.nav.blend import BlendConfig

    path = Path(__file__).resolve().parent.parent / "sitl_fixtures" / "tactical.toml"
    cfg = load_config(path)
    assert cfg.coast == CoastConfig.for_grade("tactical")
    grade = BlendConfig.for_grade("tactical")
    for key in ("accel_vrw_mps_rts", "gyro_arw_rad_rts", "accel_bias_sigma_mps2"):
        assert getattr(cfg.blend, key) == pytest.approx(getattr(grade, key), rel=1e-12), key
    assert cfg.engine.inertial_reference


def test_numpydoc_attributes_document_template_keys():
    """Blocks documented numpydoc-style (an Attributes section) still get per-key comments."""
    text = template()
    block = text.split("[potential]")[1].split("\n[")[0]
    assert "# Span of past fixes" in block
