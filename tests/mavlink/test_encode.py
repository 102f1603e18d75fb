"""Encoder: every output packed, parsed back by pymavlink, with the documented values."""

from __future__ import annotations

import math

import numpy as np
import pytest
from pymavlink.dialects.v20 import ardupilotmega as apm
from pymavlink.dialects.v20 import development as dev

from companion.mavlink import units
from companion.mavlink.decode import Decoder
from companion.mavlink.encode import Encoder, EncoderConfig
from companion.mavlink.framing import FrameParser
from companion.mavlink.ids import MAV_COMP_ID_ONBOARD_COMPUTER
from companion.mavlink.readback import PublishedText, TextJoiner
from companion.types import (
    Alert,
    AlertCode,
    AutopilotFlavour,
    FixType,
    IntegrityReport,
    NamedValue,
    NavMode,
    NavSolution,
    Severity,
)

DEG = math.pi / 180.0


def solution(
    t_s: float = 123.456,
    sigma_ne: tuple[float, float] = (0.6, 0.8),
    sigma_d: float = 1.5,
    sigma_v: float = 0.2,
    yaw: float | None = -0.5 * math.pi,
    fix: FixType = FixType.FIX_3D,
) -> NavSolution:
    return NavSolution(
        t_s=t_s,
        lat_rad=47.3977420 * DEG,
        lon_rad=-8.5455940 * DEG,
        alt_msl_m=512.345,
        vel_ned_mps=np.array([12.34, -5.67, 0.89]),
        pos_cov_ned_m2=np.diag([sigma_ne[0] ** 2, sigma_ne[1] ** 2, sigma_d**2]),
        vel_cov_ned_m2ps2=np.diag([sigma_v**2, (0.5 * sigma_v) ** 2, (0.5 * sigma_v) ** 2]),
        yaw_rad=yaw,
        mode=NavMode.NORMAL,
        fix_type=fix,
        satellites=14,
        alt_hae_m=560.0,
    )


def roundtrip(enc: Encoder, msgs: list, module: object = apm) -> list:
    data = b"".join(enc.pack(m) for m in msgs)
    p = FrameParser("development" if module is dev else "ardupilotmega")
    out = p.feed(data)
    assert p.bad_frames == 0 and len(out) == len(msgs)
    for m in out:
        assert m.get_srcSystem() == enc.system_id
        assert m.get_srcComponent() == MAV_COMP_ID_ONBOARD_COMPUTER
    return out


def test_solution_for_ardupilot_is_gpi_plus_gps_input() -> None:
    enc = Encoder(EncoderConfig(gps_input_yaw=True), system_id=7)
    gpi, gin = roundtrip(enc, enc.encode(solution(), AutopilotFlavour.ARDUPILOT))
    assert gpi.get_type() == "GLOBAL_POSITION_INT" and gin.get_type() == "GPS_INPUT"
    assert gpi.time_boot_ms == 123456
    assert gpi.lat == 473977420 and gpi.lon == -85455940
    assert gpi.alt == 512345 and gpi.relative_alt == 0
    assert (gpi.vx, gpi.vy, gpi.vz) == (1234, -567, 89)
    assert gpi.hdg == 27000
    assert gin.time_usec == 123456000 and gin.gps_id == 0 and gin.ignore_flags == 0
    assert gin.fix_type == 3 and gin.satellites_visible == 14
    assert gin.lat == 473977420 and gin.lon == -85455940
    assert gin.alt == pytest.approx(512.345, abs=1e-4)
    assert (gin.vn, gin.ve, gin.vd) == pytest.approx((12.34, -5.67, 0.89), abs=1e-5)
    assert gin.horiz_accuracy == pytest.approx(0.8, rel=1e-6)  # larger N/E sigma
    assert gin.vert_accuracy == pytest.approx(1.5, rel=1e-6)
    assert gin.speed_accuracy == pytest.approx(0.2, rel=1e-6)
    assert gin.hdop == pytest.approx(0.8, rel=1e-6) and gin.vdop == pytest.approx(1.5, rel=1e-6)
    assert gin.yaw == 27000 and gin.time_week == 0


