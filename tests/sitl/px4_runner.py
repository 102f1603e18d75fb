"""PX4 SIH scenarios with the service beside it. Run only inside ``private-net``
(``tests.sitl.harness.run_scenario`` does that); writes its result as JSON.

Scenario ``gnss_cut``: the SIH quadrotor (airframe 10040) with aux global position fusion
set up (``EKF2_AGP0_ID``, ``EKF2_AGP0_CTRL``, ``EKF2_AGP0_DELAY``), the service on the onboard link
(``udpin:127.0.0.1:14540``), takes off, hovers ``--hover-s``, loses GNSS
(MAV_CMD_INJECT_FAILURE, GPS off, ``SYS_FAILURE_EN = 1``) for ``--cut-s``, gets it back and
hovers ``--after-s`` more. ``--fusion 0`` leaves ``EKF2_AGP0_CTRL = 0``: the same flight
with PX4 alone (the service still runs, PX4 ignores it). Truth is SIH's
HIL_STATE_QUATERNION (UDP 19410); PX4's estimate its GLOBAL_POSITION_INT; the service's
solution and accuracy its GLOBAL_POSITION_INT and GLOBAL_POSITION_SENSOR. All times are
the autopilot's boot clock: a loaded machine slows the simulation, not the scores.

``--airframe 10041``: the SIH airplane instead. It takes off from the runway (Takeoff
mode, ``--climb-s`` for the climb to 40 m), then flies Hold, PX4's loiter circle
(``NAV_LOITER_RAD``, 80 m) at about 9 m/s over the ground, ``--hover-s`` of cruise
before the cut, which falls in the circle.

``python -m tests.sitl.px4_runner gnss_cut --fusion 1 --out r.json``
"""

from __future__ import annotations

import argparse
import bisect
import contextlib
import fcntl
import json
import math
import os
import shutil
import statistics
import sys
import threading
import time
import traceback
from pathlib import Path
from typing import Any

from pymavlink import mavutil

from tests.sitl import harness
from tests.sitl.harness import GroundStation, Processes
from tests.sitl.locate import sitl_dir

MAV = mavutil.mavlink
PX4_GCS_URL = "udpin:127.0.0.1:14550"
"""PX4's ground-station link sends here whatever its instance."""
COMPANION_PORT = 14540
TRUTH_PORT = 19410
"""PX4 instance N sends the onboard link to 14540 + N and SIH's truth to 19410 + N."""
MAX_INSTANCES = 10
SERVICE_TAP_PORT = harness.SERVICE_TAP_PORT
AGP_ID = 1
"""The id the PX4 set-up gives the service's aux global position (``EKF2_AGP0_ID``)."""
AGP_DELAY_MS = 150
"""``EKF2_AGP0_DELAY``: EKF2's fusion horizon on SIH (152 ms with ``EKF2_DELAY_MAX`` =
200), so that PX4 compares the aux position with its own of the same time
(docs/mavlink.md, PX4 aux global position)."""
FAILURE_UNIT_SENSOR_GPS = 4
FAILURE_TYPE_OK, FAILURE_TYPE_OFF = 0, 1
TAKEOFF_ALT_M = 10.0
AIRFRAME_QUAD, AIRFRAME_PLANE = 10040, 10041
PLANE_TAKEOFF_ALT_M = 40.0
PX4_MAIN_AUTO, PX4_AUTO_LOITER = 4, 3
"""PX4's custom mode: main mode AUTO, sub-mode LOITER (Hold)."""
PLANE_THRUSTER = {
    "SIH_F_CT0": 0.131,
    "SIH_F_CT1": 0.004,
    "SIH_F_CT2": -0.146,
    "SIH_F_CP0": 0.0777,
    "SIH_F_CP1": 0.0498,
    "SIH_F_CP2": -0.11,
    "SIH_F_DIA_INCH": 8,
    "SIH_F_RPM_MAX": 13000,
    "FW_T_CLMB_MAX": 8,
}
"""The SIH airplane's forward thruster as PX4 later set it (PX4 pull request 28362): the
build here runs 10041 on the 2 N default thrust (``SIH_T_MAX`` no longer read), and with
it full throttle rolls the plane along the runway at 6 m/s, never flying."""
"""PX4's custom mode: main mode AUTO, sub-mode LOITER (Hold)."""
COVER_95_2D = math.sqrt(-2.0 * math.log(0.05))
"""A 1-sigma horizontal accuracy times this (2.45) holds 95 % of a circular 2-D error."""


