"""``evaluate --against-input``: each figure on logs built so that the answer is known by
hand, and the ruler on a real flight (bundled: tests/data/real/log171, README there)."""

from __future__ import annotations

import csv
import importlib.util
import json
import math
from pathlib import Path

import numpy as np
import pymap3d
import pytest
from pymavlink.dialects.v20 import ardupilotmega as apm

from companion.cli import main
from companion.config import Config
from companion.evaluate.against_input import H99_PER_SIGMA, evaluate_against_input
from companion.mavlink.decode import Decoder
from companion.mavlink.encode import Encoder
from companion.mavlink.readback import read_tlog
from companion.mavlink.tlog import TlogWriter
from companion.replay import replay
from companion.types import (
    Alert,
    AlertCode,
    AutopilotFlavour,
    FixType,
    GnssFix,
    NamedValue,
    NavMode,
    NavSolution,
    Severity,
)

T0 = 1_600_000_000.0
"""Record clock of the built logs: UNIX time of autopilot time 0."""
LAT0, LON0, ALT0 = math.radians(-35.36), math.radians(149.16), 500.0
REAL = Path(__file__).parent / "data" / "real" / "log171"
REAL_TLOG = REAL / "real_copter_dronekit_log171.tlog"


def geo(n: float, e: float) -> tuple[float, float, float]:
    lat, lon, alt = pymap3d.ned2geodetic(n, e, 0.0, LAT0, LON0, ALT0, deg=False)
    return float(lat), float(lon), float(alt)


class Logs:
    """An input log (the autopilot's messages) and an output log (the service's), built
    message by message on one clock (autopilot time t, record time T0 + t)."""

    def __init__(self) -> None:
        self.ap = apm.MAVLink(None, 1, 1)
        self.enc = Encoder()
        self.inp: list[tuple[float, bytes]] = []
        self.out: list[tuple[float, list[bytes]]] = []

    def heartbeat(self, t: float) -> None:
        msg = apm.MAVLink_heartbeat_message(2, 3, 0, 0, 4, 3)
        self.inp.append((t, msg.pack(self.ap)))

    def imu(self, t: float) -> None:
        msg = apm.MAVLink_highres_imu_message(
            round(t * 1e6), 0.0, 0.0, -9.8, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 20.0, 63
        )
        self.inp.append((t, msg.pack(self.ap)))

    def fix(self, t: float, n: float, e: float, vn: float, ve: float, sats: int = 10) -> None:
        lat, lon, alt = geo(n, e)
        speed = math.hypot(vn, ve)
        cog = round(math.degrees(math.atan2(ve, vn)) * 100.0) % 36000
        msg = apm.MAVLink_gps_raw_int_message(
            round(t * 1e6),
            3,
            round(math.degrees(lat) * 1e7),
            round(math.degrees(lon) * 1e7),
            round(alt * 1000.0),
            100,  # HDOP 1.0: 1-sigma 2.5 m (HDOP x UERE)
            150,
            round(speed * 100.0),
            cog,
            sats,
        )
        self.inp.append((t, msg.pack(self.ap)))

    def publish(
        self,
        t: float,
        n: float,
        e: float,
        vn: float,
        ve: float,
        sigma_m: float = 2.0,
        fix: FixType = FixType.FIX_3D,
    ) -> None:
        lat, lon, alt = geo(n, e)
        sol = NavSolution(
            t_s=t,
            lat_rad=lat,
            lon_rad=lon,
            alt_msl_m=alt,
            vel_ned_mps=np.array([vn, ve, 0.0]),
            pos_cov_ned_m2=np.diag([sigma_m**2, sigma_m**2, (1.5 * sigma_m) ** 2]),
            vel_cov_ned_m2ps2=np.diag([0.01, 0.01, 0.01]),
            yaw_rad=None,
            mode=NavMode.NORMAL,
            fix_type=fix,
            satellites=10,
        )
        frames = self.enc.encode_frames(sol, AutopilotFlavour.ARDUPILOT)
        self.out.append((t, [f for _, f in frames]))

    def alert(self, t: float, code: AlertCode, text: str) -> None:
        self.enc.allow_next(code)
        frames = self.enc.encode_frames(
            Alert(t, code, Severity.WARNING, text), AutopilotFlavour.ARDUPILOT
        )
        self.out.append((t, [f for _, f in frames]))

    def named(self, t: float, name: str, value: float) -> None:
        frames = self.enc.encode_frames(NamedValue(t, name, value), AutopilotFlavour.ARDUPILOT)
        self.out.append((t, [f for _, f in frames]))

    def status(self, t: float, state: int) -> None:
        self.out.append((t, [self.enc.pack(self.enc.heartbeat(state))]))

    def write(self, folder: Path) -> tuple[Path, Path]:
        in_path, out_path = folder / "in.tlog", folder / "out.tlog"
        with TlogWriter(in_path) as w:
            for t, frame in sorted(self.inp, key=lambda x: x[0]):
                w.write(T0 + t, frame)
        with TlogWriter(out_path) as w:
            for t, frames in sorted(self.out, key=lambda x: x[0]):
                w.write_frames(T0 + t, frames)
        return in_path, out_path


