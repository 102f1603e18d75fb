"""The ground station's tracking on real telemetry: the dynamic channel against Singer and CV.

Run: ``python bench/tracking_real.py`` (skips with a stated reason without the data).

Real autopilot logs (``../shared/realdata/flights``, relative to the project root)
carry the streams a telemetry link brings down: GLOBAL_POSITION_INT (the
autopilot's position), ATTITUDE and the IMU (SCALED_IMU, or RAW_IMU on a ground
station's recording). There is no truth: the autopilot's own positions are the
reference, and a filter is scored by how well it predicts positions it has not
been given, from a station placed 150 m from the flight's middle, on the ground:

* ``real_plane_erle_2014-12-04`` (ArduPlane, every stream at 10 Hz): decimated to
  1, 2 and 5 Hz telemetry; the pointing error (deg) at the positions between the
  telemetry samples, predicted from the last sample, while the aircraft moves
  (> 8 m/s) and is more than 50 m from the station;
* ``real_gcs_copter_phoenix_mission1`` (ArduCopter, a ground station's recording at
  about 1 Hz) is not used: its GLOBAL_POSITION_INT interleaves two position
  streams 93 m apart in height (one of them at rest), so there is no single
  track to predict;
* ``loss``: 5 s without any telemetry every 60 s; the largest pointing error at the
  first position after each loss (deg, worst of the losses).

``<=3σ`` is the share of scored positions within 3 times the filter's own
pointing σ; ``NIS`` the positions' mean normalised innovation square (3 expected).
``dynamic+IMU``: the dynamic channel given every ATTITUDE/IMU sample of the log
(10 Hz) with the decimated positions (a link that carries them faster);
``model*``: each model at its best process noise for the rate, by the search of
``bench/tracking.py`` (``--no-search``: the defaults only).
"""

from __future__ import annotations

import argparse
import math
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from companion.mavlink.tlog import TlogReader  # noqa: E402
from companion.nav.frames import LocalFrame  # noqa: E402
from companion.nav.rotations import euler_to_mat_nb  # noqa: E402
from companion.nav.tracking import (  # noqa: E402
    MODELS,
    Tracker,
    TrackerConfig,
    acceleration_ned,
    pointing_error_rad,
)

ROOT = Path(__file__).resolve().parent.parent
FLIGHTS = ROOT.parent / "shared" / "realdata" / "flights"
G_MPS2 = 9.80665
STATION_OFFSET_M = 150.0
LOSS_EVERY_S = 60.0
LOSS_S = 5.0


@dataclass
class Streams:
    t_pos: np.ndarray
    pos_ned_m: np.ndarray
    speed_mps: np.ndarray
    t_att: np.ndarray
    euler_rad: np.ndarray
    t_imu: np.ndarray
    f_b_mps2: np.ndarray


def load(path: Path) -> Streams:
    """GLOBAL_POSITION_INT, ATTITUDE and one IMU stream of the autopilot (component 1)."""
    gpi, att = [], []
    imu: dict[str, list[tuple[float, float, float, float]]] = {}
    for _, msg in TlogReader(path):
        kind = msg.get_type()
        if msg.get_srcComponent() != 1:
            continue
        if kind == "GLOBAL_POSITION_INT":
            gpi.append(
                (msg.time_boot_ms / 1e3, msg.lat * 1e-7, msg.lon * 1e-7, msg.alt / 1e3,
                 msg.vx / 100.0, msg.vy / 100.0)
            )  # fmt: skip
        elif kind == "ATTITUDE":
            att.append((msg.time_boot_ms / 1e3, msg.roll, msg.pitch, msg.yaw))
        elif kind in ("SCALED_IMU", "SCALED_IMU2", "RAW_IMU"):
            t = msg.time_boot_ms / 1e3 if hasattr(msg, "time_boot_ms") else msg.time_usec / 1e6
            k = G_MPS2 / 1000.0  # mG (RAW_IMU: ArduPilot sends mG too)
            imu.setdefault(kind, []).append((t, msg.xacc * k, msg.yacc * k, msg.zacc * k))
    kind = next(k for k in ("SCALED_IMU", "SCALED_IMU2", "RAW_IMU") if k in imu)
    g = np.array(sorted(set(gpi)))
    a = np.array(sorted(att))
    i = np.array(sorted(imu[kind]))
    lat0, lon0 = math.radians(float(np.median(g[:, 1]))), math.radians(float(np.median(g[:, 2])))
    ground = float(np.percentile(g[:, 3], 2)) - 2.0
    frame = LocalFrame(lat0, lon0, ground)
    ned = np.array([frame.lla_to_ned(math.radians(p[1]), math.radians(p[2]), p[3]) for p in g])
    ned[:, 0] -= STATION_OFFSET_M  # the station 150 m south of the middle: it is north of it
    near = np.linalg.norm(ned, axis=1) < 5000.0  # no-fix positions (0, 0) are not positions
    return Streams(
        g[near, 0], ned[near], np.hypot(g[near, 4], g[near, 5]), a[:, 0], a[:, 1:], i[:, 0],
        i[:, 1:],
    )  # fmt: skip


