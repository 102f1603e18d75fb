"""Statistics of an autopilot's telemetry that a simulator must reproduce (``bench/realism.py``).

The same function runs on a real .tlog and on a simulated flight's .tlog: both
are decoded by the project's own decoder (:class:`companion.mavlink.decode.Decoder`);
SCALED_PRESSURE (the decoder's barometer samples keep no raw hPa) is read from the
raw messages. Every statistic is None where the log does not show it (no rest
period, no GNSS, no barometer).

Rest: IMU samples in a 2 s window (at least 6 samples) whose gyro norm stays below
0.05 rad/s and whose specific-force norm varies by less than 0.3 m/s^2 (standard
deviation), and whose speed (see ``REST_SPEED_MPS``) is low: the vehicle stands still,
engines on or off.
"""

from __future__ import annotations

import collections
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from companion.mavlink.decode.decoder import Decoder
from companion.mavlink.tlog import read_tlog
from companion.sim.trajectory import euler_to_mat_nb_batch
from companion.types import AttitudeSample, AutopilotSolution, FixType, GnssFix, ImuSample

G0_MPS2 = 9.80665
REST_WINDOW_S = 2.0
REST_SPEED_MPS = 0.5
"""...and, where the autopilot's velocity (GLOBAL_POSITION_INT) or a 3D fix is known within
0.5 s, the speed stays below this (a smooth simulated cruise is otherwise still)."""
REST_MIN_SAMPLES = 6
"""A rest window spans at least this many IMU samples (2 s hold 2 samples at 1 Hz)."""
REST_GYRO_RADPS = 0.05
REST_ACC_STD_MPS2 = 0.3
_DATA_STREAMS = frozenset(
    ("RAW_IMU", "SCALED_IMU", "SCALED_IMU2", "SCALED_IMU3", "HIGHRES_IMU", "ATTITUDE",
     "ATTITUDE_QUATERNION", "GPS_RAW_INT", "GLOBAL_POSITION_INT")
)  # fmt: skip
GAP_MIN_S = 1.0
"""A stream gap: more than this, and more than 4 median intervals, between consecutive
messages of the stream, s."""
SCATTER_BLOCK_S = 10.0


@dataclass(slots=True)
class LogStats:
    """The statistics of one log (None: the log does not show it)."""

    name: str
    stats: dict[str, float | None] = field(default_factory=dict)


def _rest_mask(
    t: np.ndarray, acc: np.ndarray, gyro: np.ndarray, speed: tuple[np.ndarray, np.ndarray]
) -> np.ndarray:
    """True for IMU samples inside a still window (see the module doc)."""
    ts, vs = speed
    n = len(t)
    mask = np.zeros(n, bool)
    if n < 3:
        return mask
    gn = np.linalg.norm(gyro, axis=1)
    an = np.linalg.norm(acc, axis=1)
    win = max(REST_WINDOW_S, REST_MIN_SAMPLES * float(np.median(np.diff(t))))
    edges = np.arange(t[0], t[-1] + win, win)
    idx = np.searchsorted(t, edges)
    for a, b in zip(idx[:-1], idx[1:], strict=True):
        if b - a < 3:
            continue
        if gn[a:b].max() < REST_GYRO_RADPS and an[a:b].std() < REST_ACC_STD_MPS2:
            i, k = np.searchsorted(ts, [t[a] - 0.5, t[b - 1] + 0.5])
            if k == i or vs[i:k].max() < REST_SPEED_MPS:
                mask[a:b] = True
    return mask


def _gaps(t: np.ndarray, duration_s: float) -> tuple[float | None, float | None]:
    """(gaps > GAP_MIN_S per hour, longest gap s) of a stream's receive times."""
    if len(t) < 2 or duration_s <= 0:
        return None, None
    d = np.diff(np.sort(t))
    big = d[d > max(GAP_MIN_S, 4.0 * float(np.median(d)))]
    return float(len(big) * 3600.0 / duration_s), float(d.max())