def ticks(t0: float, t1: float, hz: float) -> list[float]:
    """Times t0, t0 + 1/hz, ... <= t1 (rounded to the microsecond)."""
    n = int(round((t1 - t0) * hz))
    return [round(t0 + k / hz, 6) for k in range(n + 1)]


def base(logs: Logs, t_end: float, skip: tuple[float, float] | None = None) -> None:
    """Autopilot HEARTBEAT at 1 Hz and IMU at 50 Hz (none inside ``skip``, open)."""
    for t in ticks(0.0, t_end, 1.0):
        logs.heartbeat(t)
    for t in ticks(0.02, t_end, 50.0):
        if skip is None or not skip[0] < t < skip[1]:
            logs.imu(t)


# --------------------------------------------------------------------------- a gap


def north(t: float) -> tuple[float, float]:
    """Position and speed north: 5 m/s, +0.5 m/s^2 from 20 to 26 s, then 8 m/s."""
    if t <= 20.0:
        return 5.0 * t, 5.0
    if t <= 26.0:
        return 100.0 + 5.0 * (t - 20.0) + 0.25 * (t - 20.0) ** 2, 5.0 + 0.5 * (t - 20.0)
    return 139.0 + 8.0 * (t - 26.0), 8.0


def test_gap_closure_against_hold_and_constant_velocity(tmp_path: Path) -> None:
    logs = Logs()
    base(logs, 40.0)
    for t in ticks(10.0, 40.0, 5.0):
        if not 20.0 < t < 26.0:
            logs.fix(t, *north(t)[:1], 0.0, north(t)[1], 0.0)
    for t in ticks(10.0, 40.0, 10.0):
        n, vn = north(t)
        off = 3.0 if 20.0 < t < 26.0 else 0.0  # the bridge drifts 3 m east
        logs.publish(t, n, off, vn, 0.0, sigma_m=2.0)
    logs.alert(21.0, AlertCode.GNSS_LOST, "no usable fix 1.0 s")
    logs.alert(27.0, AlertCode.GNSS_BACK, "after 7.0 s")
    res = evaluate_against_input(*reversed(logs.write(tmp_path)))
    (gap,) = res.gaps
    assert gap.t_last_fix_s == pytest.approx(20.0)
    assert gap.length_s == pytest.approx(6.0)
    assert gap.alert_latency_s == pytest.approx(1.0)
    assert not gap.already_in_outage
    assert gap.imu_running and gap.imu_hz == pytest.approx(299 / 6.0)
    # hold: 139 - 100 m; constant velocity: 100 + 5 x 6 = 130 -> 9 m; the service 3 m
    assert gap.hold_h_m == pytest.approx(39.0, abs=0.02)
    assert gap.cv_h_m == pytest.approx(9.0, abs=0.02)
    assert gap.closure_h_m == pytest.approx(3.0, abs=0.02)
    assert gap.ratio == pytest.approx(1.0 / 3.0, abs=0.005)
    assert gap.bound99_m == pytest.approx(H99_PER_SIGMA * 2.0, rel=1e-4)
    assert gap.inside99 is True
    assert gap.publication_age_s == pytest.approx(0.1)  # the solution at 25.9 s, not 26.0
    s = res.gaps_summary
    assert (s.passed_alert, s.passed_ratio, s.passed_inside99) == (True, True, True)
    # outside the gap the solution is on the track; inside it there is no concurrent fix
    c = res.confidence
    assert c.n_wrong == 0 and c.max_h_m == pytest.approx(0.0, abs=0.02)
    assert c.n_no_concurrent_fix == 59
    assert c.coverage == 1.0
    assert res.dropouts == ()


