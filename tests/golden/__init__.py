"""Golden outputs: replays and simulated flights compared with recorded ones at a tolerance.

=============  =====================================================================
cases.py       the cases: every bundled flight under its configurations, the real
               flights beside the repository
record.py      what is recorded of a replay, and its two files in ``replays/``
rules.py       the tolerances: what "the same output" means (the one place)
compare.py     two records (or two tlogs) compared by those rules
replays.py     ``python -m tests.golden.replays [--record]``: compare, record again
flights.py     ``python -m tests.golden.flights [--record]``: the simulator's fixtures
probe.py       ``python -m tests.golden.probe``: the cases with their inputs nudged
=============  =====================================================================

docs/replay.md, "Golden outputs".
"""