def px4_tree(workdir: Path) -> Path:
    """A PX4 package folder whose ``bin/px4-*`` command links work: the shared one, or, when
    its links were stored as plain files (an archive that kept no symbolic links), a copy
    of it in ``workdir`` with the links made again."""
    shared = sitl_dir() / "px4"
    probe = shared / "bin" / "px4-param"
    if probe.is_symlink() or os.access(probe, os.X_OK):
        return shared
    tree = workdir / "px4"
    (tree / "bin").mkdir(parents=True, exist_ok=True)
    shutil.copy2(shared / "bin" / "px4", tree / "bin" / "px4")
    for entry in (shared / "bin").iterdir():
        name = entry.name
        if name == "px4":
            continue
        if name.startswith("px4-") and entry.stat().st_size < 64 and not name.endswith(".sh"):
            (tree / "bin" / name).symlink_to("px4")
        else:
            shutil.copy2(entry, tree / "bin" / name)
    (tree / "etc").symlink_to(shared / "etc")
    shutil.copy2(shared / "run-sih.sh", tree / "run-sih.sh")
    return tree


@contextlib.contextmanager
def px4_instance() -> Any:
    """A PX4 instance number no other PX4 on this machine uses, held while in the block.

    A private network namespace keeps the UDP ports apart, not the file system: PX4's
    daemon lock and socket (``/tmp/px4_lock-N``, ``/tmp/px4-sock-N``) are shared by every
    PX4 of instance N, and a second one does not start. The number is locked
    (``/tmp/companion-px4-N.lock``) and skipped while a PX4 holds its own lock on it."""
    for n in range(MAX_INSTANCES):
        lock = open(f"/tmp/companion-px4-{n}.lock", "w")  # noqa: SIM115 - held in the block
        try:
            fcntl.flock(lock, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            lock.close()
            continue
        busy = False
        try:  # PX4's own lock on its instance (held while it runs)
            with open(f"/tmp/px4_lock-{n}", "a") as px4_lock:
                fcntl.flock(px4_lock, fcntl.LOCK_EX | fcntl.LOCK_NB)
                fcntl.flock(px4_lock, fcntl.LOCK_UN)
        except OSError:
            busy = True
        if busy:
            lock.close()
            continue
        try:
            yield n
        finally:
            lock.close()
        return
    raise RuntimeError(f"no free PX4 instance among 0..{MAX_INSTANCES - 1}")


def start_px4(
    procs: Processes, params: dict[str, float], instance: int, airframe: int = 10040
) -> None:
    """PX4 SIH (instance ``instance``) in ``procs``'s folder, with ``params`` set at boot."""
    tree = px4_tree(procs.workdir)
    env = dict(os.environ)
    env["PX4_INSTANCE"] = str(instance)
    for name, value in params.items():
        env[f"PX4_PARAM_{name}"] = f"{value:g}"
    work = procs.workdir / "px4-work"
    procs.start("px4", [str(tree / "run-sih.sh"), str(work), str(airframe)], env=env)


class Listener:
    """One UDP port's messages of some types, each with the autopilot time it is valid at."""

    def __init__(self, url: str, handle: Any) -> None:
        self.conn = mavutil.mavlink_connection(url)
        self._handle = handle
        self._stop = threading.Event()
        self.lock = threading.Lock()
        self._thread = threading.Thread(target=self._read, daemon=True)
        self._thread.start()

    def _read(self) -> None:
        while not self._stop.is_set():
            try:
                msg = self.conn.recv_match(blocking=True, timeout=0.5)
            except (OSError, ValueError):
                continue
            if msg is None or msg.get_type() == "BAD_DATA":
                continue
            with self.lock:
                self._handle(msg)

    def close(self) -> None:
        self._stop.set()
        self._thread.join(timeout=2)
        try:
            self.conn.close()
        except OSError:
            pass


class Series:
    """(t_s, lat_deg, lon_deg) samples, kept in time order, interpolated on demand."""

    def __init__(self) -> None:
        self.t: list[float] = []
        self.lat: list[float] = []
        self.lon: list[float] = []

    def add(self, t_s: float, lat: float, lon: float) -> None:
        if self.t and t_s <= self.t[-1]:
            if t_s + 2.0 < self.t[-1]:  # a reboot: not in these scenarios
                return
            return
        self.t.append(t_s)
        self.lat.append(lat)
        self.lon.append(lon)

    def at(self, t_s: float) -> tuple[float, float] | None:
        i = bisect.bisect_left(self.t, t_s)
        if i == 0 or i >= len(self.t):
            return None
        t0, t1 = self.t[i - 1], self.t[i]
        if t1 - t0 > 0.5:
            return None
        w = (t_s - t0) / (t1 - t0)
        return (
            self.lat[i - 1] + w * (self.lat[i] - self.lat[i - 1]),
            self.lon[i - 1] + w * (self.lon[i] - self.lon[i - 1]),
        )


def errors(track: Series, truth: Series, t0: float, t1: float) -> list[tuple[float, float]]:
    """(t_s, horizontal error m) of ``track`` against ``truth`` for t0 <= t < t1."""
    out = []
    for t, lat, lon in zip(track.t, track.lat, track.lon, strict=True):
        if t0 <= t < t1:
            ref = truth.at(t)
            if ref is not None:
                out.append((t, harness.horizontal_m(ref[0], ref[1], lat, lon)))
    return out


PX4_FLAGS = ("cs_aux_gpos", "cs_fake_pos", "cs_inertial_dead_reckoning")
"""EKF2's control status flags followed (``estimator_status_flags``): the aux global
position, the fake position at the last known one, dead reckoning."""


def _px4_log(workdir: Path, topic: str) -> Any:
    """PX4's newest flight log with ``topic`` read (a pyulog ULog), or None when there is
    none or it cannot be read."""
    try:
        from pyulog import ULog
    except ImportError:
        return None
    logs = sorted((workdir / "px4-work" / "log").glob("*/*.ulg"))
    if not logs:
        return None
    try:
        return ULog(str(logs[-1]), [topic])
    except (OSError, ValueError, IndexError, KeyError, EOFError):
        return None


def px4_flags(workdir: Path) -> dict[str, list[tuple[float, bool]]]:
    """Each of :data:`PX4_FLAGS` as it changed, ``{flag: [(t_s, on), ...]}``, from the
    flight log PX4 wrote (empty when none could be read)."""
    ulog = _px4_log(workdir, "estimator_status_flags")
    if ulog is None:
        return {}
    out: dict[str, list[tuple[float, bool]]] = {}
    for data in ulog.data_list:
        if data.multi_id != 0:
            continue
        t_s = data.data["timestamp"] * 1e-6
        for flag in PX4_FLAGS:
            if flag in data.data:
                on = data.data[flag]
                out[flag] = [
                    (float(t_s[i]), bool(on[i]))
                    for i in range(len(on))
                    if i == 0 or on[i] != on[i - 1]
                ]
    return out


def px4_biases(workdir: Path, times: list[float]) -> dict[str, list[list[float]]]:
    """EKF2's accelerometer (m/s^2) and gyro (rad/s) bias estimates at ``times``
    (``estimator_sensor_bias``, from PX4's flight log): HIGHRES_IMU and ATTITUDE's body rates
    are PX4's sensors less these, so what PX4 learns from a fused input moves them."""
    ulog = _px4_log(workdir, "estimator_sensor_bias")
    if ulog is None:
        return {}
    out: dict[str, list[list[float]]] = {}
    for data in ulog.data_list:
        if data.multi_id != 0:
            continue
        t_s = [float(t) * 1e-6 for t in data.data["timestamp"]]
        for name in ("accel_bias", "gyro_bias"):
            cols = [data.data.get(f"{name}[{k}]") for k in range(3)]
            if any(c is None for c in cols):
                continue
            rows = []
            for t in times:
                i = max(bisect.bisect_right(t_s, t) - 1, 0)
                rows.append([round(float(c[i]), 6) for c in cols])  # type: ignore[index]
            out[name] = rows
    return out


def write_truth_csv(path: Path, rows: list[tuple[float, ...]]) -> None:
    """SIH's truth in the columns ``companion evaluate --truth`` reads (autopilot time, s),
    for replaying the service's recording of the flight against it."""
    head = "t_s,lat_deg,lon_deg,alt_m,vn_mps,ve_mps,vd_mps,roll_deg,pitch_deg,yaw_deg"
    lines = [head]
    lines += [
        f"{r[0]:.6f},{r[1]:.10f},{r[2]:.10f},{r[3]:.4f}," + ",".join(f"{v:.5f}" for v in r[4:])
        for r in rows
    ]
    path.write_text("\n".join(lines) + "\n")


def summary(errs: list[tuple[float, float]]) -> dict[str, float | int]:
    vals = sorted(e for _, e in errs)
    if not vals:
        return {"n": 0, "mean_m": math.nan, "p95_m": math.nan, "max_m": math.nan}
    p95 = vals[min(len(vals) - 1, math.ceil(0.95 * len(vals)) - 1)]
    return {"n": len(vals), "mean_m": statistics.fmean(vals), "p95_m": p95, "max_m": vals[-1]}


def series(
    errs: dict[str, list[tuple[float, float]]], t0: float, t1: float, step_s: float = 0.5
) -> list[list[float]]:
    """``[t - t0, value of each of errs (the latest at or before), ...]`` every ``step_s``."""
    rows = []
    t = t0
    while t < t1:
        row = [round(t - t0, 2)]
        for samples in errs.values():
            times = [s[0] for s in samples]
            i = bisect.bisect_right(times, t) - 1
            row.append(round(samples[i][1], 3) if i >= 0 and t - times[i] <= 1.5 else math.nan)
        rows.append(row)
        t += step_s
    return rows


def gnss_cut(args: argparse.Namespace, procs: Processes, instance: int) -> dict[str, Any]:
    truth, px4_est, svc = Series(), Series(), Series()
    svc_eph: dict[float, float] = {}
    sensor = Series()
    """The GLOBAL_POSITION_SENSORs sent to PX4 (their eph by time in ``svc_eph``)."""
    svc_hacc = Series()
    """The service's CMP_HACC (1-sigma horizontal accuracy, m) in its ``lat`` column."""
    svc_ids: set[int] = set()
    alerts: list[tuple[float, str]] = []
    truth_alt_m: list[float] = []
    truth_speed_mps: list[tuple[float, float]] = []
    px4_modes: list[tuple[float, int]] = []
    partial: dict[int, str] = {}
    plane = args.airframe == AIRFRAME_PLANE

    truth_rows: list[tuple[float, ...]] = []

    def on_truth(msg: Any) -> None:
        if msg.get_type() == "HIL_STATE_QUATERNION":
            truth.add(msg.time_usec * 1e-6, msg.lat * 1e-7, msg.lon * 1e-7)
            w, x, y, z = msg.attitude_quaternion
            truth_rows.append(
                (
                    msg.time_usec * 1e-6,
                    msg.lat * 1e-7,
                    msg.lon * 1e-7,
                    msg.alt * 1e-3,
                    msg.vx * 0.01,
                    msg.vy * 0.01,
                    msg.vz * 0.01,
                    math.degrees(math.atan2(2 * (w * x + y * z), 1 - 2 * (x * x + y * y))),
                    math.degrees(math.asin(max(-1.0, min(1.0, 2 * (w * y - z * x))))),
                    math.degrees(math.atan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))),
                )
            )
            truth_alt_m.append(msg.alt * 1e-3)
            truth_speed_mps.append((msg.time_usec * 1e-6, 0.01 * math.hypot(msg.vx, msg.vy)))

    def on_service(msg: Any) -> None:
        kind = msg.get_type()
        if kind == "GLOBAL_POSITION_INT":
            svc.add(msg.time_boot_ms * 1e-3, msg.lat * 1e-7, msg.lon * 1e-7)
        elif kind == "NAMED_VALUE_FLOAT" and msg.name == "CMP_HACC":
            svc_hacc.add(msg.time_boot_ms * 1e-3, float(msg.value), 0.0)
        elif kind == "GLOBAL_POSITION_SENSOR":
            svc_eph[round(msg.time_usec * 1e-6, 3)] = float(msg.eph)
            sensor.add(msg.time_usec * 1e-6, msg.lat * 1e-7, msg.lon * 1e-7)
            svc_ids.add(int(msg.id))
        elif kind == "STATUSTEXT":
            text, sid = msg.text, int(getattr(msg, "id", 0) or 0)
            if sid:  # MAVLink 2 chunks: joined
                partial[sid] = partial.get(sid, "") + text
                if len(text) == 50:
                    return
                text = partial.pop(sid)
            alerts.append((svc.t[-1] if svc.t else -1.0, text))

    params = {
        "EKF2_AGP0_ID": AGP_ID,
        "EKF2_AGP0_CTRL": 1 if args.fusion else 0,
        "EKF2_AGP0_DELAY": AGP_DELAY_MS,
        "SYS_FAILURE_EN": 1,
        "COM_RC_IN_MODE": 4,
        "NAV_DLL_ACT": 0,
        "MIS_TAKEOFF_ALT": PLANE_TAKEOFF_ALT_M if plane else TAKEOFF_ALT_M,
    }
    if plane:
        params.update(PLANE_THRUSTER)
    params.update(dict(args.px4_param))
    truth_tap = Listener(f"udpin:127.0.0.1:{TRUTH_PORT + instance}", on_truth)
    service_tap = Listener(f"udpin:127.0.0.1:{SERVICE_TAP_PORT}", on_service)
    start_px4(procs, params, instance, args.airframe)
    master = f"udpin:127.0.0.1:{COMPANION_PORT + instance}"
    sections: dict[str, dict[str, Any]] = {
        "link": {"master": master, "gcs": f"udpout:127.0.0.1:{SERVICE_TAP_PORT}"}
    }
    if args.engine:
        sections["engine"] = dict(args.engine)
    if args.encoder:
        sections["encoder"] = dict(args.encoder)
    harness.start_companion(procs, sections)
    gcs = GroundStation(PX4_GCS_URL)
    gcs.target_system = instance + 1  # PX4's MAV_SYS_ID is its instance + 1

    def on_gcs(msg: Any) -> None:
        if msg.get_type() == "GLOBAL_POSITION_INT":
            with gcs.lock:
                px4_est.add(msg.time_boot_ms * 1e-3, msg.lat * 1e-7, msg.lon * 1e-7)
        elif msg.get_type() == "HEARTBEAT":
            mode = int(msg.custom_mode)
            if not px4_modes or px4_modes[-1][1] != mode:
                px4_modes.append((gcs.ap_time_s, mode))

    gcs.on_message.append(on_gcs)
    try:
        gcs.wait_booted()
        gcs.set_message_rate("GLOBAL_POSITION_INT", 10.0)
        # EKF2 aligned, GNSS in use, the service publishing: then arm and take off
        gcs.wait_until(lambda: len(svc.t) > 20, 90.0, "the service publishing")
        gcs.arm()
        t_takeoff = gcs.now()
        gcs.command(MAV.MAV_CMD_NAV_TAKEOFF, -1, 0, 0, math.nan, math.nan, math.nan, math.nan)
        gcs.sleep(args.climb_s)
        if plane:  # then Hold: a loiter circle (NAV_LOITER_RAD) at the take-off altitude
            gcs.command(MAV.MAV_CMD_DO_SET_MODE, 1, PX4_MAIN_AUTO, PX4_AUTO_LOITER)
        gcs.sleep(args.hover_s)
        t_cut = gcs.now()
        gcs.command(MAV.MAV_CMD_INJECT_FAILURE, FAILURE_UNIT_SENSOR_GPS, FAILURE_TYPE_OFF)
        gcs.sleep(args.cut_s)
        t_back = gcs.now()
        gcs.command(MAV.MAV_CMD_INJECT_FAILURE, FAILURE_UNIT_SENSOR_GPS, FAILURE_TYPE_OK)
        gcs.sleep(args.after_s)
        t_end = gcs.now()
    finally:
        statustexts = list(gcs.statustexts)
        gcs.close()
        truth_tap.close()
        service_tap.close()
    procs.stop("px4")  # its flight log complete
    write_truth_csv(procs.workdir / "truth.csv", truth_rows)
    flags = px4_flags(procs.workdir)
    biases = px4_biases(procs.workdir, [t_cut, t_back])
    aux = flags.get("cs_aux_gpos", [])
    pre0 = max(t_cut - args.pre_window_s, 0.0)
    px4_pre = errors(px4_est, truth, pre0, t_cut)
    px4_cut = errors(px4_est, truth, t_cut, t_back)
    px4_after = errors(px4_est, truth, t_back, t_end)
    svc_all = errors(svc, truth, pre0, t_end)
    # the published accuracy: CMP_HACC (1 Hz, also through the cut, when PX4 gets no
    # GLOBAL_POSITION_SENSOR), the latest one at or before each position (it only grows
    # through a gap, so the earlier value is the stricter test)
    covered = []
    for t, e in svc_all:
        i = bisect.bisect_right(svc_hacc.t, t) - 1
        if i >= 0 and t - svc_hacc.t[i] <= 1.5:
            acc = svc_hacc.lat[i]
            covered.append((t, e, acc, e <= COVER_95_2D * acc))
    # what PX4 was given: each GLOBAL_POSITION_SENSOR's error against its eph (1-sigma)
    sent = [
        (t, e, svc_eph.get(round(t, 3), math.nan)) for t, e in errors(sensor, truth, pre0, t_end)
    ]
    sent_cut = [(t, e, eph) for t, e, eph in sent if t_cut <= t < t_back]
    pre_max = max((e for _, e in px4_pre), default=math.nan)
    # when PX4's error is back under its pre-cut maximum for good, s after GNSS returned
    back_under_s = math.nan
    for i, (t, _) in enumerate(px4_after):
        if all(e <= pre_max for _, e in px4_after[i:]):
            back_under_s = t - t_back
            break
    return {
        "fusion": bool(args.fusion),
        "t_cut_s": t_cut,
        "t_back_s": t_back,
        "t_end_s": t_end,
        "px4_pre": summary(px4_pre),
        "px4_cut": summary(px4_cut),
        "px4_after": summary(px4_after),
        "px4_back_under_pre_max_s": back_under_s,
        "px4_after_2s": summary(errors(px4_est, truth, t_back, t_back + 2.0)),
        "service_pre": summary(errors(svc, truth, pre0, t_cut)),
        "service_cut": summary(errors(svc, truth, t_cut, t_back)),
        "service_cover_95": (
            sum(1 for c in covered if c[3]) / len(covered) if covered else math.nan
        ),
        "service_cover_n": len(covered),
        "service_cover_95_cut": (
            sum(1 for c in covered if c[3] and t_cut <= c[0] < t_back)
            / max(1, sum(1 for c in covered if t_cut <= c[0] < t_back))
        ),
        "service_cover_n_cut": sum(1 for c in covered if t_cut <= c[0] < t_back),
        "t_takeoff_s": t_takeoff,
        "service_worst_ratio": max((c[1] / c[2] for c in covered if c[2] > 0), default=math.nan),
        "service_ids": sorted(svc_ids),
        "service_sensor_in_cut": sum(1 for t in svc_eph if t_cut + 1.5 <= t < t_back),
        "service_sensor_before_cut": sum(1 for t in svc_eph if pre0 <= t < t_cut),
        "px4_aux_fused": aux,
        "px4_flags": flags,
        "px4_biases_at_cut_and_back": biases,
        "sensor_cover_95": (
            sum(1 for _, e, eph in sent if e <= COVER_95_2D * eph) / len(sent) if sent else math.nan
        ),
        "sensor_n": len(sent),
        "sensor_last_in_cut_s": (sent_cut[-1][0] - t_cut) if sent_cut else math.nan,
        "sensor_cut": summary([(t, e) for t, e, _ in sent_cut]),
        "sensor_eph_max_in_cut_m": max((eph for _, _, eph in sent_cut), default=math.nan),
        "series_cols": ["t_from_cut_s", "px4_err_m", "service_err_m", "service_hacc_m"],
        "series": series(
            {
                "px4": errors(px4_est, truth, pre0, t_end),
                "svc": svc_all,
                "hacc": list(zip(svc_hacc.t, svc_hacc.lat, strict=True)),
            },
            t_cut - 2.0,
            t_end,
        ),
        "service_alerts": alerts,
        "px4_statustexts": statustexts[-40:],
        "truth_n": len(truth.t),
        "truth_climb_m": (max(truth_alt_m) - truth_alt_m[0]) if truth_alt_m else math.nan,
        "truth_speed_mps": [[round(t, 2), round(v, 2)] for t, v in truth_speed_mps[::25]],
        "px4_modes": px4_modes,
    }


