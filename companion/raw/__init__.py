"""Positioning from a receiver's raw observations (pure: no I/O, no clock).

Kim, Walter and Powell's time-differenced precise relative positioning (T-D PRP) and
their solution-separation RAIM (FIS-RAIM), on carrier phase decoded at the edge
(``companion.ubx``) into :mod:`companion.raw.obs` records.
"""
