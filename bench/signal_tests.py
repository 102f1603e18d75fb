"""Bench: the raw link's signal tests (spoofing and jamming evidence) on real and simulated data.

Real data (the noise figures the tests' thresholds scale, and what they say there):

* the walk (``../shared/realdata/gnss_imu/walk_0827/gnss_1730.ubx``, a handheld
  multi-band u-blox at 4 Hz, 134 s; ``--ubx`` for another file, e.g. the bundled cut
  ``tests/data/walk_0827/gnss_1730_cut.ubx``): its C/N0, the statistics each test
  compares, and the epochs where a test tripped (none expected);
* the receivers' own jamming indicator (u-blox ``jamInd``) in the real autopilot logs
  (``../shared/realdata/flights``: DataFlash UBX1, PX4 ``vehicle_gps_position``), and
  the limit it gives.

Simulated truth (``companion.raw.simulate``, the walk's broadcast orbits, a cruise at
40 m/s, 4 Hz, realistic C/N0): ``--flights`` seeded flights per case, each signature
from 40 s of a 100 s flight: the time from its start to the first epoch whose verdict
cites it (and the missed ones); and the verdicts that say jamming or spoofing on clean
epochs (the clean flights, ``--clean-s`` long, and the first 40 s of the others), with
the hours of clean epochs they came from.

Run: ``python bench/signal_tests.py [--flights 10] [--seed 1] [--real DIR] [--ubx FILE]``
(a few minutes; run it under ``nice``). Skips the real data, saying so, where it is
absent.
"""

from __future__ import annotations

import argparse
import math
import sys
from collections import defaultdict
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from companion.nav.frames import ecef_to_geodetic, geodetic_to_ecef_m  # noqa: E402
from companion.raw.broadcast import collect_ephemerides  # noqa: E402
from companion.raw.geometry import enu_rotation  # noqa: E402
from companion.raw.signal import SignalTestConfig, SignalTests  # noqa: E402
from companion.raw.simulate import (  # noqa: E402
    Cn0Model,
    Jamming,
    RawSimConfig,
    SpoofCapture,
    simulate_flight,
)
from companion.ubx.reader import read_file  # noqa: E402
from companion.ubx.session import load_session  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
REAL = ROOT.parent / "shared" / "realdata"
CUT = ROOT / "tests" / "data" / "walk_0827"
START_S = 40.0
DURATION_S = 100.0
RATE_HZ = 4.0
NO_CHANGE = dict(jump_dbhz=0.0, converge_s=math.inf, spread_dbhz=0.0, clock_step_m=0.0)
CASES: dict[str, tuple[str, SpoofCapture | None, Jamming | None]] = {
    "clean": ("", None, None),
    "capture (C/N0 +8 dB, 1 us clock step)": ("C/N0 up", SpoofCapture(START_S), None),
    "  its C/N0 converging (3 s)": ("spread", SpoofCapture(START_S), None),
    "capture, +3 dB, no clock step": (
        "spread",
        SpoofCapture(START_S, jump_dbhz=3.0, clock_step_m=0.0),
        None,
    ),
    "clock step 10 m alone": (
        "clock step",
        SpoofCapture(START_S, **{**NO_CHANGE, "clock_step_m": 10.0}),  # type: ignore[arg-type]
        None,
    ),
    "code drag 1 m/s alone": (
        "code moves",
        SpoofCapture(START_S, **NO_CHANGE, code_drag_enu_mps=(1.0, 0.0, 0.0)),  # type: ignore[arg-type]
        None,
    ),
    "code drag 3 m/s alone": (
        "code moves",
        SpoofCapture(START_S, **NO_CHANGE, code_drag_enu_mps=(3.0, 0.0, 0.0)),  # type: ignore[arg-type]
        None,
    ),
    "jamming, C/N0 -1 dB/s": ("below its baseline", None, Jamming(START_S)),
    "jamming, C/N0 -0.2 dB/s": ("below its baseline", None, Jamming(START_S, ramp_dbhz_per_s=0.2)),
}


def _pct(values: list[float] | np.ndarray, qs: tuple[float, ...] = (0, 1, 50, 100)) -> str:
    v = np.asarray(values, float)
    return " ".join(f"p{q:g} {np.percentile(v, q):.3f}" for q in qs)


