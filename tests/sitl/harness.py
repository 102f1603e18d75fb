"""Running a simulator, the service and a ground station together, inside a private network
namespace, in a temporary folder.

The pytest tests never start a simulator themselves: :func:`run_scenario` runs a scenario
module (``python -m tests.sitl.<runner> ... --out result.json``) under ``private-net``,
where the runner starts everything with :class:`Processes` (each in its own process group,
all killed on the way out, also on failure), drives the autopilot with
:class:`GroundStation`, listens to the service with :class:`ServiceTap` and writes its
result as JSON, which the test asserts on. ``bench/sitl.py`` runs the same runners with
longer flights.

Times are the autopilot's (``time_boot_ms``), never the wall clock: a loaded machine
slows the simulation, not the scores.
"""

from __future__ import annotations

import collections
import contextlib
import json
import math
import os
import queue
import signal
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from tests.sitl.locate import PROJECT_ROOT, sitl_dir

os.environ.setdefault("MAVLINK20", "1")

from pymavlink import mavutil  # noqa: E402

GCS_PORT = 5760
"""SITL serial0: the ground station."""
COMPANION_PORT = 5762
"""SITL serial1: the service's ``--master``."""
SERVICE_TAP_PORT = 14660
"""The service's ground-station link sends here (udpout); :class:`ServiceTap` listens."""
CANBERRA_HOME = "-35.363261,149.165230,584,353"
"""SITL's usual home: the CMAC runway, heading 353 deg."""
EARTH_RADIUS_M = 6378137.0


def run_scenario(module: str, args: list[str], out_json: Path, timeout_s: float) -> dict[str, Any]:
    """Run ``python -m <module> <args> --out <out_json>`` under ``private-net`` and return
    the JSON it wrote. Raises RuntimeError (with the runner's output tail) when it fails."""
    private_net = sitl_dir() / "private-net"
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(PROJECT_ROOT), env.get("PYTHONPATH")]))
    argv = [str(private_net), sys.executable, "-m", module, *args, "--out", str(out_json)]
    proc = subprocess.Popen(
        argv,
        cwd=PROJECT_ROOT,
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
        start_new_session=True,
    )
    try:
        output, _ = proc.communicate(timeout=timeout_s)
    except subprocess.TimeoutExpired:
        with contextlib.suppress(ProcessLookupError):
            os.killpg(proc.pid, signal.SIGTERM)
        output, _ = proc.communicate(timeout=30)
        raise RuntimeError(
            f"{module} timed out after {timeout_s:.0f} s:\n{output[-4000:]}"
        ) from None
    if proc.returncode != 0 or not out_json.exists():
        raise RuntimeError(f"{module} failed (exit {proc.returncode}):\n{output[-4000:]}")
    result: dict[str, Any] = json.loads(out_json.read_text())
    result.setdefault("_output_tail", output[-2000:])
    return result


class Processes:
    """Child processes, each in its own session (process group), all stopped on exit."""

    def __init__(self, workdir: Path) -> None:
        self.workdir = workdir
        self.procs: dict[str, subprocess.Popen[bytes]] = {}

    def start(self, name: str, argv: list[str], env: dict[str, str] | None = None) -> None:
        log = open(self.workdir / f"{name}.log", "ab")  # noqa: SIM115 - closed with the process
        self.procs[name] = subprocess.Popen(
            argv,
            cwd=self.workdir,
            env=env,
            stdout=log,
            stderr=subprocess.STDOUT,
            start_new_session=True,
        )
        log.close()

    def alive(self, name: str) -> bool:
        p = self.procs.get(name)
        return p is not None and p.poll() is None

    def stop(self, name: str, sig: int = signal.SIGTERM, wait_s: float = 10.0) -> None:
        p = self.procs.pop(name, None)
        if p is None:
            return
        with contextlib.suppress(ProcessLookupError):
            os.killpg(p.pid, sig)
        try:
            p.wait(timeout=wait_s)
        except subprocess.TimeoutExpired:
            with contextlib.suppress(ProcessLookupError):
                os.killpg(p.pid, signal.SIGKILL)
            p.wait(timeout=10)

    def stop_all(self) -> None:
        for name in list(self.procs):
            self.stop(name)

    def tail(self, name: str, chars: int = 3000) -> str:
        path = self.workdir / f"{name}.log"
        return path.read_text(errors="replace")[-chars:] if path.exists() else ""

    def __enter__(self) -> Processes:
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop_all()