def _key_value(text: str) -> tuple[str, float | str]:
    key, _, value = text.partition("=")
    try:
        return key, float(value)
    except ValueError:
        return key, value


def _key_number(text: str) -> tuple[str, float]:
    key, sep, value = text.partition("=")
    if not sep or not key:
        raise argparse.ArgumentTypeError(f"NAME=VALUE expected, got {text!r}")
    try:
        return key, float(value)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{key}: {value!r} is not a number") from None


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("scenario", choices=("gnss_cut",))
    ap.add_argument("--fusion", type=int, default=1, help="EKF2_AGP0_CTRL (1 on, 0 off)")
    ap.add_argument(
        "--airframe",
        type=int,
        default=AIRFRAME_QUAD,
        choices=(AIRFRAME_QUAD, AIRFRAME_PLANE),
        help="SIH quadrotor (hover) or airplane (take-off, then Hold: a loiter circle)",
    )
    ap.add_argument("--climb-s", type=float, default=10.0)
    ap.add_argument("--hover-s", type=float, default=15.0)
    ap.add_argument("--pre-window-s", type=float, default=10.0)
    ap.add_argument("--cut-s", type=float, default=20.0)
    ap.add_argument("--after-s", type=float, default=10.0)
    ap.add_argument(
        "--engine",
        action="append",
        type=_key_value,
        default=[],
        metavar="KEY=VALUE",
        help="an [engine] setting of the service (a number or a word), repeatable",
    )
    ap.add_argument(
        "--encoder",
        action="append",
        type=_key_value,
        default=[],
        metavar="KEY=VALUE",
        help="an [encoder] setting of the service (a number or a word), repeatable",
    )
    ap.add_argument(
        "--px4-param",
        action="append",
        type=_key_number,
        default=[],
        metavar="NAME=VALUE",
        help="a PX4 parameter set at boot (e.g. EKF2_AGP0_DELAY=100), repeatable",
    )
    ap.add_argument("--keep", type=Path, default=None, help="run in this folder, keep it")
    ap.add_argument("--out", type=Path, required=True)
    args = ap.parse_args(argv)
    wall0 = time.monotonic()
    with px4_instance() as instance, harness.workdir(args.keep) as wd, Processes(wd) as procs:
        try:
            result = gnss_cut(args, procs, instance)
        except Exception:
            traceback.print_exc()
            for name in ("px4", "companion"):
                print(f"--- {name} log tail ---\n{procs.tail(name)}", file=sys.stderr)
            return 1
        result["companion_log_tail"] = procs.tail("companion", 4000)
    result["wall_s"] = time.monotonic() - wall0
    args.out.write_text(json.dumps(result, indent=1, default=str))
    return 0


if __name__ == "__main__":
    sys.exit(main())
