"""What "the same output" means: the tolerances of every replay and fixture comparison.

The one place they are written down. The replay comparison (:mod:`tests.golden.compare`),
the comparison of a regenerated simulated flight with the committed one
(:mod:`tests.golden.flights`) and ``bench/compare_replays.py`` all ask this module
whether two values agree.

Why tolerances at all: numpy's matrix products run on the OpenBLAS kernel chosen for
the CPU (``OPENBLAS_CORETYPE`` picks another), and numpy's own exp, log, arctan2, power
... on the SIMD loops the CPU offers (``NPY_DISABLE_CPU_FEATURES`` turns them off).
Another kernel sums in another order: the last bits of a double differ, and a value
that sat within a rounding error of a half unit is published one unit apart. Measured
over every golden case on four x86 kernels (docs/replay.md, "Golden outputs"): only
float32 fields moved, by one unit in their last place; no integer field, no alert.

The rules, per quantity the service publishes (each a value at the resolution MAVLink
gives it, or a small fraction of the 1-sigma accuracy the service publishes beside it,
whichever is larger):

=====================  ==============================================================
horizontal position    1 unit of 1e-7 deg, or ``SIGMA_FRACTION`` of the published
                       horizontal 1-sigma
altitude               1 mm, or ``SIGMA_FRACTION`` of the vertical 1-sigma
velocity               1 cm/s, or ``SIGMA_FRACTION`` of the speed 1-sigma
heading / yaw          1 cdeg (across north), "unknown" exactly
accuracies, DOPs       relative ``FLOAT_REL_TOL``
other floats           relative ``FLOAT_REL_TOL`` or ``FLOAT_ABS_TOL``
                       (NAMED_VALUE_FLOAT values, the simulator's float32 fields)
other integers         1 unit (a rounding-boundary flip; time stamps, scaled sensor
                       values)
enumerations, flags    exactly (fix type, ignore flags, satellites, ids)
texts                  the same words; each number within one unit of its last
                       printed digit, printed with as many decimals
times of events        within ``EVENT_SAMPLES`` samples of the flight's output rate
                       (alerts, STATUSTEXTs, HEARTBEAT state changes)
counts                 exactly (messages by type, rejections, alerts by code)
=====================  ==============================================================

One unit of 1e-7 deg is 1.1 cm; ``SIGMA_FRACTION`` of a 1-sigma moves a NEES by about
2 %: a difference the service's own uncertainty cannot tell apart. A deliberate change
of an estimate (a noise figure by 10 %) moves the published accuracies by far more than
``FLOAT_REL_TOL`` (``tests/test_replay_golden.py`` shows it fails).
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass
from typing import Any

import numpy as np

from companion.mavlink import units

SIGMA_FRACTION = 0.01
"""A position, altitude or velocity may differ by this fraction of its published 1-sigma."""
FLOAT_REL_TOL = 1e-5
"""Relative agreement of accuracies and other floats (float32 resolves 6e-8)."""
FLOAT_ABS_TOL = 1e-6
"""Absolute agreement that always suffices for other floats (m, m/s, rad, deg: far below
the integer fields' resolution)."""
JSON_REL_TOL = 1e-9
"""Relative agreement of the doubles a JSON file holds (the simulator's sidecar)."""
EVENT_SAMPLES = 2
"""An alert, a STATUSTEXT or a state change may come this many output samples apart."""

EARTH_RADIUS_M = 6_371_000.0
"""Mean radius: only to turn a tolerance in metres into units of 1e-7 deg."""
LAT_LSB_M = EARTH_RADIUS_M / units.DEGE7_PER_RAD
"""Metres per unit of a 1e-7 deg latitude (1.1 cm)."""
HEADING_UNITS = 36000
"""Centidegrees in a turn."""

# (message type, field) -> quantity; a field not listed follows its type: an integer
# ``count`` (1 unit), a float ``float`` (relative), a text ``exact``.
QUANTITIES: dict[tuple[str, str], str] = {
    ("GLOBAL_POSITION_INT", "lat"): "lat_e7",
    ("GLOBAL_POSITION_INT", "lon"): "lon_e7",
    ("GLOBAL_POSITION_INT", "alt"): "alt_mm",
    ("GLOBAL_POSITION_INT", "relative_alt"): "alt_mm",
    ("GLOBAL_POSITION_INT", "vx"): "vel_cms",
    ("GLOBAL_POSITION_INT", "vy"): "vel_cms",
    ("GLOBAL_POSITION_INT", "vz"): "vel_cms",
    ("GLOBAL_POSITION_INT", "hdg"): "hdg_cdeg",
    ("GPS_INPUT", "lat"): "lat_e7",
    ("GPS_INPUT", "lon"): "lon_e7",
    ("GPS_INPUT", "alt"): "alt_m",
    ("GPS_INPUT", "vn"): "vel_mps",
    ("GPS_INPUT", "ve"): "vel_mps",
    ("GPS_INPUT", "vd"): "vel_mps",
    ("GPS_INPUT", "yaw"): "yaw_cdeg",
    ("GPS_INPUT", "horiz_accuracy"): "accuracy",
    ("GPS_INPUT", "vert_accuracy"): "accuracy",
    ("GPS_INPUT", "speed_accuracy"): "accuracy",
    ("GPS_INPUT", "hdop"): "accuracy",
    ("GPS_INPUT", "vdop"): "accuracy",
    ("GPS_INPUT", "fix_type"): "exact",
    ("GPS_INPUT", "ignore_flags"): "exact",
    ("GPS_INPUT", "satellites_visible"): "exact",
    ("GPS_INPUT", "gps_id"): "exact",
    ("GPS_INPUT", "time_week"): "exact",
    ("GLOBAL_POSITION_SENSOR", "lat"): "lat_e7",
    ("GLOBAL_POSITION_SENSOR", "lon"): "lon_e7",
    ("GLOBAL_POSITION_SENSOR", "alt"): "alt_m",
    ("GLOBAL_POSITION_SENSOR", "alt_ellipsoid"): "alt_m",
    ("GLOBAL_POSITION_SENSOR", "eph"): "accuracy",
    ("GLOBAL_POSITION_SENSOR", "epv"): "accuracy",
    ("GLOBAL_POSITION_SENSOR", "flags"): "exact",
    ("GLOBAL_POSITION_SENSOR", "source"): "exact",
    ("GLOBAL_POSITION_SENSOR", "id"): "exact",
}
EXACT_FIELDS = frozenset({"target_system", "target_component", "command", "confirmation"})
"""Enumerations in any message: compared exactly."""

_NUMBER_RE = re.compile(r"-?\d+(?:\.\d+)?")


@dataclass(frozen=True, slots=True)
class Sigmas:
    """What a sample's tolerance depends on beyond its field: the 1-sigma accuracies the
    service published with it (m, m/s; 0 where none was) and the cosine of its latitude
    (a unit of longitude is shorter by it)."""

    h_m: np.ndarray
    v_m: np.ndarray
    speed_mps: np.ndarray
    cos_lat: np.ndarray

    @staticmethod
    def none(n: int) -> Sigmas:
        """No published accuracy: the resolution alone."""
        zero = np.zeros(n)
        return Sigmas(zero, zero, zero, np.ones(n))


def quantity(msg_type: str, field: str, value: Any) -> str:
    """The quantity a field holds (the keys of :func:`tolerance`)."""
    q = QUANTITIES.get((msg_type, field))
    if q is not None:
        return q
    if field in EXACT_FIELDS or isinstance(value, str | bytes | np.str_):
        return "exact"
    if isinstance(value, float | np.floating):
        return "float"
    return "count"


def difference(q: str, ref: np.ndarray, new: np.ndarray) -> np.ndarray:
    """|new - ref| per sample in the field's own units: across north for headings,
    0 where both are NaN or both the same "unknown", inf where only one is."""
    if ref.dtype.kind in "USO" or new.dtype.kind in "USO":
        return np.where(ref == new, 0.0, np.inf)
    a = ref.astype(np.float64)
    b = new.astype(np.float64)
    with np.errstate(invalid="ignore"):
        diff = np.abs(b - a)
        if q in ("hdg_cdeg", "yaw_cdeg"):
            unknown = units.UINT16_UNKNOWN if q == "hdg_cdeg" else 0
            diff = np.minimum(diff % HEADING_UNITS, -diff % HEADING_UNITS)
            one_unknown = (a == unknown) | (b == unknown)
            diff = np.where(one_unknown, np.where(a == b, 0.0, np.inf), diff)
    diff = np.where(np.isnan(a) & np.isnan(b), 0.0, diff)
    return np.where(np.isnan(diff), np.inf, diff)


def tolerance(q: str, ref: np.ndarray, sigmas: Sigmas) -> np.ndarray:
    """The largest |difference| allowed per sample, in the field's own units."""
    n = len(ref)
    if q == "lat_e7":
        return np.maximum(1.0, SIGMA_FRACTION * sigmas.h_m / LAT_LSB_M)
    if q == "lon_e7":
        lsb_m = LAT_LSB_M * np.maximum(sigmas.cos_lat, 1e-3)
        return np.maximum(1.0, SIGMA_FRACTION * sigmas.h_m / lsb_m)
    if q == "alt_mm":
        return np.maximum(1.0, SIGMA_FRACTION * sigmas.v_m * units.MM_PER_M)
    if q == "alt_m":
        return np.maximum(1.0 / units.MM_PER_M, SIGMA_FRACTION * sigmas.v_m)
    if q == "vel_cms":
        return np.maximum(1.0, SIGMA_FRACTION * sigmas.speed_mps * units.CM_PER_M)
    if q == "vel_mps":
        return np.maximum(1.0 / units.CM_PER_M, SIGMA_FRACTION * sigmas.speed_mps)
    if q in ("hdg_cdeg", "yaw_cdeg", "count"):
        return np.ones(n)
    if q == "exact":
        return np.zeros(n)
    scale = np.abs(ref.astype(np.float64))
    if q == "accuracy":
        return FLOAT_REL_TOL * scale
    if q == "float":
        return np.maximum(FLOAT_REL_TOL * scale, FLOAT_ABS_TOL)
    raise ValueError(f"unknown quantity {q!r}")


def values_agree(msg_type: str, field: str, ref: Any, new: Any) -> tuple[bool, float]:
    """Whether two scalar values of a field agree without a published accuracy beside
    them (the resolution alone), and |difference| / tolerance (0 when equal)."""
    if isinstance(ref, list | tuple):
        if not isinstance(new, list | tuple) or len(ref) != len(new):
            return False, math.inf
        worst = 0.0
        for a, b in zip(ref, new, strict=True):
            ok, r = values_agree(msg_type, field, a, b)
            if not ok:
                return False, r
            worst = max(worst, r)
        return True, worst
    if isinstance(ref, str | bytes) or isinstance(new, str | bytes):
        if isinstance(ref, str | bytes) and isinstance(new, str | bytes):
            return texts_agree(str(ref), str(new))
        return False, math.inf
    if isinstance(ref, bool) or isinstance(new, bool) or ref is None or new is None:
        return ref == new, 0.0 if ref == new else math.inf
    q = quantity(msg_type, field, ref)
    a, b = np.array([ref]), np.array([new])
    diff = float(difference(q, a, b)[0])
    tol = float(tolerance(q, a, Sigmas.none(1))[0])
    if diff == 0.0:
        return True, 0.0
    return diff <= tol, diff / tol if tol > 0 else math.inf


def texts_agree(ref: str, new: str) -> tuple[bool, float]:
    """The same words, each number printed with as many decimals and within one unit of
    its last printed digit; and the largest number difference in those units."""
    if ref == new:
        return True, 0.0
    if _NUMBER_RE.sub("#", ref) != _NUMBER_RE.sub("#", new):
        return False, math.inf
    worst = 0.0
    for x, y in zip(_NUMBER_RE.findall(ref), _NUMBER_RE.findall(new), strict=True):
        if x == y:
            continue
        decimals = len(x.split(".")[1]) if "." in x else 0
        if decimals != (len(y.split(".")[1]) if "." in y else 0):
            return False, math.inf
        # in units of the last printed digit, exactly: the digits without the point
        units_apart = abs(int(x.replace(".", "")) - int(y.replace(".", "")))
        worst = max(worst, float(units_apart))
    return worst <= 1.0, worst


def json_agree(ref: Any, new: Any, path: str = "") -> list[tuple[str, Any, Any, float]]:
    """Where two JSON trees differ beyond :data:`JSON_REL_TOL` (numbers) or at all (the
    rest): ``(path, ref, new, |difference| / tolerance)``, empty when they agree."""
    if isinstance(ref, dict) and isinstance(new, dict):
        out = []
        for key in sorted(set(ref) | set(new), key=str):
            sub = f"{path}.{key}" if path else str(key)
            if key not in ref or key not in new:
                out.append((sub, ref.get(key), new.get(key), math.inf))
            else:
                out += json_agree(ref[key], new[key], sub)
        return out
    if isinstance(ref, list) and isinstance(new, list):
        if len(ref) != len(new):
            return [(f"{path}[len]", len(ref), len(new), math.inf)]
        return [
            d
            for i, (a, b) in enumerate(zip(ref, new, strict=True))
            for d in json_agree(a, b, f"{path}[{i}]")
        ]
    if isinstance(ref, float | int) and isinstance(new, float | int):
        if (
            isinstance(ref, bool)
            or isinstance(new, bool)
            or isinstance(ref, int)
            and isinstance(new, int)
        ):
            return [] if ref == new else [(path, ref, new, math.inf)]
        tol = JSON_REL_TOL * max(abs(ref), abs(new))
        diff = abs(float(new) - float(ref))
        if diff <= tol:
            return []
        return [(path, ref, new, diff / tol if tol > 0 else math.inf)]
    return [] if ref == new else [(path, ref, new, math.inf)]


def evaluation_tolerance(key: str, ref: float, n: int | None, event_s: float) -> float:
    """The largest |difference| allowed in a figure of ``companion evaluate`` (computed
    from the compared outputs and the truth): a time (``*_s``) as an event's, a coverage
    fraction by :data:`EVENT_SAMPLES` of its ``n`` samples, any other as a float."""
    if key.endswith("_s"):
        return event_s
    if "coverage" in key and n:
        return EVENT_SAMPLES / n
    return max(FLOAT_REL_TOL * abs(ref), FLOAT_ABS_TOL)
