"""companion: a navigation service beside an ArduPilot or PX4 autopilot.

It listens to the autopilot's GNSS and IMU MAVLink streams and gives back a
position that stays right through GNSS and RTK-correction outages, a heading
corrected during the taxi before take-off, and integrity alerts.

Package map (DESIGN.md): ``types`` (samples and outputs), ``nav`` and
``integrity`` (pure estimation), ``engine`` (pure orchestrator), ``mavlink``
(the edge: decode, encode, links, tlog), ``service`` (asyncio live driver),
``replay`` (tlog driver), ``sim`` (simulated flights with truth),
``evaluate`` and ``report`` (scoring against truth).
"""

__version__ = "0.1.0"
