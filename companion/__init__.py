"""companion: a navigation service beside an ArduPilot or PX4 autopilot.

It listens to the autopilot's GNSS and IMU MAVLink streams and gives back a
position that stays right through GNSS and RTK-correction outages, a heading
corrected during the taxi before take-off, and integrity alerts.

Package map (docs/architecture.md): ``types`` (samples and outputs), ``nav``
and ``integrity`` (pure estimation), ``engine`` (pure orchestrator), ``mavlink``
(the edge: decode, encode, links, tlog), ``pipeline`` (the service at the
MAVLink level, without I/O), ``service`` (asyncio live driver), ``replay``
(tlog driver), ``config`` (TOML configuration), ``sim`` (simulated flights with
truth), ``evaluate`` and ``report`` (scoring against truth), ``console`` (the
ground-side terminal view).
"""

__version__ = "0.1.0"