@contextlib.contextmanager
def workdir(keep: Path | None = None) -> Iterator[Path]:
    """A fresh working folder (``keep``: this one, left in place, for a post-mortem)."""
    if keep is not None:
        keep.mkdir(parents=True, exist_ok=True)
        yield keep
        return
    with tempfile.TemporaryDirectory(prefix="companion-sitl-") as d:
        yield Path(d)


def start_ardupilot(
    procs: Processes,
    vehicle: str,
    speedup: float,
    wipe: bool = True,
    home: str = CANBERRA_HOME,
    name: str = "sitl",
) -> None:
    """ArduPlane (``vehicle='plane'``) or ArduCopter (``'copter'``) SITL in ``procs``'s folder."""
    folder = sitl_dir()
    binary, model, parm = {
        "plane": ("arduplane", "plane", "plane.parm"),
        "copter": ("arducopter", "quad", "copter.parm"),
    }[vehicle]
    argv = [
        str(folder / binary),
        "--model",
        model,
        "--speedup",
        f"{speedup:g}",
        "--defaults",
        str(folder / "params" / parm),
        "--home",
        home,
        "-I0",
    ]
    if wipe:
        argv.append("-w")
    procs.start(name, argv)


def write_companion_config(path: Path, sections: dict[str, dict[str, Any]]) -> Path:
    """A TOML configuration from ``{section: {key: value}}`` (scalars, lists, strings)."""

    def fmt(v: Any) -> str:
        if isinstance(v, bool):
            return "true" if v else "false"
        if isinstance(v, str):
            return json.dumps(v)
        if isinstance(v, (list, tuple)):
            return "[" + ", ".join(fmt(x) for x in v) + "]"
        return repr(v)

    lines = []
    for section, values in sections.items():
        lines.append(f"[{section}]")
        lines += [f"{k} = {fmt(v)}" for k, v in values.items()]
        lines.append("")
    path.write_text("\n".join(lines))
    return path


def start_companion(
    procs: Processes, sections: dict[str, dict[str, Any]], name: str = "companion"
) -> None:
    """``companion run`` against SITL serial1, its ground-station link to the tap."""
    base: dict[str, dict[str, Any]] = {
        "link": {
            "master": f"tcp:127.0.0.1:{COMPANION_PORT}",
            "gcs": f"udpout:127.0.0.1:{SERVICE_TAP_PORT}",
            "state_file": str(procs.workdir / "companion-state" / "state.json"),
            "record_dir": str(procs.workdir / "companion-logs"),
        }
    }
    for section, values in sections.items():
        base.setdefault(section, {}).update(values)
    cfg = write_companion_config(procs.workdir / "companion.toml", base)
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(PROJECT_ROOT), env.get("PYTHONPATH")]))
    procs.start(name, [sys.executable, "-m", "companion", "run", "--config", str(cfg)], env=env)


PROTOCOL_TYPES = frozenset(
    {
        "PARAM_VALUE",
        "COMMAND_ACK",
        "MISSION_REQUEST",
        "MISSION_REQUEST_INT",
        "MISSION_ACK",
    }
)


MISSION_REPLIES = ("MISSION_REQUEST", "MISSION_REQUEST_INT", "MISSION_ACK")
MissionItem = tuple[int, int, tuple[float, ...], float, float, float]
"""(frame, command, (p1..p4), lat_deg, lon_deg, alt_m)"""