def log_stats(name: str, path: Path) -> LogStats:
    """Decode a .tlog and compute its statistics."""
    dec = Decoder()
    imu: dict[tuple[int, str], list[ImuSample]] = collections.defaultdict(list)
    att: list[AttitudeSample] = []
    spd: list[tuple[float, float]] = []
    gnss: list[GnssFix] = []
    baro_t: list[float] = []
    baro_hpa: list[float] = []
    rx_by_type: dict[str, list[float]] = collections.defaultdict(list)
    n_msgs = 0
    t_first = t_last = None
    for t_rx, msg in read_tlog(path):
        n_msgs += 1
        t_first = t_rx if t_first is None else t_first
        t_last = t_rx
        typ = msg.get_type()
        rx_by_type[typ].append(t_rx)
        if typ == "SCALED_PRESSURE":
            baro_t.append(msg.time_boot_ms / 1e3)
            baro_hpa.append(float(msg.press_abs))
        for s in dec.decode(msg, t_rx):
            if isinstance(s, ImuSample):
                imu[(s.imu_id, s.source)].append(s)
            elif isinstance(s, AttitudeSample):
                att.append(s)
            elif isinstance(s, GnssFix) and s.receiver_id == 0:
                gnss.append(s)
                if s.fix_type >= FixType.FIX_3D:
                    spd.append((s.t_s, s.ground_speed_mps))
            elif isinstance(s, AutopilotSolution):
                spd.append((s.t_s, float(np.linalg.norm(s.vel_ned_mps))))
    out: dict[str, float | None] = {}
    duration = (t_last - t_first) if t_first is not None and t_last is not None else 0.0
    out["duration_s"] = duration
    out["reboots"] = float(dec.reboots)
    # the fastest IMU stream
    main = max(imu.values(), key=len) if imu else []
    out["imu_units"] = float(len(imu))
    sp = np.array(sorted(spd)).reshape(-1, 2)
    speed = (sp[:, 0], sp[:, 1])
    out.update(_imu_stats(main, att, speed))
    out.update(_gnss_stats(gnss, main, speed))
    out.update(_stream_stats(rx_by_type, duration, main))
    out.update(_baro_stats(np.array(baro_t), np.array(baro_hpa)))
    return LogStats(name, out)