def walk_statistics(path: Path) -> None:
    """The walk's C/N0 and the tests' statistics (what the thresholds were set from)."""
    epochs, nav, pvt, _ = read_file(str(path))
    ephs, _ = collect_ephemerides(nav)
    print(f"\n== real: {path} ({len(epochs)} epochs, {len(ephs)} ephemerides)")
    cn0 = [s.cn0_dbhz for e in epochs for s in e.signals]
    l1 = [s.cn0_dbhz for e in epochs for s in e.signals if s.band in ("L1", "E1")]
    print(f"C/N0, every signal, dB-Hz: {_pct(cn0, (0, 5, 50, 95, 100))}")
    print(f"C/N0, L1/E1 signals:      {_pct(l1, (0, 5, 50, 95, 100))}")
    # one signal's C/N0 change between epochs, and about its baseline
    tau = SignalTestConfig().baseline_tau_s
    steps, devs = [], []
    prev: dict[tuple[str, int, str], float] = {}
    base: dict[tuple[str, int, str], tuple[float, float]] = {}
    for e in epochs:
        cur = {(s.system, s.sv, s.band): s.cn0_dbhz for s in e.signals if s.band in ("L1", "E1")}
        steps += [v - prev[k] for k, v in cur.items() if k in prev]
        devs += [v - base[k][0] for k, v in cur.items() if k in base]
        for k, v in cur.items():
            old = base.get(k)
            w = 1.0 if old is None else 1.0 - math.exp(-(e.tow_s - old[1]) / tau)
            base[k] = (v if old is None else old[0] + w * (v - old[0]), e.tow_s)
        prev = cur
    mad = 1.4826 * float(np.median(np.abs(np.asarray(steps) - np.median(steps))))
    print(f"one signal's C/N0 step between epochs: std {np.std(steps):.2f}, MAD-sigma {mad:.2f}")
    mad = 1.4826 * float(np.median(np.abs(np.asarray(devs) - np.median(devs))))
    print(
        f"one signal's C/N0 about its {tau:.0f} s baseline: std {np.std(devs):.2f}, "
        f"MAD-sigma {mad:.2f}"
    )
    by_ms = {round(p.itow_s * 1000.0): p for p in pvt}
    tests = SignalTests()
    stats: dict[str, list[float]] = defaultdict(list)
    tripped = []
    for e in epochs:
        ms = round(e.tow_s * 1000.0)
        p = next((by_ms[k] for k in range(ms - 20, ms + 21) if k in by_ms), None)
        x = None
        if p is not None:
            lat, lon = math.radians(p.lat_deg), math.radians(p.lon_deg)
            x = np.array(geodetic_to_ecef_m(lat, lon, p.height_m))
        v = tests.on_epoch(e, x, ephs)
        for k, val in tests.stats.items():
            stats[k].append(val)
        if v.jamming.value == "detected" or v.spoofing.value == "detected":
            tripped.append(e.tow_s)
    print("the tests' statistics over the walk (p0 p1 p50 p100):")
    for k in sorted(stats):
        print(f"  {k:16s} {_pct(stats[k])}")
    print(f"trips of each test: {tests.trips or 'none'}; epochs with a verdict: {len(tripped)}")


def jam_indicator_statistics(real: Path) -> None:
    """u-blox jamInd in the real autopilot logs."""
    flights = real / "flights"
    if not flights.is_dir():
        print(f"\n== real logs: skipped ({flights} absent)")
        return
    from pymavlink import DFReader
    from pyulog import ULog

    from companion.integrity.signal import SignalMonitorConfig

    print("\n== real logs: the receivers' jamming indicator (jamInd, of 255)")
    pooled = []
    for path in sorted(flights.glob("*/*")):
        values: list[float] = []
        if path.suffix.lower() == ".bin":
            r = DFReader.DFReader_binary(str(path), zero_time_base=True)
            while (m := r.recv_match(type=["UBX1"])) is not None:
                values.append(float(m.jamInd))
        elif path.suffix == ".ulg":
            for d in ULog(str(path)).data_list:
                if d.name == "vehicle_gps_position" and "jamming_indicator" in d.data:
                    values += d.data["jamming_indicator"].astype(float).tolist()
        if values:
            pooled += values
            v = np.asarray(values)
            print(
                f"  {path.name:40s} n {len(v):4d} mean {v.mean():5.1f} "
                f"std {v.std():4.1f} max {v.max():3.0f}"
            )
    if pooled:
        v = np.asarray(pooled)
        limit = SignalMonitorConfig().jam_indicator_limit
        print(f"  pooled: n {len(v)} mean {v.mean():.1f} std {v.std():.1f} max {v.max():.0f}")
        print(f"  limit (P_FA 1e-6): {limit:.3f} = {limit * 255:.0f} of 255")