def test_gap_closure_worse_than_holding_fails(tmp_path: Path) -> None:
    logs = Logs()
    base(logs, 40.0)
    for t in ticks(10.0, 40.0, 5.0):
        if not 20.0 < t < 26.0:
            logs.fix(t, 50.0, 0.0, 0.0, 0.0)  # parked: holding is exact
    for t in ticks(10.0, 40.0, 10.0):
        logs.publish(t, 50.0, 12.0 if 20.0 < t < 26.0 else 0.0, 0.0, 0.0, sigma_m=2.0)
    res = evaluate_against_input(*reversed(logs.write(tmp_path)))
    (gap,) = res.gaps
    assert gap.alert_latency_s is None  # no alert at all: missed
    assert gap.closure_h_m == pytest.approx(12.0, abs=0.02)
    assert gap.ratio is not None and gap.ratio > 1e6  # hold and cv both exact (to rounding)
    assert gap.inside99 is False  # 12 m > 3.03 x 2 m
    s = res.gaps_summary
    assert (s.passed_alert, s.passed_ratio, s.passed_inside99) == (False, False, False)


@pytest.mark.parametrize(("east_m", "passed"), [(0.005, True), (0.03, False)])
def test_gap_closure_tied_with_holding_within_the_rounding(
    tmp_path: Path, east_m: float, passed: bool
) -> None:
    """Parked: holding closes at 0 m. A service 5 mm off (under the published position's
    rounding) ties with it; 3 cm off is worse than holding."""
    logs = Logs()
    base(logs, 40.0)
    for t in ticks(10.0, 40.0, 5.0):
        if not 20.0 < t < 26.0:
            logs.fix(t, 50.0, 100.0, 0.0, 0.0)
    for t in ticks(10.0, 40.0, 10.0):
        logs.publish(t, 50.0, 100.0 + (east_m if 20.0 < t < 26.0 else 0.0), 0.0, 0.0, sigma_m=2.0)
    logs.alert(21.0, AlertCode.GNSS_LOST, "no usable fix 1.0 s")
    res = evaluate_against_input(*reversed(logs.write(tmp_path)))
    (gap,) = res.gaps
    assert gap.closure_h_m is not None and gap.hold_h_m is not None
    assert gap.closure_h_m - gap.hold_h_m == pytest.approx(east_m, abs=0.006)
    assert res.gaps_summary.passed_ratio is passed


# --------------------------------------------------------------------------- confidently wrong


def test_confidently_wrong_counts_only_claimed_fixes(tmp_path: Path) -> None:
    logs = Logs()
    base(logs, 40.0)
    for t in ticks(10.0, 40.0, 5.0):
        logs.fix(t, 5.0 * t, 0.0, 5.0, 0.0)
    for t in ticks(10.0, 40.0, 10.0):
        if 30.0 <= t < 32.0:
            logs.publish(t, 5.0 * t, 40.0, 5.0, 0.0, sigma_m=2.0)  # 40 m off, fix 3D
        elif 34.0 <= t < 35.0:
            logs.publish(t, 5.0 * t, 100.0, 5.0, 0.0, fix=FixType.NO_FIX)  # honest: no fix
        else:
            logs.publish(t, 5.0 * t, 0.0, 5.0, 0.0, sigma_m=2.0)
    res = evaluate_against_input(*reversed(logs.write(tmp_path)))
    c = res.confidence
    n_claims = 301 - 10
    assert c.n_claims == n_claims and c.n_evaluated == n_claims
    assert c.n_wrong == 20
    assert c.max_h_m == pytest.approx(40.0, abs=0.02)
    assert 30.0 <= c.max_h_t_s < 32.0
    # 95 % radius: 2.448 x sqrt(2^2 + 2.5^2) = 7.8 m; the 20 are outside it
    assert c.coverage == pytest.approx((n_claims - 20) / n_claims)
    assert c.n_receiver_sigma_from_hdop == n_claims
    assert (c.passed_wrong, c.passed_coverage) == (False, False)  # 271/291 = 93 %


