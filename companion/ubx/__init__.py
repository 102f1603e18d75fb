"""u-blox UBX at the edge: raw observations from a recorded file or a serial port.

Decodes RXM-RAWX, RXM-SFRBX and NAV-PVT with pyubx2 into the pure records of
:mod:`companion.raw.obs`; nothing here estimates anything.
"""