def _nearest(t: np.ndarray, at: float) -> int:
    j = int(np.searchsorted(t, at))
    if j <= 0:
        return 0
    if j >= len(t):
        return len(t) - 1
    return j if t[j] - at < at - t[j - 1] else j - 1


def _dynamics(trk: Tracker, s: Streams, t: float, ji: int) -> None:
    """One IMU sample with the nearest ATTITUDE (within 0.2 s) as z2."""
    ja = _nearest(s.t_att, t)
    if abs(s.t_att[ja] - t) < 0.2 and trk.started:
        mat = euler_to_mat_nb(*(float(x) for x in s.euler_rad[ja]))
        trk.acceleration(t, acceleration_ned(mat, s.f_b_mps2[ji], G_MPS2), mat)


def run(
    s: Streams,
    model: str,
    step: int,
    min_speed: float,
    cfg: TrackerConfig | None = None,
    all_imu: bool = False,
) -> dict[str, float]:
    """Every ``step``-th position is telemetry, the others are scored (``cfg``: the filter's
    configuration, default :class:`TrackerConfig`; ``all_imu``: every IMU sample of the log
    is telemetry, paired with the nearest ATTITUDE, not only those beside a position)."""
    trk = Tracker(model, cfg)  # type: ignore[arg-type]
    i_imu = 0  # the next IMU sample not yet given (all_imu)
    errs, cover, loss = [], [], []
    t0 = float(s.t_pos[0])
    was_lost = False

    def lost(t: float) -> bool:
        return ((t - t0) % LOSS_EVERY_S) < LOSS_S and t - t0 > LOSS_EVERY_S / 2

    for k, t in enumerate(s.t_pos):
        t = float(t)
        rel = s.pos_ned_m[k]
        # all_imu: the IMU samples heard before this position's time (none in a loss)
        while all_imu and i_imu < len(s.t_imu) and s.t_imu[i_imu] < t:
            if not lost(float(s.t_imu[i_imu])):
                _dynamics(trk, s, float(s.t_imu[i_imu]), i_imu)
            i_imu += 1
        if lost(t):
            was_lost = True
            continue
        moving = s.speed_mps[k] > min_speed and float(np.linalg.norm(rel)) > 50.0
        est = trk.estimate(t) if trk.positions > 20 else None
        if est is not None and moving:
            e = pointing_error_rad(est, rel)
            if was_lost:  # the first position after a loss, predicted through it
                loss.append(e)
            elif k % step != 0:
                errs.append(e)
                cover.append(e <= 3.0 * est.pointing_sigma_rad)
        was_lost = False
        if k % step != 0:
            continue
        if all_imu:
            trk.position(t, rel)
            continue
        trk.position(t, rel)
        ja, ji = _nearest(s.t_att, t), _nearest(s.t_imu, t)
        if abs(s.t_att[ja] - t) < 0.6 and abs(s.t_imu[ji] - t) < 0.6:
            mat = euler_to_mat_nb(*(float(x) for x in s.euler_rad[ja]))
            trk.acceleration(t, acceleration_ned(mat, s.f_b_mps2[ji], G_MPS2), mat)
    deg = np.degrees(np.array(errs))
    return {
        "rms": float(np.sqrt(np.mean(deg**2))),
        "p95": float(np.percentile(deg, 95)),
        "cover": float(np.mean(cover)),
        "loss": math.degrees(max(loss)) if loss else math.nan,
        "nis": trk.nis_position / max(trk.positions - 1, 1),
        "n": float(len(deg)),
    }