# --------------------------------------------------------------------------- receiver use


@pytest.mark.parametrize("standby", [False, True])
def test_receiver_use_from_outage_time_and_heartbeat(tmp_path: Path, standby: bool) -> None:
    logs = Logs()
    base(logs, 40.0)
    for t in ticks(10.0, 40.0, 5.0):
        logs.fix(t, 5.0 * t, 0.0, 5.0, 0.0)
    for t in ticks(10.0, 40.0, 1.0):
        logs.named(t, "CMP_OUTG", {25.0: 1.0, 26.0: 2.0, 27.0: 3.0}.get(t, 0.0))
        logs.status(t, 3 if standby and t >= 35.0 else 4)
    res = evaluate_against_input(*reversed(logs.write(tmp_path)))
    u = res.receiver_use
    # good from 20 s (10 s after the first fix) to 40 s: 101 fixes x 0.2 s
    assert u.good_s == pytest.approx(20.2)
    assert u.unused_outage_s == pytest.approx(3.0)  # the fixes of 25.0 .. 27.8 s
    not_nav = 5.2 if standby else 0.0  # STANDBY from 35 s: 26 fixes
    assert u.unused_not_navigating_s == pytest.approx(not_nav)
    assert u.fraction == pytest.approx((20.2 - 3.0 - not_nav) / 20.2)
    assert u.passed is False


# --------------------------------------------------------------------------- dropout


@pytest.mark.parametrize(("offset_m", "inside"), [(4.0, False), (2.0, True)])
def test_whole_stream_dropout_first_solution_against_its_bound(
    tmp_path: Path, offset_m: float, inside: bool
) -> None:
    logs = Logs()
    base(logs, 40.0, skip=(20.0, 25.0))  # heartbeats go on, as in real logs
    for t in ticks(10.0, 40.0, 5.0):
        if not 20.0 < t < 25.0:
            logs.fix(t, 0.0, 0.0, 0.0, 0.0)
    for t in ticks(10.0, 40.0, 10.0):
        if not 20.0 < t < 25.0:
            logs.publish(t, 0.0, offset_m if t == 25.0 else 0.0, 0.0, 0.0, sigma_m=1.0)
    res = evaluate_against_input(*reversed(logs.write(tmp_path)))
    (drop,) = res.dropouts
    assert drop.t_rx_start_s == pytest.approx(20.0)
    assert drop.length_s == pytest.approx(5.0)
    assert drop.dt_s == pytest.approx(0.0)
    assert drop.error_h_m == pytest.approx(offset_m, abs=0.02)
    assert drop.bound99_m == pytest.approx(H99_PER_SIGMA, rel=1e-4)
    assert drop.inside99 is inside and res.passed_dropouts is inside
    (gap,) = res.gaps  # also a GNSS gap, without the IMU
    assert gap.imu_hz == 0.0 and not gap.imu_running
    assert res.gaps_summary.passed_ratio is None


# --------------------------------------------------------------------------- no GNSS


@pytest.mark.parametrize("alert_at", [3.0, None])
def test_no_gnss_alert_after_the_first_autopilot_message(
    tmp_path: Path, alert_at: float | None
) -> None:
    logs = Logs()
    base(logs, 20.0)
    logs.status(1.0, 3)
    if alert_at is not None:
        logs.alert(alert_at, AlertCode.GNSS_LOST, "no GNSS messages 3.0 s")
    res = evaluate_against_input(*reversed(logs.write(tmp_path)))
    n = res.no_gnss
    assert n.applies and n.first_fix_after_s is None
    assert n.alert_latency_s == (None if alert_at is None else pytest.approx(3.0))
    assert n.passed is (alert_at is not None)
    assert res.n_fixes_3d == 0 and res.solution_source is None
    assert res.confidence.passed_wrong is None and res.receiver_use.passed is None
    assert res.row()["no-GNSS alert"].endswith("PASS" if alert_at is not None else "FAIL")


