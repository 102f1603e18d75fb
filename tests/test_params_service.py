"""The parameter protocol on the wire: ``companion run`` as a real process, pymavlink as
the ground station over UDP on 127.0.0.1 (the service's ``--gcs`` link), and where the
autopilot matters a peer that plays a bundled flight on the autopilot link.

* a list request returns every parameter once, with one consistent count;
* reads by name and by index;
* a valid PARAM_SET is echoed and survives a restart of the service (``params.json``);
* an invalid value is refused: the old value echoed, one STATUSTEXT saying why;
* an unknown name gets no PARAM_VALUE (a set of one gets a STATUSTEXT) and the service
  goes on answering;
* a stream rate set live is requested from the autopilot at once.
"""

from __future__ import annotations

import json
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from pymavlink import mavutil

from companion.mavlink.tlog import TlogReader
from companion.params import BY_NAME, PARAMS

ROOT = Path(__file__).resolve().parents[1]
FIXTURE = ROOT / "sitl_fixtures" / "approach_rtk20.tlog"
OUR_COMPONENT = 191
START_TIMEOUT_S = 30.0


def free_udp_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


class Service:
    """``companion run`` with a ground-station link and a state directory in ``tmp``."""

    def __init__(self, tmp: Path) -> None:
        self.autopilot_port = free_udp_port()
        self.gcs_port = free_udp_port()
        self.state_dir = tmp / "state"
        self.config = tmp / "companion.toml"
        self.config.write_text(
            "[link]\n"
            f'master = "udpin:127.0.0.1:{self.autopilot_port}"\n'
            f'gcs = "udpin:127.0.0.1:{self.gcs_port}"\n'
            f'state_file = "{self.state_dir / "state.json"}"\n'
            'record_dir = ""\n'
        )
        self.proc: subprocess.Popen[bytes] | None = None

        self.log = tmp / "service.log"

    def start(self) -> None:
        """Start the service and wait until it runs (its links open, signals handled)."""
        with open(self.log, "w") as log:
            self.proc = subprocess.Popen(
                [sys.executable, "-m", "companion", "--log-level", "info", "run"]
                + ["--config", str(self.config)],
                cwd=ROOT,
                stdout=subprocess.DEVNULL,
                stderr=log,
            )
        deadline = time.monotonic() + START_TIMEOUT_S
        while "companion running" not in self.log.read_text():
            assert self.alive(), self.log.read_text()
            assert time.monotonic() < deadline, "service did not start"
            time.sleep(0.05)

    def stop(self) -> str:
        """SIGTERM; the service must exit 0. Returns its log."""
        proc = self.proc
        assert proc is not None
        proc.send_signal(signal.SIGTERM)
        try:
            proc.wait(timeout=15)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()
            pytest.fail("service did not stop on SIGTERM")
        self.proc = None
        text = self.log.read_text()
        assert proc.returncode == 0, text
        return text

    def alive(self) -> bool:
        return self.proc is not None and self.proc.poll() is None