def _imu_stats(
    imu: list[ImuSample], att: list[AttitudeSample], speed: tuple[np.ndarray, np.ndarray]
) -> dict[str, float | None]:
    out: dict[str, float | None] = dict.fromkeys(
        ("imu_rate_hz", "imu_dt_jitter_ms", "imu_t_backwards_pct", "rest_fraction",
         "rest_sf_resid_mps2", "rest_tilt_disagree_deg", "rest_acc_noise_mps2",
         "rest_gyro_bias_dps",
         "inair_acc_hp_mps2"),
        None,
    )  # fmt: skip
    if len(imu) < 10:
        return out
    t = np.array([s.t_s for s in imu])
    acc = np.array([s.acc_b_mps2 for s in imu])
    gyro = np.array([s.gyro_b_radps for s in imu])
    dt = np.diff(t)
    out["imu_t_backwards_pct"] = float(100.0 * np.mean(dt <= 0.0))
    order = np.argsort(t, kind="stable")
    t, acc, gyro = t[order], acc[order], gyro[order]
    keep = np.concatenate([[True], np.diff(t) > 0.0])
    t, acc, gyro = t[keep], acc[keep], gyro[keep]
    dt = np.diff(t)
    med = float(np.median(dt))
    out["imu_rate_hz"] = 1.0 / med
    normal = dt[dt < 5.0 * med]
    # robust jitter: median absolute deviation of the interval, as a sigma, ms
    out["imu_dt_jitter_ms"] = float(1.4826 * np.median(np.abs(normal - med)) * 1e3)
    rest = _rest_mask(t, acc, gyro, speed)
    out["rest_fraction"] = float(rest.mean())
    an = np.linalg.norm(acc, axis=1)
    if rest.sum() >= 10:
        ra = acc[rest]
        out["rest_acc_noise_mps2"] = float(np.median(np.std(ra - ra.mean(axis=0), axis=0)))
        # the gyro's mean at rest is its bias (Earth rate, 0.004 deg/s, is below it)
        out["rest_gyro_bias_dps"] = float(np.degrees(np.linalg.norm(gyro[rest].mean(axis=0))))
    # in the air, or moving: high-passed specific force (vibration as delivered)
    moving = ~rest
    if moving.sum() >= 20:
        hp = an - np.convolve(an, np.ones(5) / 5.0, mode="same")
        out["inair_acc_hp_mps2"] = float(np.std(hp[moving][5:-5])) if moving.sum() > 30 else None
    if len(att) >= 5 and rest.sum() >= 10:
        ta = np.array([s.t_s for s in att])
        oa = np.argsort(ta, kind="stable")
        ta = ta[oa]
        eul = np.array([[s.roll_rad, s.pitch_rad, s.yaw_rad] for s in att])[oa]
        tr = t[rest]
        j = np.clip(np.searchsorted(ta, tr), 1, len(ta) - 1)
        j = np.where(np.abs(ta[j - 1] - tr) < np.abs(ta[j] - tr), j - 1, j)
        close = np.abs(ta[j] - tr) < 0.2
        if close.sum() >= 10:
            m = euler_to_mat_nb_batch(eul[j[close]])
            f_n = np.einsum("nij,nj->ni", m, acc[rest][close])
            resid = f_n + np.array([0.0, 0.0, G0_MPS2])
            # a 1 s mean removes the white noise; what is left is attitude/bias disagreement
            out["rest_sf_resid_mps2"] = float(np.median(np.linalg.norm(resid[:, :2], axis=1)))
            tilt = np.degrees(np.arctan2(np.linalg.norm(resid[:, :2], axis=1), G0_MPS2))
            out["rest_tilt_disagree_deg"] = float(np.median(tilt))
    return out


def _gnss_stats(
    gnss: list[GnssFix], imu: list[ImuSample], speed: tuple[np.ndarray, np.ndarray]
) -> dict[str, float | None]:
    keys = (
        "gnss_rate_hz", "gnss_nofix_pct", "gnss_garbage_pct", "gnss_2d3d_flaps_per_h",
        "gnss_rest_speed_mps", "gnss_hacc_over_scatter", "gnss_sats_std", "gnss_hdop_std",
    )  # fmt: skip
    out: dict[str, float | None] = dict.fromkeys(keys, None)
    if len(gnss) < 10:
        return out
    t = np.array([g.t_s for g in gnss])
    dt = np.diff(np.sort(t))
    dt = dt[dt > 0]
    out["gnss_rate_hz"] = 1.0 / float(np.median(dt)) if len(dt) else None
    ft = np.array([int(g.fix_type) for g in gnss])
    nofix = ft <= FixType.NO_FIX
    out["gnss_nofix_pct"] = float(100.0 * nofix.mean())
    garbage = np.array(
        [(int(g.fix_type) <= 1) and (g.lat_rad != 0.0 or g.lon_rad != 0.0) for g in gnss]
    )
    out["gnss_garbage_pct"] = float(100.0 * garbage.mean())
    dur_h = max((t.max() - t.min()) / 3600.0, 1e-9)
    is3d = ft >= FixType.FIX_3D
    fix = ft >= FixType.FIX_2D
    flaps = np.sum(fix[1:] & fix[:-1] & (is3d[1:] != is3d[:-1]))
    out["gnss_2d3d_flaps_per_h"] = float(flaps / dur_h)
    good = ft >= FixType.FIX_3D
    sats = np.array([g.satellites if g.satellites is not None else np.nan for g in gnss])[good]
    hdop = np.array([g.hdop if g.hdop is not None else np.nan for g in gnss])[good]
    if np.isfinite(sats).sum() > 5:
        out["gnss_sats_std"] = float(np.nanstd(sats))
    if np.isfinite(hdop).sum() > 5:
        out["gnss_hdop_std"] = float(np.nanstd(hdop))
    # at rest: fixes inside IMU rest windows
    if len(imu) >= 10:
        ti = np.array([s.t_s for s in imu])
        o = np.argsort(ti, kind="stable")
        ti = ti[o]
        acc = np.array([s.acc_b_mps2 for s in imu])[o]
        gyro = np.array([s.gyro_b_radps for s in imu])[o]
        rest = _rest_mask(ti, acc, gyro, speed)
        j = np.clip(np.searchsorted(ti, t), 0, len(ti) - 1)
        at_rest = rest[j] & good & (np.abs(ti[j] - t) < 0.5)
        if at_rest.sum() >= 10:
            gs = np.array([g.ground_speed_mps for g in gnss])[at_rest]
            out["gnss_rest_speed_mps"] = float(np.median(gs))
            lat = np.array([g.lat_rad for g in gnss])[at_rest]
            lon = np.array([g.lon_rad for g in gnss])[at_rest]
            tr = t[at_rest]
            # scatter about the mean of each 10 s block of rest (the vehicle may move between)
            block = np.floor((tr - tr[0]) / SCATTER_BLOCK_S)
            var = []
            for b in np.unique(block):
                m = block == b
                if m.sum() >= 5:
                    n_m = (lat[m] - lat[m].mean()) * 6_371_000.0
                    e_m = (lon[m] - lon[m].mean()) * 6_371_000.0 * math.cos(float(lat[m].mean()))
                    var.append(0.5 * (np.var(n_m) + np.var(e_m)))
            scatter = math.sqrt(float(np.mean(var))) if var else 0.0
            hacc = np.array([g.h_acc_m if g.h_acc_m is not None else np.nan for g in gnss])
            hacc = hacc[at_rest]
            if np.isfinite(hacc).sum() >= 5 and scatter > 0:
                out["gnss_hacc_over_scatter"] = float(np.nanmedian(hacc) / scatter)
    return out