def test_relative_alt_and_yaw_north_and_unknown() -> None:
    enc = Encoder(EncoderConfig(gps_input_yaw=True))
    enc.encode(solution(), AutopilotFlavour.ARDUPILOT)
    s2 = solution(yaw=0.0)
    s2 = NavSolution(**{**{k: getattr(s2, k) for k in s2.__slots__}, "alt_msl_m": 500.0})
    gpi, gin = enc.encode(s2, AutopilotFlavour.ARDUPILOT)
    assert gpi.relative_alt == -12345
    assert gpi.hdg == 0 and gin.yaw == 36000  # north: 36000 in GPS_INPUT, 0 = unknown
    gpi, gin = enc.encode(solution(yaw=None), AutopilotFlavour.ARDUPILOT)
    assert gpi.hdg == 65535 and gin.yaw == 0


def test_accuracy_floors_and_honest_fix() -> None:
    enc = Encoder(EncoderConfig(min_h_acc_m=0.05, min_v_acc_m=0.1, min_vel_acc_mps=0.03))
    _, gin = enc.encode(
        solution(sigma_ne=(1e-4, 1e-4), sigma_d=1e-4, sigma_v=1e-5, fix=FixType.NO_FIX),
        AutopilotFlavour.ARDUPILOT,
    )
    assert gin.horiz_accuracy == 0.05 and gin.vert_accuracy == 0.1 and gin.speed_accuracy == 0.03
    assert gin.fix_type == 1


def test_solution_for_px4_is_global_position_sensor() -> None:
    enc = Encoder(system_id=3)
    gpi, gps = roundtrip(enc, enc.encode(solution(), AutopilotFlavour.PX4))
    assert gps.get_type() == "GLOBAL_POSITION_SENSOR"
    assert gps.target_system == 3 and gps.target_component == 1
    assert gps.time_usec == 123456000 and gps.source == 6 and gps.flags == 2
    assert gps.lat == 473977420 and gps.lon == -85455940
    assert gps.alt == pytest.approx(512.345, abs=1e-4) and gps.alt_ellipsoid == 560.0
    assert gps.eph == pytest.approx(0.8, rel=1e-6) and gps.epv == pytest.approx(1.5, rel=1e-6)
    _, bad = enc.encode(solution(fix=FixType.FIX_2D), AutopilotFlavour.PX4)
    assert bad.flags == 1  # unhealthy


def test_px4_position_carried_forward_by_the_lead() -> None:
    # 12.34 m/s north, -5.67 m/s east for 50 ms: 0.617 m north, 0.2835 m west, stamped
    # 50 ms later; GPS_INPUT / GLOBAL_POSITION_INT keep the solution's own time and place
    enc = Encoder(system_id=3, config=EncoderConfig(px4_agp_lead_s=0.05))
    gpi, gps = roundtrip(enc, enc.encode(solution(), AutopilotFlavour.PX4))
    assert gps.time_usec == 123506000 and gpi.time_boot_ms == 123456
    assert gpi.lat == 473977420 and gpi.lon == -85455940
    lat0, lon0 = 47.3977420 * DEG, -8.5455940 * DEG
    north_m = (gps.lat * 1e-7 * DEG - lat0) * 6367000.0  # meridian radius near 47 deg N
    east_m = (gps.lon * 1e-7 * DEG - lon0) * 6389000.0 * math.cos(lat0)  # prime vertical
    assert north_m == pytest.approx(12.34 * 0.05, abs=0.02)
    assert east_m == pytest.approx(-5.67 * 0.05, abs=0.02)
    # ArduPilot's GPS_INPUT is untouched by it
    gpi2, gin = roundtrip(enc, enc.encode(solution(), AutopilotFlavour.ARDUPILOT))
    assert gin.time_usec == 123456000 and gin.lat == 473977420


def test_output_choice() -> None:
    assert len(Encoder().encode(solution(), AutopilotFlavour.UNKNOWN)) == 1
    forced = Encoder(EncoderConfig(output="gps_input")).encode(solution(), AutopilotFlavour.PX4)
    assert [m.get_type() for m in forced] == ["GLOBAL_POSITION_INT", "GPS_INPUT"]
    with pytest.raises(ValueError):
        EncoderConfig(output="bogus")


def test_nonfinite_solution_not_encoded() -> None:
    enc = Encoder()
    s = solution()
    bad = NavSolution(**{**{k: getattr(s, k) for k in s.__slots__}, "lat_rad": math.nan})
    assert enc.encode(bad, AutopilotFlavour.ARDUPILOT) == []
    assert enc.dropped["nonfinite_solution"] == 1