class GroundStation:
    """A ground station on SITL serial0: parameters, modes, arming, a mission, and the
    autopilot's clock (the newest ``time_boot_ms`` heard, s)."""

    def __init__(self, url: str = f"tcp:127.0.0.1:{GCS_PORT}", connect_wall_s: float = 60.0):
        deadline = time.monotonic() + connect_wall_s
        while True:
            try:
                self.conn = mavutil.mavlink_connection(
                    url, source_system=255, source_component=190, autoreconnect=True
                )
                break
            except OSError:
                if time.monotonic() > deadline:
                    raise
                time.sleep(0.5)
        self.lock = threading.Lock()
        self.ap_time_s = -1.0
        self.boot_count = 0
        """Times the autopilot's clock went back (a reboot or a restart)."""
        self.heartbeat: Any = None
        self.heartbeats_after_boot = 0
        self.statustexts: list[tuple[float, str]] = []
        self.latest: dict[str, Any] = {}
        self.protocol: queue.Queue[Any] = queue.Queue()
        self.on_message: list[Callable[[Any], None]] = []
        self.target_system = 1
        self.target_component = 1
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._read, daemon=True)
        self._thread.start()

    def _read(self) -> None:
        while not self._stop.is_set():
            try:
                msg = self.conn.recv_match(blocking=True, timeout=0.5)
            except (OSError, ValueError):
                time.sleep(0.2)
                continue
            if msg is None or msg.get_srcSystem() != self.target_system:
                continue
            if msg.get_srcComponent() != self.target_component:
                continue
            mtype = msg.get_type()
            if mtype == "BAD_DATA":
                continue
            with self.lock:
                t_ms = getattr(msg, "time_boot_ms", None)
                if t_ms:
                    t_s = float(t_ms) / 1000.0
                    if t_s + 2.0 < self.ap_time_s:  # the clock went back: a reboot
                        self.boot_count += 1
                        self.heartbeats_after_boot = 0
                        self.ap_time_s = t_s
                    else:
                        self.ap_time_s = max(self.ap_time_s, t_s)
                self.latest[mtype] = msg
                if mtype == "HEARTBEAT":
                    self.heartbeat = msg
                    self.heartbeats_after_boot += 1
                elif mtype == "STATUSTEXT":
                    self.statustexts.append((self.ap_time_s, msg.text))
            if mtype in PROTOCOL_TYPES:
                self.protocol.put(msg)
            for cb in self.on_message:
                cb(msg)

    def close(self) -> None:
        self._stop.set()
        self._thread.join(timeout=2)
        with contextlib.suppress(Exception):
            self.conn.close()

    # -- waiting on the autopilot's clock -------------------------------------------------

    def now(self) -> float:
        with self.lock:
            return self.ap_time_s

    def wait_until(
        self,
        cond: Callable[[], bool],
        ap_timeout_s: float,
        what: str,
        wall_factor: float = 20.0,
        poll_s: float = 0.05,
    ) -> None:
        """Wait for ``cond()``; fail after ``ap_timeout_s`` of autopilot time (or, should
        the autopilot's clock stall, ``wall_factor`` times as much wall time)."""
        t0 = self.now()
        wall_deadline = time.monotonic() + max(30.0, wall_factor * ap_timeout_s)
        while not cond():
            if self.now() - t0 > ap_timeout_s or time.monotonic() > wall_deadline:
                raise TimeoutError(f"{what}: not within {ap_timeout_s:g} s (autopilot time)")
            time.sleep(poll_s)

    def sleep(self, ap_s: float) -> None:
        """Let ``ap_s`` of autopilot time pass."""
        t_end = self.now() + ap_s
        self.wait_until(lambda: self.now() >= t_end, ap_s + 5.0, f"{ap_s:g} s to pass")

    def wait_booted(self, ap_timeout_s: float = 60.0) -> None:
        deadline = time.monotonic() + 120.0
        while self.heartbeat is None:
            if time.monotonic() > deadline:
                raise TimeoutError("no autopilot HEARTBEAT")
            time.sleep(0.1)
        # ArduCopter sends nothing timed on a port until asked
        self.set_message_rate("SYSTEM_TIME", 10.0)
        self.set_message_rate("ATTITUDE", 10.0)
        while self.ap_time_s < 0.0:
            if time.monotonic() > deadline:
                raise TimeoutError("no autopilot clock (SYSTEM_TIME, ATTITUDE)")
            time.sleep(0.1)

    # -- commands and parameters ----------------------------------------------------------

    def _drain_protocol(self) -> None:
        with contextlib.suppress(queue.Empty):
            while True:
                self.protocol.get_nowait()

    def _expect(self, pred: Callable[[Any], bool], wall_timeout_s: float) -> Any | None:
        deadline = time.monotonic() + wall_timeout_s
        while (left := deadline - time.monotonic()) > 0:
            try:
                msg = self.protocol.get(timeout=left)
            except queue.Empty:
                return None
            if pred(msg):
                return msg
        return None

    def command(
        self, cmd: int, *params: float, retries: int = 5, wall_timeout_s: float = 3.0
    ) -> int | None:
        """COMMAND_LONG to the autopilot; its COMMAND_ACK result (None: no answer)."""
        p = list(params) + [0.0] * (7 - len(params))
        for attempt in range(retries):
            self._drain_protocol()
            with self.lock:
                self.conn.mav.command_long_send(
                    self.target_system, self.target_component, cmd, attempt, *p
                )
            ack = self._expect(
                lambda m: m.get_type() == "COMMAND_ACK" and m.command == cmd, wall_timeout_s
            )
            if ack is not None:
                return int(ack.result)
        return None

    def set_message_rate(self, name: str, rate_hz: float) -> None:
        msg_id = getattr(mavutil.mavlink, f"MAVLINK_MSG_ID_{name}")
        self.command(mavutil.mavlink.MAV_CMD_SET_MESSAGE_INTERVAL, msg_id, 1e6 / rate_hz, retries=2)

    def set_param(self, name: str, value: float, retries: int = 8) -> None:
        for _ in range(retries):
            self._drain_protocol()
            with self.lock:
                self.conn.mav.param_set_send(
                    self.target_system,
                    self.target_component,
                    name.encode(),
                    float(value),
                    mavutil.mavlink.MAV_PARAM_TYPE_REAL32,
                )
            echo = self._expect(lambda m: m.get_type() == "PARAM_VALUE" and m.param_id == name, 3.0)
            if echo is not None and math.isclose(echo.param_value, value, abs_tol=1e-6):
                return
        raise TimeoutError(f"parameter {name} = {value} not confirmed")

    def get_param(self, name: str, retries: int = 8) -> float:
        for _ in range(retries):
            self._drain_protocol()
            with self.lock:
                self.conn.mav.param_request_read_send(
                    self.target_system, self.target_component, name.encode(), -1
                )
            echo = self._expect(lambda m: m.get_type() == "PARAM_VALUE" and m.param_id == name, 3.0)
            if echo is not None:
                return float(echo.param_value)
        raise TimeoutError(f"parameter {name} not read")

    def set_mode(self, custom_mode: int) -> None:
        """Asked again until the heartbeat shows it: an accepted change can be undone just
        after boot (a copter's GUIDED, ACKed, was not shown 10 s later once in a loaded run)."""

        def shown() -> bool:
            if self.mode() == custom_mode:
                return True
            self.command(mavutil.mavlink.MAV_CMD_DO_SET_MODE, 1, custom_mode)
            return False

        self.wait_until(shown, 60.0, f"mode {custom_mode} shown", poll_s=2.0)

    def mode(self) -> int | None:
        hb = self.heartbeat
        return None if hb is None else int(hb.custom_mode)

    def armed(self) -> bool:
        hb = self.heartbeat
        return hb is not None and bool(hb.base_mode & mavutil.mavlink.MAV_MODE_FLAG_SAFETY_ARMED)

    def arm(self, ap_timeout_s: float = 120.0) -> None:
        """Arm once the pre-arm checks pass (retried every 2 s of autopilot time)."""
        last = [-1e9]

        def try_arm() -> bool:
            if self.armed():
                return True
            if self.now() - last[0] >= 2.0:
                last[0] = self.now()
                self.command(mavutil.mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 1, retries=1)
            return self.armed()

        self.wait_until(try_arm, ap_timeout_s, "arming", poll_s=0.2)

    def reboot(self) -> None:
        self.command(mavutil.mavlink.MAV_CMD_PREFLIGHT_REBOOT_SHUTDOWN, 1, retries=2)

    def upload_mission(self, items: list[MissionItem]) -> None:
        """Items ``(frame, command, (p1..p4), lat_deg, lon_deg, alt_m)``; item 0 is home."""
        mav = mavutil.mavlink
        for _ in range(3):
            self._drain_protocol()
            with self.lock:
                self.conn.mav.mission_count_send(
                    self.target_system,
                    self.target_component,
                    len(items),
                    mav.MAV_MISSION_TYPE_MISSION,
                )
            while True:
                msg = self._expect(
                    lambda m: (
                        m.get_type() in ("MISSION_REQUEST", "MISSION_REQUEST_INT", "MISSION_ACK")
                    ),
                    5.0,
                )
                if msg is None:
                    break
                if msg.get_type() == "MISSION_ACK":
                    if msg.type == mav.MAV_MISSION_ACCEPTED:
                        return
                    break
                seq = int(msg.seq)
                frame, cmd, p, lat, lon, alt = items[seq]
                with self.lock:
                    self.conn.mav.mission_item_int_send(
                        self.target_system,
                        self.target_component,
                        seq,
                        frame,
                        cmd,
                        0,
                        1,
                        *(list(p) + [0.0] * (4 - len(p))),
                        int(round(lat * 1e7)),
                        int(round(lon * 1e7)),
                        float(alt),
                        mav.MAV_MISSION_TYPE_MISSION,
                    )
        raise TimeoutError("mission upload not accepted")


