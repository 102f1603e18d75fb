"""Make the bundled cut of walk_0827 (run from the project root; see README.md here).

Keeps, unmodified and in stream order, the RXM-RAWX and NAV-PVT frames of the first
``SECONDS`` of the recording, then every GPS L1 C/A and Galileo E1-B RXM-SFRBX frame of
the whole recording (so every ephemeris the full file yields is decodable); and the
``.pos`` lines of the kept epochs.
"""

from __future__ import annotations

import sys
from pathlib import Path

from pyubx2 import UBX_PROTOCOL, UBXReader

SECONDS = 40.0
HERE = Path(__file__).resolve().parent


def main(src_dir: str) -> None:
    src = Path(src_dir)
    head, nav = [], []
    t0 = None
    last_tow = 0.0
    with open(src / "gnss_1730.ubx", "rb") as f:
        for raw, msg in UBXReader(f, protfilter=UBX_PROTOCOL):
            if msg.identity == "RXM-RAWX":
                t0 = msg.rcvTow if t0 is None else t0
                if msg.rcvTow - t0 <= SECONDS:
                    head.append(raw)
                    last_tow = msg.rcvTow
            elif msg.identity == "NAV-PVT":
                if t0 is None or (int.from_bytes(raw[6:10], "little") * 1e-3) <= last_tow + 0.01:
                    head.append(raw)
            elif msg.identity == "RXM-SFRBX":
                gnss, sig = int(msg.gnssId), int(msg.sigId)
                if (gnss, sig) in ((0, 0), (2, 1)):
                    nav.append(raw)
    (HERE / "gnss_1730_cut.ubx").write_bytes(b"".join(head + nav))
    lines = (src / "gnss_1730_sf.pos").read_text(encoding="utf-8").splitlines(keepends=True)
    n_epochs = sum(1 for r in head if r[2:4] == b"\x02\x15")
    header = [ln for ln in lines if ln.startswith("%")]
    body = [ln for ln in lines if not ln.startswith("%")][:n_epochs]
    (HERE / "gnss_1730_sf_cut.pos").write_text("".join(header + body), encoding="utf-8")


if __name__ == "__main__":
    main(sys.argv[1] if len(sys.argv) > 1 else "../shared/realdata/gnss_imu/walk_0827")
