"""Persisted state of the heading correction: what survives a service restart.

:func:`to_state` writes a plain, JSON-compatible dictionary (layout version
:data:`STATE_VERSION`); :func:`restore_state` reads it back into a fresh
:class:`~companion.nav.heading.corrector.HeadingCorrector`. :class:`HeadingPhase`
is the phase of the corrector's state machine. The attitude buffer (a few
seconds) is not kept: after a restart the first cycles wait for
``settle_time_s`` of attitude.
"""

from __future__ import annotations

import enum
from collections import Counter
from dataclasses import asdict
from typing import TYPE_CHECKING, Any

from companion.nav.heading.config import TRACK_SOURCES
from companion.nav.heading.stats import HeadingEstimate, RunningStats

if TYPE_CHECKING:
    from companion.nav.heading.corrector import HeadingCorrector

STATE_VERSION = 1
"""Version of the :func:`to_state` dictionary layout."""


class HeadingPhase(enum.Enum):
    """Where the correction stands (persisted as its value)."""

    ACCUMULATING = "accumulating"  # collecting straight-leg cycles
    READY = "ready"  # all criteria hold: waiting for confirmation
    APPLIED = "applied"  # the correction is in use for this flight


class HeadingStatus(enum.IntEnum):
    """The correction's state as a ground station shows it: the value of ``CMP_HDGS``
    (docs/mavlink.md). Derived from the phase, the current sample and the last verdict."""

    IDLE = 0  # nothing accumulated: before the first straight-leg cycle, or airborne
    ACCUMULATING = 1  # collecting straight-leg cycles
    READY = 2  # all criteria hold: waiting for the ground station's confirmation
    APPLIED = 3  # every estimator and the published heading use the correction
    REJECTED = 4  # a criterion failed or the operator refused; until the next cycle


def to_state(hc: HeadingCorrector) -> dict[str, Any]:
    """Everything of ``hc`` that must survive a restart, as a JSON-compatible dict."""

    def est(e: HeadingEstimate | None) -> dict[str, Any] | None:
        return None if e is None else asdict(e)

    sample = hc._sample
    return {
        "version": STATE_VERSION,
        "phase": hc.phase.value,
        "stats": asdict(sample.stats),
        "mean_stats": asdict(sample.mean_stats),
        "t_s": list(sample.t_s),
        "x_rad": list(sample.x_rad),
        "sigma_rad": list(sample.sigma_rad),
        "leg": list(sample.leg),
        "leg_id": sample.leg_id,
        "park_ok": hc._park.ok,
        "park_reject_sent": hc._park.reject_sent,
        "ground_ref_alt_m": hc._ground.ref_alt_m,
        "ground_ref_n": hc._ground.ref_n,
        "candidate": est(hc._candidate),
        "applied": est(hc._applied),
        "last_publish_t_s": hc._last_publish_t,
        "rejections": dict(hc.rejections),
        "reject_alerts": hc.reject_alerts,
        "source": hc._source,
        "rejected": hc._rejected,
    }


def restore_state(hc: HeadingCorrector, state: dict[str, Any]) -> None:
    """Load :func:`to_state` output into the fresh corrector ``hc`` (ValueError when malformed)."""
    if not isinstance(state, dict):
        raise ValueError("heading state must be a dict")
    if state.get("version") != STATE_VERSION:
        raise ValueError(f"heading state version {state.get('version')!r} != {STATE_VERSION}")
    sample = hc._sample
    try:
        hc.phase = HeadingPhase(state["phase"])
        sample.stats = _stats_from(state["stats"])
        sample.mean_stats = _stats_from(state["mean_stats"])
        sample.t_s = [float(v) for v in state["t_s"]]
        sample.x_rad = [float(v) for v in state["x_rad"]]
        sample.sigma_rad = [float(v) for v in state["sigma_rad"]]
        sample.leg = [int(v) for v in state["leg"]]
        sample.leg_id = int(state["leg_id"])
        sample.n_legs = len(set(sample.leg))
        counts = Counter(sample.leg)
        sample.full_legs = sum(1 for c in counts.values() if c >= hc.config.min_leg_cycles)
        sample.leg_cycles = counts[sample.leg[-1]] if sample.leg else 0
        park_ok = state["park_ok"]
        hc._park.ok = None if park_ok is None else bool(park_ok)
        hc._park.reject_sent = bool(state["park_reject_sent"])
        ref = state["ground_ref_alt_m"]
        hc._ground.ref_alt_m = None if ref is None else float(ref)
        hc._ground.ref_n = int(state["ground_ref_n"])
        hc._candidate = _estimate_from(state["candidate"])
        hc._applied = _estimate_from(state["applied"])
        last = state["last_publish_t_s"]
        hc._last_publish_t = None if last is None else float(last)
        hc.rejections = Counter({str(k): int(v) for k, v in state["rejections"].items()})
        hc.reject_alerts = int(state["reject_alerts"])
        source = state.get("source")
        if source is not None and source not in TRACK_SOURCES:
            raise ValueError(f"heading state malformed: source {source!r}")
        hc._source = source
        hc._rejected = bool(state.get("rejected", False))
    except (KeyError, TypeError, AttributeError) as exc:
        raise ValueError(f"heading state malformed: {exc!r}") from exc
    lengths = {len(sample.t_s), len(sample.x_rad), len(sample.sigma_rad), len(sample.leg)}
    if len(lengths) != 1 or sample.stats.n != len(sample.x_rad):
        raise ValueError("heading state malformed: cycle arrays disagree")
    if hc.phase is HeadingPhase.APPLIED and hc._applied is None:
        raise ValueError("heading state malformed: APPLIED without an applied estimate")
    if hc.phase is HeadingPhase.READY and hc._candidate is None:
        raise ValueError("heading state malformed: READY without a candidate")


def _stats_from(d: dict[str, Any]) -> RunningStats:
    return RunningStats(int(d["n"]), float(d["mean"]), float(d["var"]))


def _estimate_from(d: dict[str, Any] | None) -> HeadingEstimate | None:
    if d is None:
        return None
    return HeadingEstimate(
        float(d["correction_rad"]),
        float(d["sigma_rad"]),
        float(d["eps_rad"]),
        int(d["n"]),
        int(d["legs"]),
    )