@dataclass
class ServiceTap:
    """What the service sends on its ground-station link: its positions (autopilot time,
    s), alerts (at the service's newest publication time) and counts."""

    port: int = SERVICE_TAP_PORT
    positions: list[tuple[float, float, float, float]] = field(default_factory=list)
    """(t_s, lat_deg, lon_deg, alt_msl_m) of each GLOBAL_POSITION_INT."""
    accuracies: list[tuple[float, float]] = field(default_factory=list)
    """(t_s, horiz_accuracy_m) of each GPS_INPUT."""
    alerts: list[tuple[float, str]] = field(default_factory=list)
    counts: collections.Counter[str] = field(default_factory=collections.Counter)
    t_last_s: float = -1.0
    wall_of_first_pub: list[float] = field(default_factory=list)

    def __post_init__(self) -> None:
        self.conn = mavutil.mavlink_connection(f"udpin:127.0.0.1:{self.port}")
        self._stop = threading.Event()
        self.lock = threading.Lock()
        self._partial: dict[int, str] = {}
        self._thread = threading.Thread(target=self._read, daemon=True)
        self._thread.start()

    def _read(self) -> None:
        while not self._stop.is_set():
            msg = self.conn.recv_match(blocking=True, timeout=0.5)
            if msg is None:
                continue
            mtype = msg.get_type()
            with self.lock:
                self.counts[mtype] += 1
                if mtype == "GLOBAL_POSITION_INT":
                    t_s = msg.time_boot_ms / 1000.0
                    self.t_last_s = t_s
                    self.positions.append((t_s, msg.lat * 1e-7, msg.lon * 1e-7, msg.alt * 1e-3))
                elif mtype == "GPS_INPUT":
                    self.accuracies.append((msg.time_usec * 1e-6, float(msg.horiz_accuracy)))
                elif mtype == "STATUSTEXT":
                    text = msg.text
                    sid = int(getattr(msg, "id", 0) or 0)
                    if sid:
                        self._partial[sid] = self._partial.get(sid, "") + text
                        if len(text) == 50:
                            continue
                        text = self._partial.pop(sid)
                    self.alerts.append((self.t_last_s, text))

    def alert_times(self, code: str) -> list[float]:
        with self.lock:
            return [t for t, text in self.alerts if text.startswith(f"CMP {code}")]

    def close(self) -> None:
        self._stop.set()
        self._thread.join(timeout=2)
        with contextlib.suppress(Exception):
            self.conn.close()


def horizontal_m(lat0: float, lon0: float, lat1: float, lon1: float) -> float:
    """Horizontal distance between two nearby points (deg), m (equirectangular)."""
    dn = math.radians(lat1 - lat0) * EARTH_RADIUS_M
    de = math.radians(lon1 - lon0) * EARTH_RADIUS_M * math.cos(math.radians(0.5 * (lat0 + lat1)))
    return math.hypot(dn, de)


def offset_deg(lat: float, lon: float, north_m: float, east_m: float) -> tuple[float, float]:
    """The point ``north_m``, ``east_m`` from (lat, lon), deg."""
    dlat = math.degrees(north_m / EARTH_RADIUS_M)
    dlon = math.degrees(east_m / (EARTH_RADIUS_M * math.cos(math.radians(lat))))
    return lat + dlat, lon + dlon