def test_statustext_format_truncation_and_rate_limit() -> None:
    enc = Encoder(EncoderConfig(statustext_min_interval_s=5.0))
    a = Alert(t_s=10.0, code=AlertCode.GNSS_LOST, severity=Severity.WARNING, text="no fix " * 20)
    chunks = roundtrip(enc, enc.encode(a, AutopilotFlavour.ARDUPILOT))
    assert all(m.severity == 4 for m in chunks)
    # 153 characters: chunks 50, 50, 50, 3 of one non-zero id, in order
    assert [m.chunk_seq for m in chunks] == [0, 1, 2, 3]
    assert len({m.id for m in chunks}) == 1 and chunks[0].id != 0
    assert [len(m.text) for m in chunks] == [50, 50, 50, 3]
    assert "".join(m.text for m in chunks) == ("CMP GNSS_LOST " + "no fix " * 20).rstrip()
    ap = AutopilotFlavour.ARDUPILOT
    assert enc.encode(Alert(12.0, AlertCode.GNSS_LOST, Severity.WARNING), ap) == []
    assert len(enc.encode(Alert(12.0, AlertCode.RTK_LOST, Severity.WARNING), ap)) == 1
    assert len(enc.encode(Alert(15.0, AlertCode.GNSS_LOST, Severity.WARNING), ap)) == 1
    assert enc.suppressed["GNSS_LOST"] == 1
    # a reboot (time going back) re-arms the code
    again = Alert(1.0, AlertCode.GNSS_LOST, Severity.CRITICAL, "x")
    (m,) = roundtrip(enc, enc.encode(again, AutopilotFlavour.ARDUPILOT))
    assert m.text == "CMP GNSS_LOST x" and m.severity == 2 and m.id == 0
    enc2 = Encoder(EncoderConfig(statustext_interval_overrides=(("CAT", 0.0),)))
    for _ in range(3):
        assert len(enc2.encode(Alert(1.0, AlertCode.CAT, Severity.INFO), AutopilotFlavour.PX4)) == 1


def test_a_change_of_state_is_sent_whatever_the_interval() -> None:
    """GNSS lost, back and lost again within the interval: every change reaches the ground
    (thinned, the second loss would leave the ground saying GNSS is back while it is
    not); a repeat of the state last sent is still thinned."""
    enc = Encoder(EncoderConfig(statustext_min_interval_s=5.0))
    ap = AutopilotFlavour.ARDUPILOT
    sent = [
        bool(enc.encode(Alert(t, code, Severity.WARNING), ap))
        for t, code in (
            (10.0, AlertCode.GNSS_LOST),
            (11.0, AlertCode.GNSS_BACK),
            (12.0, AlertCode.GNSS_LOST),
            (12.5, AlertCode.GNSS_LOST),
            (13.0, AlertCode.NO_DATA),
            (13.5, AlertCode.NO_DATA),
            (14.0, AlertCode.DATA_BACK),
        )
    ]
    assert sent == [True, True, True, False, True, False, True]
    assert enc.suppressed == {"GNSS_LOST": 1, "NO_DATA": 1}


def test_integrity_and_category_changes_are_sent_whatever_the_interval() -> None:
    """INTEGRITY restored then lost again within the interval, and the category falling
    twice: each is a new state and reaches the ground (thinned, the ground would believe
    integrity restored, or a category above the service's); a repeat of a state is still
    thinned."""
    enc = Encoder(EncoderConfig(statustext_min_interval_s=5.0))
    ap = AutopilotFlavour.ARDUPILOT
    sent = [
        bool(enc.encode(Alert(t, code, severity, text), ap))
        for t, code, severity, text in (
            (10.0, AlertCode.INTEGRITY, Severity.CRITICAL, "lost (cruise, NPA): HPL"),
            (16.0, AlertCode.INTEGRITY, Severity.NOTICE, "restored (cruise, NPA)"),
            (17.0, AlertCode.INTEGRITY, Severity.CRITICAL, "lost (cruise, NPA): VPL"),
            (18.0, AlertCode.INTEGRITY, Severity.CRITICAL, "bridged 120 s: lost"),
            (20.0, AlertCode.CAT, Severity.WARNING, "CAT III -> CAT II"),
            (21.0, AlertCode.CAT, Severity.WARNING, "CAT II -> CAT I"),
            (22.0, AlertCode.CAT, Severity.WARNING, "CAT II -> CAT I"),
        )
    ]
    assert sent == [True, True, True, False, True, True, False]
    assert enc.suppressed == {"INTEGRITY": 1, "CAT": 1}