# --------------------------------------------------------------------------- STATUSTEXT


def test_statustext_rate_and_parked_flapping(tmp_path: Path) -> None:
    logs = Logs()
    base(logs, 40.0)
    for t in ticks(10.0, 40.0, 5.0):
        logs.fix(t, 0.0, 0.0, 0.0, 0.0)
    for t, text in [
        (12.0, "lost (landing, CAT I): VPL 35.1 m > VAL 35.0 m"),
        (18.0, "restored (taxi, surface): HPL 23.8 m VPL 35.4 m"),
        (24.0, "lost (landing, CAT I): VPL 35.5 m > VAL 35.0 m"),
        (30.0, "restored (taxi, surface): HPL 23.7 m VPL 36.9 m"),
        (36.0, "lost (landing, CAT I): VPL 37.1 m > VAL 35.0 m"),
    ]:
        logs.alert(t, AlertCode.INTEGRITY, text)
    for t in (13.0, 14.0, 15.0):
        logs.alert(t, AlertCode.GNSS_STALE, f"rx0 frozen: moved 0.{int(t)} m, expected 2 m")
    res = evaluate_against_input(*reversed(logs.write(tmp_path)))
    x = res.texts
    assert x.total == 8 and x.max_in_window == 8 and x.passed_rate is False
    assert x.n_parked_intervals == 1 and x.parked_s == pytest.approx(30.0)
    assert x.flaps_phase_integrity == 3  # lost x3, restored x2: 3 repeats
    assert x.flaps_all == 5  # and GNSS_STALE x3: 2 repeats
    assert x.passed_flapping is False


def test_statustext_announcing_real_gaps_not_counted(tmp_path: Path) -> None:
    """Four real 4 s gaps announced (loss and return: 8 texts) are real changes; four
    loss/return pairs around 1 s pauses between fixes (no gap) are 8 texts too many."""
    logs = Logs()
    base(logs, 70.0)
    gaps = [(12.0, 16.0), (22.0, 26.0), (32.0, 36.0), (42.0, 46.0)]
    for t in ticks(10.0, 70.0, 1.0):
        if not any(a < t < b for a, b in gaps):
            logs.fix(t, 0.0, 0.0, 0.0, 0.0)
    for a, b in gaps:
        logs.alert(a + 1.0, AlertCode.GNSS_LOST, "no GNSS messages 1.0 s: bridging")
        logs.alert(b + 0.1, AlertCode.GNSS_BACK, "after 4.0 s")
    x = evaluate_against_input(*reversed(logs.write(tmp_path))).texts
    assert x.total == 8 and x.real_changes == 8
    assert x.max_in_window == 0 and x.passed_rate is True
    for t in (52.5, 54.5, 56.5, 58.5):  # no gap in the input: noise
        logs.alert(t, AlertCode.GNSS_LOST, "no GNSS messages 1.0 s: bridging")
        logs.alert(t + 0.4, AlertCode.GNSS_BACK, "after 1.0 s")
    x = evaluate_against_input(*reversed(logs.write(tmp_path))).texts
    assert x.total == 16 and x.real_changes == 8
    assert x.max_in_window == 8 and x.passed_rate is False