def _stream_stats(
    rx: dict[str, list[float]], duration_s: float, imu: list[ImuSample]
) -> dict[str, float | None]:
    out: dict[str, float | None] = {}
    imu_name = imu[0].source if imu else None
    g_imu, l_imu = _gaps(np.array(rx.get(imu_name, [])), duration_s) if imu_name else (None, None)
    out["imu_gaps_per_h"], out["imu_gap_max_s"] = g_imu, l_imu
    g_g, l_g = _gaps(np.array(rx.get("GPS_RAW_INT", [])), duration_s)
    out["gnss_gaps_per_h"], out["gnss_gap_max_s"] = g_g, l_g
    # every stream at once: gaps of the union of the IMU, attitude and position messages
    names = [k for k in rx if k in _DATA_STREAMS]
    allt = np.sort(np.concatenate([np.asarray(rx[k]) for k in names])) if names else np.array([])
    g_a, l_a = _gaps(allt, duration_s)
    out["all_gaps_per_h"], out["all_gap_max_s"] = g_a, l_a
    return out


def _baro_stats(t: np.ndarray, p_hpa: np.ndarray) -> dict[str, float | None]:
    out: dict[str, float | None] = {"baro_noise_hpa": None, "baro_rate_hz": None}
    if len(t) < 20:
        return out
    p = p_hpa  # in receive order: a reboot restarts the clock, sorting would interleave
    d = np.diff(t)
    d = d[d > 0]
    out["baro_rate_hz"] = 1.0 / float(np.median(d))
    # noise: the second difference (a smooth altitude profile cancels), as a per-sample sigma
    dd = p[2:] - 2.0 * p[1:-1] + p[:-2]
    out["baro_noise_hpa"] = float(1.4826 * np.median(np.abs(dd - np.median(dd))) / math.sqrt(6.0))
    return out


def format_value(v: Any) -> str:
    """A table cell."""
    if v is None:
        return "—"
    if abs(v) >= 100:
        return f"{v:.0f}"
    if abs(v) >= 1:
        return f"{v:.2f}"
    return f"{v:.3f}"
