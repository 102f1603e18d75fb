"""IMU-grade presets: the whole configuration for an IMU grade, generated from the one grade
table (:data:`companion.nav.grades.IMU_GRADES`).

The blend's noise model and the coasting references take the grade's figures through
their ``for_grade`` constructors, and a grade adds the choices its figures allow
(:data:`GRADE_CHOICES`): a tactical IMU outlasts the autopilot's attitude, so the blend
integrates the gyros (``strapdown``), and it coasts slowly enough to be the integrity
monitor's second opinion (``engine.inertial_reference``). ``mems``, a typical autopilot
IMU, is the service's default configuration.

Used by ``companion run``/``replay`` ``--grade G`` (the configuration a ``--config`` file's
keys then override) and ``companion config-template --grade G`` (the full template with
the grade's values, e.g. for ``/etc/companion/companion.toml``).
``sitl_fixtures/tactical.toml`` spells out the tactical preset for the bundled flights;
``tests/test_presets.py`` holds the two equal.
"""

from __future__ import annotations

import dataclasses
from typing import Any

from companion.config import Config, ConfigError, template
from companion.integrity.coast import CoastConfig
from companion.integrity.spoof import SpoofConfig
from companion.nav.blend import BlendConfig

GRADES: tuple[str, ...] = ("mems", "tactical")
"""The IMU grades a preset exists for (the blend's and the coasting references' grades)."""

GRADE_CHOICES: dict[str, dict[str, dict[str, Any]]] = {
    "mems": {},
    "tactical": {
        # a tactical IMU outlasts the autopilot's attitude: integrate the gyros
        "blend": {"mode": "strapdown"},
        # it coasts slowly enough to be the integrity monitor's second opinion: vertical
        # ramps of 4 cm/s and 0.5 m dithers show against it with one receiver
        "engine": {"inertial_reference": True},
    },
}
"""Per grade, ``{block: {key: value}}`` beyond the grade's figures."""


def grade_config(grade: str) -> Config:
    """The configuration for an IMU grade (``"mems"``: ``Config()``, the defaults).

    Raises ConfigError naming the known grades.
    """
    if grade not in GRADES:
        raise ConfigError(f"unknown IMU grade {grade!r} (known: {', '.join(GRADES)})")
    config = dataclasses.replace(
        Config(),
        blend=BlendConfig.for_grade(grade),
        coast=CoastConfig.for_grade(grade),
        spoof=SpoofConfig.for_grade(grade),
    )
    blocks = {
        block: dataclasses.replace(getattr(config, block), **keys)
        for block, keys in GRADE_CHOICES[grade].items()
    }
    return dataclasses.replace(config, **blocks)


def grade_template(grade: str) -> str:
    """``companion config-template --grade G``: every key with the grade's value."""
    return template(grade_config(grade), f"every key, with its value for a {grade}-grade IMU")