def _path_fn(x0: np.ndarray, r_enu: np.ndarray):  # type: ignore[no-untyped-def]
    def path(t: float) -> np.ndarray:
        enu = np.array([40.0 * t, 200.0 * (1.0 - math.cos(t / 50.0)), 300.0])
        return np.asarray(x0 + r_enu.T @ enu)

    return path


def simulated(flights: int, seed: int, clean_s: float) -> None:
    s = load_session(str(CUT / "gnss_1730_cut.ubx"), str(CUT / "gnss_1730_sf_cut.pos"))
    lat, lon, _ = ecef_to_geodetic(*s.x0_ecef_m)
    path = _path_fn(s.x0_ecef_m, enu_rotation(lat, lon))
    tow0 = s.epochs[0].tow_s
    print(f"\n== simulated: {flights} flights per case at {RATE_HZ:.0f} Hz, a signature from "
          f"{START_S:.0f} s of {DURATION_S:.0f} s, clean flights {clean_s:.0f} s")  # fmt: skip
    print(f"{'case':42s} {'seen':>6s} {'median s':>9s} {'max s':>7s}  false trips")
    for name, (word, spoof, jam) in CASES.items():
        delays: list[float] = []
        missed = 0
        false_trips = 0
        epochs_n = 0
        for k in range(flights):
            cfg = RawSimConfig(rate_hz=RATE_HZ, cn0=Cn0Model(), spoof=spoof, jam=jam)
            rng = np.random.default_rng(seed + k)
            duration = DURATION_S if word else clean_s
            epochs, truth = simulate_flight(s.ephemerides, tow0, duration, path, rng, cfg)
            tests = SignalTests()
            seen = None
            for e, x in zip(epochs, truth, strict=True):
                v = tests.on_epoch(e, x, s.ephemerides)
                t = round((e.tow_s - tow0) * RATE_HZ) / RATE_HZ
                cites = any(word in text for text in v.spoofing_evidence + v.jamming_evidence)
                if word and seen is None and cites and t >= START_S:
                    seen = t - START_S
                if (t < START_S or not word) and (
                    v.jamming.value == "detected" or v.spoofing.value == "detected"
                ):
                    false_trips += 1
                epochs_n += 1 if (t < START_S or not word) else 0
            if word:
                if seen is None:
                    missed += 1
                else:
                    delays.append(seen)
        hours = epochs_n / RATE_HZ / 3600.0
        rate = f"{false_trips} in {hours:.2f} h of clean epochs"
        if not word:
            print(f"{name:42s} {'':>6s} {'':>9s} {'':>7s}  {rate}")
            continue
        med = f"{np.median(delays):.2f}" if delays else "-"
        mx = f"{max(delays):.2f}" if delays else "-"
        print(f"{name:42s} {flights - missed:>3d}/{flights:<2d} {med:>9s} {mx:>7s}  {rate}")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--flights", type=int, default=10)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--real", type=Path, default=REAL, help="the real data's folder")
    ap.add_argument("--ubx", type=Path, help="the raw recording (default: the real walk)")
    ap.add_argument("--clean-s", type=float, default=600.0, help="length of a clean flight")
    args = ap.parse_args()
    ubx = args.ubx or args.real / "gnss_imu" / "walk_0827" / "gnss_1730.ubx"
    if ubx.is_file():
        walk_statistics(ubx)
    else:
        print(f"== real walk: skipped ({ubx} absent; --ubx {CUT}/gnss_1730_cut.ubx)")
    jam_indicator_statistics(args.real)
    simulated(args.flights, args.seed, args.clean_s)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
