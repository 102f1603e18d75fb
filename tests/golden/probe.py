"""Where can a last bit flip a decision? Replay the golden cases with the inputs nudged.

    python -m tests.golden.probe                    # every case, nudged by 1e-13
    python -m tests.golden.probe --rel 1e-11 -k taxi

Another CPU's arithmetic moves a double by about one unit in its last place (2.2e-16
relative) at each operation. This replays each case with every IMU reading and every
attitude the autopilot sent multiplied by ``1 + rel * u`` (``u`` uniform in [-1, 1],
seeded per case): a perturbation of the same kind, some 450 times larger by default,
that reaches every estimate, covariance and test statistic. The outputs are compared
with the recorded ones by the rules of :mod:`tests.golden.rules`, as
``tests/test_replay_golden.py`` compares them. A case beyond tolerance points at a
decision (a gate, a reset, an optimiser's step) that a value within ``rel`` of its
threshold takes: the listing says which output moved first and where.
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
import zlib
from typing import Any
from unittest import mock

import numpy as np

from tests.golden import cases as golden_cases
from tests.golden import replays as golden
from tests.golden.compare import compare, failures

DEFAULT_REL = 1e-13


def _nudged_decode(rel: float, rng: np.random.Generator) -> Any:
    from companion.mavlink.decode.decoder import Decoder
    from companion.types import AttitudeSample, ImuSample

    original = Decoder.decode

    def nudge(x: Any) -> Any:
        arr = np.asarray(x, dtype=np.float64)
        return arr * (1.0 + rel * rng.uniform(-1.0, 1.0, arr.shape))

    def decode(self: Decoder, msg: Any, t_rx_s: float) -> list[Any]:
        out = []
        for s in original(self, msg, t_rx_s):
            if isinstance(s, ImuSample):
                s = dataclasses.replace(
                    s, acc_b_mps2=nudge(s.acc_b_mps2), gyro_b_radps=nudge(s.gyro_b_radps)
                )
            elif isinstance(s, AttitudeSample):
                roll, pitch, yaw = nudge([s.roll_rad, s.pitch_rad, s.yaw_rad])
                s = dataclasses.replace(
                    s, roll_rad=float(roll), pitch_rad=float(pitch), yaw_rad=float(yaw)
                )
            out.append(s)
        return out

    return mock.patch.object(Decoder, "decode", decode)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rel", type=float, default=DEFAULT_REL, help="relative nudge")
    parser.add_argument("-k", action="append", default=[], metavar="TEXT")
    args = parser.parse_args(argv)
    every = golden_cases.cases() + golden_cases.realdata_cases()
    chosen = [c for c in every if not args.k or any(k in c[0] for k in args.k)]
    moved = 0
    for name, tlog, cfg in chosen:
        ref = golden.recorded(name)
        if ref is None:
            print(f"(none)   {name}")
            continue
        rng = np.random.default_rng(zlib.crc32(name.encode()))
        with _nudged_decode(args.rel, rng):
            new, _ = golden.replay_case(name, tlog, cfg)
        differences = compare(ref, new)
        bad = failures(differences)
        if bad:
            moved += 1
            print(f"MOVED    {name}: {len(bad)} beyond tolerance", flush=True)
            for d in bad[:5]:
                print(f"    {d.describe()}")
        else:
            largest = differences[0].describe() if differences else "no difference"
            print(f"agrees   {name}: largest {largest}", flush=True)
    print(f"{len(chosen)} cases nudged by {args.rel:g}: {moved} beyond tolerance")
    return 1 if moved else 0


if __name__ == "__main__":
    sys.exit(main())