SEARCH = {
    "singer": [(sm, tau) for sm in (1.0, 2.0, 3.0, 5.0) for tau in (3.0, 10.0, 30.0)],
    "dynamic": [(sm, tau) for sm in (1.0, 2.0, 3.0, 5.0) for tau in (3.0, 10.0, 30.0)],
    "cv": [(q, 0.0) for q in (0.3, 1.0, 3.0, 10.0, 30.0)],
}
"""The process-noise search of ``bench/tracking.py``: σ_m/τ for Singer and the dynamic
channel, the white acceleration's PSD for constant velocity."""


def _config(model: str, point: tuple[float, float]) -> TrackerConfig:
    if model == "cv":
        return TrackerConfig(cv_acc_psd=point[0])
    return TrackerConfig(singer_sigma_mps2=point[0], singer_tau_s=point[1])


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument(
        "--no-search", action="store_true", help="skip the process-noise search (defaults only)"
    )
    args = ap.parse_args(argv)
    cases = [("real_plane_erle_2014-12-04", [(1, 10), (2, 5), (5, 2)], 8.0)]
    if not FLIGHTS.is_dir():
        print(f"skipped: {FLIGHTS} is absent (the real logs are not part of the project)")
        return 0
    print(
        "pointing error of predicted positions, deg (the autopilot's own positions as "
        "reference); +IMU: every ATTITUDE/IMU sample of the log (10 Hz), not only those beside "
        "a position; model*: its best process noise for this rate (σ_m/τ; CV: q)"
    )
    print(
        f"{'flight':<34}{'Hz':>4} {'model':<15}{'RMS':>7}{'p95':>7}{'loss':>7}{'<=3σ':>7}"
        f"{'NIS':>6}{'n':>6}"
    )
    for name, rates, min_speed in cases:
        path = FLIGHTS / name / f"{name}.tlog"
        if not path.is_file():
            print(f"{name}: skipped, {path} is absent")
            continue
        s = load(path)
        for rate, step in rates:
            rows = {m: run(s, m, step, min_speed) for m in MODELS}
            rows["dynamic+IMU"] = run(s, "dynamic", step, min_speed, all_imu=True)
            if not args.no_search:
                for m in MODELS:
                    scored = [(run(s, m, step, min_speed, _config(m, pt)), pt) for pt in SEARCH[m]]
                    r, pt = min(scored, key=lambda x: x[0]["rms"])
                    label = f"{pt[0]:g}" if m == "cv" else f"{pt[0]:g}/{pt[1]:g}"
                    rows[f"{m}* {label}"] = r
            for m, r in rows.items():
                hz = f"{rate:g}"
                print(
                    f"{name:<34}{hz:>4} {m:<15}{r['rms']:>7.2f}{r['p95']:>7.2f}{r['loss']:>7.2f}"
                    f"{r['cover']:>7.1%}{r['nis']:>6.2f}{r['n']:>6.0f}"
                )
            rms = {m.split(" ")[0]: r["rms"] for m, r in rows.items()}
            line = (
                f"{'':<39}Singer/dynamic RMS {rms['singer'] / rms['dynamic']:.2f}x,"
                f" CV/dynamic {rms['cv'] / rms['dynamic']:.2f}x,"
                f" Singer/dynamic+IMU {rms['singer'] / rms['dynamic+IMU']:.2f}x"
            )
            if not args.no_search:
                line += (
                    f", Singer*/dynamic {rms['singer*'] / rms['dynamic']:.2f}x,"
                    f" Singer*/dynamic* {rms['singer*'] / rms['dynamic*']:.2f}x"
                )
            print(line)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
