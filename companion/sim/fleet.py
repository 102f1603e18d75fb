"""Many varied simulated flights at once (``companion simulate --many N``).

Flight ``i`` (0-based) is the catalogue scenario ``FLEET_SCENARIOS[i % k]`` with
seed ``seed * 100000 + i``, written to ``flight_<i>/`` (tlog, truth CSV, JSON
sidecar). With ``duration_s`` every flight is that long and its events are replaced
by one GNSS outage of 4-7 s (``4 + i % 4``) starting at 50-54 % of the flight (the
catalogue's events would mostly fall after a short flight's end); without it each
flight keeps its scenario's duration and events. The same arguments give the same
files.
"""

from __future__ import annotations

from pathlib import Path

from companion.sim.flight import simulate
from companion.sim.scenarios import Event, make_scenario
from companion.sim.writer import write_flight

FLEET_SCENARIOS = (
    "cruise_gnss_loss", "px4_rotorcraft", "approach_rtk20", "stale_fix", "downgrade",
    "approach_rtk40", "taxi",
)  # fmt: skip
"""The catalogue scenarios a fleet cycles through: fixed-wing and rotorcraft,
ArduPilot and PX4, outages, RTK losses, stale fixes, downgrades, a taxi."""
SEED_STRIDE = 100_000


def write_fleet(
    out_dir: Path, n: int, seed: int = 1, duration_s: float | None = None
) -> list[Path]:
    """Write ``n`` flights under ``out_dir`` (module docstring); return their tlogs.

    Raises
    ------
    ValueError
        ``n`` < 1, a negative seed or a duration that is not positive.
    """
    if n < 1:
        raise ValueError(f"--many needs at least 1 flight, got {n}")
    if seed < 0:
        raise ValueError(f"seed must be a non-negative integer, got {seed}")
    if duration_s is not None and not duration_s > 0:
        raise ValueError(f"duration must be positive, got {duration_s}")
    width = max(4, len(str(n - 1)))
    tlogs = []
    for i in range(n):
        name = FLEET_SCENARIOS[i % len(FLEET_SCENARIOS)]
        if duration_s is None:
            sc = make_scenario(name)
        else:
            start = duration_s * (0.50 + 0.01 * (i % 5))
            outage = Event("outage", start, start + 4.0 + i % 4)
            sc = make_scenario(name, duration_s=duration_s, events=(outage,))
        folder = out_dir / f"flight_{i:0{width}d}"
        written = write_flight(simulate(sc, seed * SEED_STRIDE + i), folder)
        tlogs.append(written[0])
    return tlogs
