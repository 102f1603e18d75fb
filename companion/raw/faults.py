"""Faults injected into one satellite's raw observations (code, carrier and Doppler).

A satellite fault (a clock ramp, a dither) moves the pseudorange and the carrier
phase alike; the Doppler carries its rate, so the fault does not show as a cycle slip.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import replace

from companion.raw.obs import C_MPS, SIGNAL_HZ, RawEpoch

Fault = Callable[[float], tuple[float, float]]
"""Time since the fault's start (s) -> (range error m, its rate m/s)."""


def ramp(rate_mps: float) -> Fault:
    return lambda t: (rate_mps * t, rate_mps)


def dither(amplitude_m: float, period_s: float) -> Fault:
    w = 2.0 * math.pi / period_s
    return lambda t: (amplitude_m * math.sin(w * t), amplitude_m * w * math.cos(w * t))


def inject(
    epochs: Sequence[RawEpoch], system: str, sv: int, start_tow_s: float, fault: Fault
) -> list[RawEpoch]:
    """The epochs with ``fault`` added to every signal of one satellite from ``start``."""
    out = []
    for ep in epochs:
        t = ep.tow_s - start_tow_s
        if t < 0.0:
            out.append(ep)
            continue
        err_m, rate_mps = fault(t)
        sigs = []
        for s in ep.signals:
            hz = SIGNAL_HZ.get(s.band)
            if s.system != system or s.sv != sv or hz is None:
                sigs.append(s)
                continue
            wl = C_MPS / hz
            sigs.append(
                replace(
                    s,
                    pseudorange_m=s.pseudorange_m + err_m,
                    phase_cyc=s.phase_cyc + err_m / wl,
                    doppler_hz=s.doppler_hz - rate_mps / wl,
                )
            )
        out.append(replace(ep, signals=tuple(sigs)))
    return out