def test_cli_json_and_errors(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    logs = Logs()
    base(logs, 12.0)
    in_path, out_path = logs.write(tmp_path)
    assert main(["evaluate", str(out_path), "--against-input", str(in_path), "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert set(doc["verdicts"]) >= {"never_wrong", "coverage95", "gap_alert", "text_rate"}
    assert main(["evaluate", str(out_path)]) == 1  # neither --truth nor --against-input
    assert main(["evaluate", str(out_path), "--truth", "t.csv", "--grade", "mems"]) == 1
    assert main(["evaluate", str(out_path), "--against-input", str(tmp_path / "x")]) == 1
    assert "no such file" in capsys.readouterr().err


# --------------------------------------------------------------------------- real flight


def test_real_log_against_itself_is_exact(tmp_path: Path) -> None:
    """The receiver's own fixes published as the solution: zero error, full coverage. The
    fixes the ruler decodes are those of the converter's receiver_track.csv."""
    decoder = Decoder()
    fixes: list[GnssFix] = []
    for t_rx, msg in read_tlog(REAL_TLOG).records:
        fixes += [s for s in decoder.decode(msg, t_rx) if isinstance(s, GnssFix)]
    with (REAL / "receiver_track.csv").open() as fh:
        track = {round(float(r["time_boot_s"]), 3): r for r in csv.DictReader(fh)}
    good = [f for f in fixes if f.fix_type >= FixType.FIX_3D]
    assert len(good) == sum(float(r["fix_type"]) >= 3 for r in track.values()) == 1038
    for f in good:
        row = track[round(f.t_s, 3)]
        assert math.degrees(f.lat_rad) == pytest.approx(float(row["lat_deg"]), abs=1e-7)
        assert math.degrees(f.lon_rad) == pytest.approx(float(row["lon_deg"]), abs=1e-7)
    enc = Encoder()
    out_path = tmp_path / "self.tlog"
    with TlogWriter(out_path) as w:
        for f in good:
            sol = NavSolution(
                t_s=f.t_s,
                lat_rad=f.lat_rad,
                lon_rad=f.lon_rad,
                alt_msl_m=f.alt_msl_m,
                vel_ned_mps=np.array([*(f.vel_ne_mps if f.vel_ne_mps is not None else (0, 0)), 0]),
                pos_cov_ned_m2=np.eye(3),
                vel_cov_ned_m2ps2=np.eye(3),
                yaw_rad=None,
                mode=NavMode.NORMAL,
                fix_type=f.fix_type,
                satellites=f.satellites or 0,
            )
            frames = enc.encode_frames(sol, AutopilotFlavour.ARDUPILOT)
            w.write_frames(f.t_rx_s, [b for _, b in frames])
    res = evaluate_against_input(out_path, REAL_TLOG)
    c = res.confidence
    assert c.n_evaluated == 1038 and c.n_no_concurrent_fix == 0
    assert c.n_wrong == 0 and c.max_h_m == pytest.approx(0.0, abs=0.01)
    assert c.coverage == 1.0
    assert res.receiver_sigma_from_hdop  # this receiver reports no h_acc
    # what the input alone says: no gap >= 3 s (the longest is 2.2 s), no dropout, and the
    # first 3-D fix 34 s after the autopilot's first message
    assert res.gaps == () and res.dropouts == ()
    assert res.no_gnss.applies and res.no_gnss.first_fix_after_s == pytest.approx(33.7, abs=0.1)


def test_real_log_replayed_and_scored(tmp_path: Path) -> None:
    """The replay of the bundled flight is scored: every rule yields a figure (what the
    figures are is the estimators' business: bench/realdata.py prints them)."""
    out_path = tmp_path / "out.tlog"
    config = Config()
    replay(REAL_TLOG, out_path, config)
    res = evaluate_against_input(out_path, REAL_TLOG, config.decoder)
    assert res.solution_source == "GPS_INPUT" and res.n_solutions > 1000
    c = res.confidence
    assert c.n_evaluated > 1000 and 0 <= c.n_wrong <= c.n_evaluated
    assert c.coverage is not None and 0.0 <= c.coverage <= 1.0
    assert res.receiver_use.good_s > 150.0 and res.receiver_use.fraction is not None
    assert res.no_gnss.applies and res.no_gnss.passed is not None
    assert res.texts.total > 0 and res.texts.n_parked_intervals > 0
    assert set(res.row()) == {
        "wrong>25m", "cover95", "rx used", "gap alert", "closure x", "in 99%", "dropout",
        "no-GNSS alert", "txt/60s", "parked flaps",
    }  # fmt: skip
    assert "overall:" in res.to_text()
    assert json.dumps(res.to_dict())


def _bench_realdata():  # type: ignore[no-untyped-def]
    path = Path(__file__).resolve().parents[1] / "bench" / "realdata.py"
    spec = importlib.util.spec_from_file_location("bench_realdata", path)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_bench_realdata_table_skips_and_scores(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    bench = _bench_realdata()
    assert bench.main(["--flights", str(tmp_path / "absent")]) == 0
    assert "skipped: no real data" in capsys.readouterr().out
    flights = tmp_path / "flights"
    (flights / "empty").mkdir(parents=True)
    (flights / REAL_TLOG.stem).mkdir()
    (flights / REAL_TLOG.stem / REAL_TLOG.name).symlink_to(REAL_TLOG)
    assert bench.main(["--flights", str(flights), "--json", str(tmp_path / "r.json")]) == 0
    out = capsys.readouterr().out
    assert "skipped: no empty.tlog in the folder" in out
    row = next(line for line in out.splitlines() if line.startswith(REAL_TLOG.stem))
    assert row.rstrip().endswith(("PASS", "FAIL"))
    doc = json.loads((tmp_path / "r.json").read_text())
    assert [d["flight"] for d in doc] == ["empty", REAL_TLOG.stem]
    assert doc[1]["n_fixes_3d"] == 1038 and "verdicts" in doc[1]
    extra = [{"flight": "other", "new column": "1.0 PASS"}]
    bench.print_table([{"flight": "a", "wrong>25m": "0 PASS"}, *extra])
    lines = capsys.readouterr().out.splitlines()
    assert lines[0].split() == ["flight", "wrong>25m", "new", "column"]
    assert lines[3].split() == ["other", "-", "1.0", "PASS"]


# --------------------------------------------------------------------------- a slow link


def slow_link_gaps(tmp_path: Path, announced: bool) -> tuple:
    """A 1 Hz receiver with a 2.5 s interval at 20 s (its rhythm), then a 3.5 s gap at
    40 s with no alert of its own and a 7 s gap at 60 s alerted 3.8 s after its last fix;
    ``announced``: the service's GNSS_SLOW in force from 15 s."""
    logs = Logs()
    base(logs, 90.0)
    times = [t for t in ticks(10.0, 90.0, 1.0) if not 40.0 < t < 43.5 and not 60.0 < t < 67.0]
    times = [t for t in times if t != 21.0] + [22.5]  # 20 -> 22.5: 2.5 s (then 23.0)
    times = [t for t in times if t != 22.0]
    for t in sorted(times):
        logs.fix(t, 0.0, 0.0, 0.0, 0.0)
    if announced:
        logs.alert(15.0, AlertCode.GNSS_SLOW, "fixes every 1.0 s, up to 1.0 s")
    logs.alert(63.8, AlertCode.GNSS_LOST, "no GNSS messages 3.8 s: bridging")
    logs.alert(67.0, AlertCode.GNSS_BACK, "after 7.0 s")
    res = evaluate_against_input(*reversed(logs.write(tmp_path)))
    return res.gaps, res.gaps_summary


def test_a_slow_link_is_judged_from_when_its_fix_was_due(tmp_path: Path) -> None:
    """With GNSS_SLOW in force the next fix is due by the link's rhythm (its longest
    interval in the minute before: 2.5 s): the 3.5 s gap ends before an alert is owed
    (2.5 + 1.5 s), the 7 s one is alerted 1.3 s after its fix was due."""
    (short, long), summary = slow_link_gaps(tmp_path, announced=True)
    assert short.rhythm_s == pytest.approx(2.5) and short.within_rhythm
    assert short.judged_latency_s == 0.0
    assert long.rhythm_s == pytest.approx(2.5) and not long.within_rhythm
    assert long.alert_latency_s == pytest.approx(3.8)
    assert long.judged_latency_s == pytest.approx(1.3)
    assert summary.passed_alert is True and summary.n_missed == 0


def test_without_the_slow_announcement_each_gap_is_judged_from_its_last_fix(
    tmp_path: Path,
) -> None:
    (short, long), summary = slow_link_gaps(tmp_path, announced=False)
    assert short.rhythm_s is None and short.judged_latency_s is None  # missed
    assert long.judged_latency_s == pytest.approx(3.8)
    assert summary.passed_alert is False and summary.n_missed == 1