def test_the_ground_always_holds_the_newest_state_of_every_family() -> None:
    """Random sequences of the state alerts (every family, INTEGRITY, CAT), a few tenths
    of a second to a few seconds apart: after each, the last text the ground received of
    each family says the state the service last raised (seeded)."""
    rng = np.random.default_rng(35)
    families = {
        "gnss": [AlertCode.NO_GNSS, AlertCode.GNSS_LOST, AlertCode.GNSS_BACK],
        "data": [AlertCode.NO_DATA, AlertCode.DATA_BACK],
        "rtk": [AlertCode.RTK_LOST, AlertCode.RTK_BACK],
        "raw": [AlertCode.RAW_FAULT, AlertCode.RAW_LOST, AlertCode.RAW_BACK],
        "spoof": [AlertCode.SPOOF, AlertCode.SPOOF_END],
    }
    integrity = [(Severity.CRITICAL, "lost"), (Severity.NOTICE, "restored")]
    categories = ["none -> CAT I", "CAT I -> CAT II", "CAT II -> none"]
    ap = AutopilotFlavour.ARDUPILOT
    for _ in range(20):
        enc = Encoder(EncoderConfig(statustext_min_interval_s=5.0))
        raised: dict[str, str] = {}
        ground: dict[str, str] = {}
        t = 0.0
        for _ in range(200):
            t += float(rng.uniform(0.1, 3.0))
            kind = int(rng.integers(len(families) + 2))
            if kind < len(families):
                name = list(families)[kind]
                code = families[name][int(rng.integers(len(families[name])))]
                alert = Alert(t, code, Severity.WARNING, "x")
                state = code.value
            elif kind == len(families):
                name = "integrity"
                severity, text = integrity[int(rng.integers(2))]
                alert = Alert(t, AlertCode.INTEGRITY, severity, text)
                state = text
            else:
                name = "cat"
                text = categories[int(rng.integers(len(categories)))]
                alert = Alert(t, AlertCode.CAT, Severity.NOTICE, text)
                state = text
            raised[name] = state
            if enc.encode(alert, ap):
                ground[name] = state
            assert ground == raised
        assert sum(enc.suppressed.values()) > 0  # the limit did thin repeats


def test_statustext_chunks_join_and_end() -> None:
    """An exact multiple of 50 ends on an empty chunk; over 200 characters is cut; the
    chunks join back through the read-back joiner."""
    ap = AutopilotFlavour.ARDUPILOT
    enc = Encoder(EncoderConfig(statustext_min_interval_s=0.0))
    exact = "x" * (100 - len("CMP CAT "))
    chunks = roundtrip(enc, enc.encode(Alert(1.0, AlertCode.CAT, Severity.INFO, exact), ap))
    assert [len(m.text) for m in chunks] == [50, 50, 0]
    long = roundtrip(enc, enc.encode(Alert(2.0, AlertCode.CAT, Severity.INFO, "y" * 500), ap))
    assert [len(m.text) for m in long] == [50, 50, 50, 50, 0]
    assert long[0].id == chunks[0].id + 1
    joiner = TextJoiner()
    done = [joiner.add(i, PublishedText(m.text, m.severity, m.id)) for i, m in enumerate(chunks)]
    assert done[:2] == [None, None] and done[2] == (0, "CMP CAT " + exact, Severity.INFO)


def test_named_value_float() -> None:
    enc = Encoder()
    (m,) = roundtrip(enc, enc.encode(NamedValue(2.5, "CMP_HPL", 12.75), AutopilotFlavour.ARDUPILOT))
    assert m.name == "CMP_HPL" and m.value == 12.75 and m.time_boot_ms == 2500
    assert enc.encode(NamedValue(2.5, "CMP_TOO_LONG", 1.0), AutopilotFlavour.ARDUPILOT) == []
    assert enc.dropped["bad_name"] == 1


def test_gnss_integrity_only_with_a_dialect_that_has_it() -> None:
    rep = IntegrityReport(
        t_s=1.0, hpl_m=12.34, vpl_m=700.0, integrity_ok=False, fault_detected=True
    )
    assert Encoder().encode(rep, AutopilotFlavour.ARDUPILOT) == []
    enc = Encoder(EncoderConfig(dialect="development"))
    assert enc.has_gnss_integrity
    (m,) = roundtrip(enc, enc.encode(rep, AutopilotFlavour.ARDUPILOT), dev)
    assert m.get_type() == "GNSS_INTEGRITY"
    assert m.raim_hfom == 1234 and m.raim_vfom == 65534 and m.raim_state == 3


