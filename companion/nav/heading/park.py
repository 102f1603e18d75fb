"""The parked check: before the taxi, the GNSS velocity while parked must show no bias.

Parked: the mean GNSS velocity over the last ``park_smooth_s`` is at most
``park_speed_mps`` (one noisy fix must not end the parking; a taxiing speed ends
it at once). After ``park_time_s`` parked, and every ``park_time_s`` after that,
the velocities of the last ``park_window_s`` are tested for a bias
(:func:`~companion.nav.heading.criteria.park_bias_verdict`; Markelov et al., the
parking-stand check). A bias above ``park_max_bias_mps`` fails the check (announced
once per parking, however often later checks of the same parking flip); a significant
one above ``park_suspect_bias_mps`` only makes the parking *suspect*: real receivers
report 0.1-0.2 m/s at standstill that is gone in motion, and the taxi's own leg test
judges a bias that persists (the corrector then wants ``suspect_min_legs`` legs). The
parked fixes also set the ground reference altitude.
"""

from __future__ import annotations

import logging
import math

import numpy as np

from companion.nav.heading.config import HeadingConfig
from companion.nav.heading.criteria import Verdict, park_bias_verdict
from companion.nav.heading.ground import GroundState
from companion.types import GnssFix

logger = logging.getLogger(__name__)


class ParkCheck:
    """State of the parked GNSS velocity check."""

    def __init__(self, config: HeadingConfig) -> None:
        self.config = config
        self._start_t: float | None = None
        self._vel: list[tuple[float, float, float]] = []  # (t, vn, ve) of the window
        self._recent: list[tuple[float, float, float]] = []  # (t, vn, ve) of park_smooth_s
        self._last_eval_t: float | None = None
        self.ok: bool | None = None
        """Latest check: passed, failed, or ``None`` when not done."""
        self.reject_sent = False
        """A failed check of this parking was announced (once per parking)."""
        self.suspect = False
        """The latest check passed with a significant bias above ``park_suspect_bias_mps``."""

    def reset(self) -> None:
        """The parking ended (or the vehicle is airborne): the next one starts afresh."""
        self._recent.clear()
        self._start_t = None
        self._vel.clear()
        self._last_eval_t = None
        self.reject_sent = False

    def verdict(self, vel_ne_mps: np.ndarray) -> Verdict:
        """Is the mean of the GNSS velocities ``vel_ne_mps`` (shape (n, 2), m/s) a bias?"""
        return park_bias_verdict(vel_ne_mps, self.config.park_alpha, self.config.park_max_bias_mps)

    def step(
        self, fix: GnssFix, vn_mps: float, ve_mps: float, speed_mps: float, ground: GroundState
    ) -> str | None:
        """One fix: its north and east velocity and its ground speed, m/s.

        Returns the reason of a failed check to announce (once), else ``None``.
        """
        cfg = self.config
        self._recent.append((fix.t_s, vn_mps, ve_mps))
        while self._recent and self._recent[0][0] < fix.t_s - cfg.park_smooth_s:
            self._recent.pop(0)
        m_n = sum(v[1] for v in self._recent) / len(self._recent)
        m_e = sum(v[2] for v in self._recent) / len(self._recent)
        if speed_mps >= cfg.min_speed_mps or math.hypot(m_n, m_e) > cfg.park_speed_mps:
            self.reset()
            return None
        if self._start_t is None:
            self._start_t = fix.t_s
        self._vel.append((fix.t_s, vn_mps, ve_mps))
        # ground reference altitude: the mean of parked fixes
        ground.add_parked_altitude(fix.alt_msl_m)
        horizon = fix.t_s - cfg.park_window_s
        while self._vel and self._vel[0][0] < horizon:
            self._vel.pop(0)
        if fix.t_s - self._start_t < cfg.park_time_s:
            return None
        if self._last_eval_t is not None and fix.t_s - self._last_eval_t < cfg.park_time_s:
            return None
        self._last_eval_t = fix.t_s
        vel = np.array([[v[1], v[2]] for v in self._vel])
        verdict = self.verdict(vel)
        self.ok = verdict.ok
        if verdict.ok:
            strict = park_bias_verdict(vel, cfg.park_alpha, cfg.park_suspect_bias_mps)
            self.suspect = not strict.ok
            logger.info(
                "parked GNSS velocity check passed%s: %s",
                " (bias suspect)" if self.suspect else "",
                verdict.details,
            )
            return None
        logger.warning("parked GNSS velocity check failed: %s", verdict.details)
        if self.reject_sent:
            return None
        self.reject_sent = True
        return verdict.reason