class Gcs:
    """pymavlink as the ground station (system 255, component 190)."""

    def __init__(self, service: Service) -> None:
        self.service = service
        self.conn = mavutil.mavlink_connection(
            f"udpout:127.0.0.1:{service.gcs_port}", source_system=255, source_component=190
        )
        self.target_system = self.connect()

    def connect(self) -> int:
        """Beat until the service's heartbeat (component 191) comes back: its system id."""
        deadline = time.monotonic() + START_TIMEOUT_S
        while time.monotonic() < deadline:
            assert self.service.alive(), "service died"
            self.conn.mav.heartbeat_send(6, 8, 0, 0, 0)  # MAV_TYPE_GCS, MAV_AUTOPILOT_INVALID
            msg = self.conn.recv_match(type="HEARTBEAT", blocking=True, timeout=0.5)
            if msg is not None and msg.get_srcComponent() == OUR_COMPONENT:
                return int(msg.get_srcSystem())
        pytest.fail("the service never answered the ground station")

    def ours(self, types: list[str], timeout_s: float) -> list[Any]:
        """Every message of ``types`` from component 191 within ``timeout_s``."""
        got = []
        deadline = time.monotonic() + timeout_s
        while (left := deadline - time.monotonic()) > 0:
            msg = self.conn.recv_match(type=types, blocking=True, timeout=left)
            if msg is not None and msg.get_srcComponent() == OUR_COMPONENT:
                got.append(msg)
        return got

    def first(self, types: list[str], timeout_s: float = 3.0, **fields: Any) -> Any:
        deadline = time.monotonic() + timeout_s
        while (left := deadline - time.monotonic()) > 0:
            msg = self.conn.recv_match(type=types, blocking=True, timeout=left)
            if msg is None or msg.get_srcComponent() != OUR_COMPONENT:
                continue
            if all(getattr(msg, k) == v for k, v in fields.items()):
                return msg
        return None

    def read(self, name: str = "", index: int = -1) -> Any:
        self.conn.mav.param_request_read_send(
            self.target_system, OUR_COMPONENT, name.encode(), index
        )
        want = {"param_id": name} if index < 0 else {"param_index": index}
        return self.first(["PARAM_VALUE"], **want)

    def set(self, name: str, value: float, param_type: int) -> tuple[Any, list[str]]:
        """PARAM_SET: the PARAM_VALUE echo and the STATUSTEXTs that came with it."""
        self.conn.mav.param_set_send(
            self.target_system, OUR_COMPONENT, name.encode(), value, param_type
        )
        echo, texts = None, []
        for msg in self.ours(["PARAM_VALUE", "STATUSTEXT"], 1.5):
            if msg.get_type() == "STATUSTEXT":
                texts.append(msg.text)
            elif msg.param_id == name:
                echo = msg
        return echo, texts

    def close(self) -> None:
        self.conn.close()


@pytest.fixture
def service(tmp_path):
    svc = Service(tmp_path)
    svc.start()
    yield svc
    if svc.alive():
        svc.stop()


def f32(x: float) -> float:
    return float(np.float32(x))


def test_list_returns_every_parameter_once_with_a_consistent_count(service):
    gcs = Gcs(service)
    try:
        gcs.conn.mav.param_request_list_send(gcs.target_system, 0)  # broadcast component
        values: dict[int, Any] = {}
        counts = set()
        repeats = 0
        deadline = time.monotonic() + 15.0
        while len(values) < len(PARAMS) and time.monotonic() < deadline:
            for msg in gcs.ours(["PARAM_VALUE"], 0.5):
                counts.add(msg.param_count)
                repeats += msg.param_index in values
                values[msg.param_index] = msg
    finally:
        gcs.close()
    assert counts == {len(PARAMS)}
    assert repeats == 0
    assert sorted(values) == list(range(len(PARAMS)))
    assert [values[i].param_id for i in range(len(PARAMS))] == [p.name for p in PARAMS]
    assert values[BY_NAME["ENG_PUB_RATE"].index].param_value == 10.0


def test_read_by_name_and_by_index(service):
    gcs = Gcs(service)
    try:
        p = BY_NAME["OUT_GNSS_TIMEOUT"]
        by_name = gcs.read(p.name)
        by_index = gcs.read(index=p.index)
    finally:
        gcs.close()
    for msg in (by_name, by_index):
        assert msg is not None
        assert (msg.param_id, msg.param_index, msg.param_count) == (p.name, p.index, len(PARAMS))
        assert (msg.param_value, msg.param_type) == (1.0, mavutil.mavlink.MAV_PARAM_TYPE_REAL32)


def test_a_valid_set_is_echoed_and_survives_a_restart(service):
    real32 = mavutil.mavlink.MAV_PARAM_TYPE_REAL32
    int32 = mavutil.mavlink.MAV_PARAM_TYPE_INT32
    gcs = Gcs(service)
    try:
        echo, texts = gcs.set("ENG_PUB_RATE", 5.0, real32)  # live
        assert echo is not None and echo.param_value == 5.0 and texts == []
        echo, texts = gcs.set("BLD_LEVER_Z", -0.3, real32)  # at the next start
        assert echo is not None and echo.param_value == f32(-0.3)
        assert texts == ["CMP PARAM BLD_LEVER_Z applies after restart"]
        echo, texts = gcs.set("ENG_NAVIGATOR", 1, int32)
        assert echo is not None and echo.param_value == 1.0 and echo.param_type == int32
    finally:
        gcs.close()
    service.stop()
    saved = json.loads((service.state_dir / "params.json").read_text())
    assert saved == {
        "version": 1,
        "params": {"ENG_PUB_RATE": 5.0, "BLD_LEVER_Z": -0.3, "ENG_NAVIGATOR": "singer"},
    }
    service.start()
    gcs = Gcs(service)
    try:
        assert gcs.read("ENG_PUB_RATE").param_value == 5.0
        assert gcs.read("BLD_LEVER_Z").param_value == f32(-0.3)
        assert gcs.read("ENG_NAVIGATOR").param_value == 1.0
    finally:
        gcs.close()
    err = service.stop()
    assert "3 parameters set over MAVLink loaded" in err