def test_heartbeat_pack_sequence_and_sysid() -> None:
    enc = Encoder()
    hb = enc.heartbeat(4)
    enc.system_id = 42
    a, b = enc.pack(hb), enc.pack(hb)
    msgs = FrameParser().feed(a + b)
    assert [m.get_seq() for m in msgs] == [0, 1]
    assert all(m.get_srcSystem() == 42 and m.get_srcComponent() == 191 for m in msgs)
    assert msgs[0].type == 18 and msgs[0].autopilot == 8 and msgs[0].system_status == 4
    # the decoder ignores our own heartbeat
    d = Decoder()
    assert d.decode(msgs[0], 0.0) == [] and d.rejections["own_message"] == 1
    with pytest.raises(ValueError):
        enc.system_id = 0
    # deterministic: a second encoder produces the same bytes
    enc2 = Encoder()
    enc2.system_id = 42
    assert enc2.pack(enc2.heartbeat(4)) == a


def test_gps_input_decodes_back_to_the_same_fix_through_our_decoder_scalings() -> None:
    """GPS_INPUT lat/lon use the same 1e7-degree integers our decoder inverts exactly."""
    enc = Encoder()
    _, gin = enc.encode(solution(), AutopilotFlavour.ARDUPILOT)
    assert gin.lat / units.DEGE7_PER_RAD == pytest.approx(47.3977420 * DEG, abs=1e-15)


def test_closed_form_accuracies_match_navsolution_properties() -> None:
    """GPS_INPUT accuracies equal NavSolution.h_acc_m / v_acc_m / vel_acc_mps (random SPD)."""
    rng = np.random.default_rng(17)
    enc = Encoder(EncoderConfig(min_h_acc_m=1e-9, min_v_acc_m=1e-9, min_vel_acc_mps=1e-9))
    base = solution()
    fields = {k: getattr(base, k) for k in base.__slots__}
    for i in range(300):
        a = rng.normal(size=(3, 3)) * 10.0 ** rng.uniform(-3, 2)
        b = rng.normal(size=(3, 3)) * 10.0 ** rng.uniform(-3, 1)
        pc, vc = a @ a.T, b @ b.T
        if i % 10 == 0:
            vc = np.diag(np.diag(vc))  # the diagonal special case
        sol = NavSolution(**{**fields, "pos_cov_ned_m2": pc, "vel_cov_ned_m2ps2": vc})
        _, gin = enc.encode(sol, AutopilotFlavour.ARDUPILOT)
        # GPS_INPUT carries float32
        assert gin.horiz_accuracy == pytest.approx(sol.h_acc_m, rel=1e-6)
        assert gin.vert_accuracy == pytest.approx(sol.v_acc_m, rel=1e-6)
        assert gin.speed_accuracy == pytest.approx(sol.vel_acc_mps, rel=1e-6)


def test_gps_input_yaw_is_off_by_default() -> None:
    """The autopilot would fuse GPS_INPUT.yaw as a GNSS heading: only when configured."""
    gpi, gin = Encoder().encode(solution(yaw=0.3), AutopilotFlavour.ARDUPILOT)
    assert gin.yaw == 0 and gpi.hdg != 65535


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"output": "bogus"}, r"output must be one of \['auto', 'gps_input'"),
        ({"gps_id": 256}, r"gps_id must be in \[0, 255\], got 256"),
        ({"uere_m": math.inf}, r"uere_m must be > 0, got inf"),
        ({"px4_agp_lead_s": -0.01}, r"px4_agp_lead_s must be in \[0, 0.5\], got -0.01"),
        ({"px4_agp_lead_s": 0.6}, r"px4_agp_lead_s must be in \[0, 0.5\], got 0.6"),
        ({"min_h_acc_m": 0.0}, r"min_h_acc_m must be > 0, got 0.0"),
        ({"statustext_min_interval_s": -1.0}, r"statustext_min_interval_s must be >= 0"),
        ({"statustext_interval_overrides": (("NOPE", 1.0),)}, r"unknown alert code 'NOPE'"),
        ({"dialect": "nope"}, r"unknown MAVLink dialect 'nope'"),
    ],
)
def test_config_rejections_name_the_field(kwargs: dict, message: str) -> None:
    with pytest.raises(ValueError, match=message):
        EncoderConfig(**kwargs)