def test_an_invalid_value_is_refused_and_the_old_value_echoed(service):
    gcs = Gcs(service)
    try:
        echo, texts = gcs.set("ENG_PUB_RATE", 80.0, mavutil.mavlink.MAV_PARAM_TYPE_REAL32)
        assert echo is not None and echo.param_value == 10.0
        assert texts == ["CMP PARAM ENG_PUB_RATE must be in (0, 50]"]
        echo, texts = gcs.set("HDG_AUTO_APPLY", 3, mavutil.mavlink.MAV_PARAM_TYPE_UINT8)
        assert echo is not None and echo.param_value == 0.0
        assert texts == ["CMP PARAM HDG_AUTO_APPLY must be 0 or 1"]
        assert gcs.read("ENG_PUB_RATE").param_value == 10.0
    finally:
        gcs.close()
    service.stop()
    assert not (service.state_dir / "params.json").exists()


def test_an_unknown_name_gets_no_value_and_no_crash(service):
    gcs = Gcs(service)
    try:
        assert gcs.read("NO_SUCH_PARAM") is None
        assert gcs.read(index=len(PARAMS)) is None
        echo, texts = gcs.set("NO_SUCH_PARAM", 1.0, mavutil.mavlink.MAV_PARAM_TYPE_REAL32)
        assert echo is None and texts == ["CMP PARAM NO_SUCH_PARAM unknown"]
        assert gcs.read("LNK_HB_RATE").param_value == 1.0  # still serving
    finally:
        gcs.close()
    assert service.alive()


def flight_frames(seconds: float) -> list[bytes]:
    frames, t0 = [], None
    for t, msg in TlogReader(FIXTURE):
        t0 = t if t0 is None else t0
        if t - t0 > seconds:
            break
        frames.append(bytes(msg.get_msgbuf()))
    return frames


def test_a_stream_rate_set_live_is_requested_from_the_autopilot(service):
    autopilot = mavutil.mavlink_connection(
        f"udpout:127.0.0.1:{service.autopilot_port}", source_system=1, source_component=1
    )
    try:
        frames = flight_frames(5.0)
        for frame in frames:  # the autopilot appears: its streams are requested
            autopilot.write(frame)
        first = _interval_requests(autopilot, 3.0)
        assert first.get(mavutil.mavlink.MAVLINK_MSG_ID_GPS_RAW_INT) == 100_000.0  # 10 Hz
        gcs = Gcs(service)
        try:
            echo, texts = gcs.set("SR_GPS_RAW_INT", 4.0, mavutil.mavlink.MAV_PARAM_TYPE_REAL32)
            assert echo is not None and echo.param_value == 4.0 and texts == []
        finally:
            gcs.close()
        again = _interval_requests(autopilot, 3.0)
        assert again.get(mavutil.mavlink.MAVLINK_MSG_ID_GPS_RAW_INT) == 250_000.0  # 4 Hz
    finally:
        autopilot.close()


def _interval_requests(conn: Any, timeout_s: float) -> dict[int, float]:
    """SET_MESSAGE_INTERVAL requests from component 191: message id -> interval (us)."""
    got: dict[int, float] = {}
    deadline = time.monotonic() + timeout_s
    while (left := deadline - time.monotonic()) > 0:
        msg = conn.recv_match(type="COMMAND_LONG", blocking=True, timeout=left)
        if (
            msg is not None
            and msg.get_srcComponent() == OUR_COMPONENT
            and msg.command == mavutil.mavlink.MAV_CMD_SET_MESSAGE_INTERVAL
        ):
            got[int(msg.param1)] = msg.param2
    return got
