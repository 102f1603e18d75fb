"""The configuration as MAVLink parameters, through the pipeline (no sockets here; the
wire test against a running service is tests/test_params_service.py).

* the table: every configuration key is a parameter or says why not; names, types,
  pinned words, the documented list;
* every parameter reads by name and by index with its index and the count, and takes a
  new value that the configuration accepts: echoed, applied at once when live, else
  announced for the restart, and reloaded from what the service persists;
* refusals (range, checks between keys, type) echo the old value with one STATUSTEXT;
* live keys change what the running pipeline sends (publication rate, stream requests,
  GPS_INPUT fields, heartbeat), without stalling a clock.
"""

from __future__ import annotations

import dataclasses
import math
import typing
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from pymavlink.dialects.v20 import ardupilotmega as mavlink

from companion.config import Config, ConfigError, merge_config
from companion.engine import Engine
from companion.mavlink.encode import Encoder, EncoderConfig
from companion.mavlink.framing import FrameParser
from companion.mavlink.params import (
    MAV_PARAM_TYPE_INT32,
    MAV_PARAM_TYPE_REAL32,
    MAV_PARAM_TYPE_UINT8,
    real32,
)
from companion.mavlink.tlog import TlogReader
from companion.params import (
    BY_NAME,
    CHOICES,
    LIST_BURST,
    LIVE_KEYS,
    NOT_EXPOSED,
    PARAMS,
    PREFIXES,
    TABLE,
    Param,
    get_value,
    load_overrides,
    markdown_table,
    saved_form,
    wire_of,
    with_value,
)
from companion.pipeline import Pipeline
from companion.ranges import field_range

ROOT = Path(__file__).resolve().parents[1]
FIXTURE = ROOT / "sitl_fixtures" / "approach_rtk20.tlog"
GCS = mavlink.MAVLink(None, srcSystem=255, srcComponent=190)
N = len(PARAMS)


def f32(x: float) -> float:
    """``x`` as a PARAM_VALUE carries it (a 32-bit float, read back exactly)."""
    return float(np.float32(x))


def gcs(msg: Any) -> Any:
    """``msg`` as the pipeline receives it: packed by a ground station, parsed back."""
    return GCS.decode(bytearray(msg.pack(GCS)))


def parsed(frames: list[bytes]) -> list[Any]:
    parser = FrameParser()
    return [m for f in frames for m in parser.feed(f)]


def read(pipe: Pipeline, name: str = "", index: int = -1, comp: int = 191) -> list[Any]:
    req = mavlink.MAVLink_param_request_read_message(1, comp, name.encode(), index)
    return parsed(pipe.on_message(gcs(req), 0.0))


def set_param(pipe: Pipeline, name: str, value: float, t_rx_s: float = 0.0) -> list[Any]:
    req = mavlink.MAVLink_param_set_message(1, 191, name.encode(), value, 0)
    return parsed(pipe.on_message(gcs(req), t_rx_s))


def leaf_keys(obj: Any, prefix: str) -> list[str]:
    """Every key of a configuration block, ``key[i]`` for the items of a fixed-length list."""
    keys = []
    for f in dataclasses.fields(obj):
        value = getattr(obj, f.name)
        if dataclasses.is_dataclass(value):
            keys += leaf_keys(value, f"{prefix}.{f.name}")
            continue
        rng = field_range(f)
        if rng is not None and rng.length is not None:
            keys += [f"{prefix}.{f.name}[{i}]" for i in range(rng.length)]
        else:
            keys.append(f"{prefix}.{f.name}")
    return keys


ALL_KEYS = [
    k for f in dataclasses.fields(Config) for k in leaf_keys(getattr(Config(), f.name), f.name)
]


# --------------------------------------------------------------------------- the table


def test_every_configuration_key_is_a_parameter_or_says_why_not():
    exposed = [path for _, path in TABLE]
    assert len(set(exposed)) == len(exposed), "a key with two names"
    assert sorted(set(exposed) | set(NOT_EXPOSED)) == sorted(ALL_KEYS)
    assert not set(exposed) & set(NOT_EXPOSED)
    assert all(why for why in NOT_EXPOSED.values())


def test_names_are_short_unique_and_prefixed_by_their_block():
    assert len(BY_NAME) == N == len(TABLE)
    for p in PARAMS:
        assert len(p.name) <= 16 and p.name.isascii() and p.name == p.name.upper()
        assert p.name.startswith(PREFIXES[p.block] + "_"), p.name
        assert PARAMS[p.index] is p


def test_types_follow_the_configuration():
    for p in PARAMS:
        value = get_value(Config(), p)
        expected = {
            "float": MAV_PARAM_TYPE_REAL32,
            "int": MAV_PARAM_TYPE_INT32,
            "choice": MAV_PARAM_TYPE_INT32,
            "bool": MAV_PARAM_TYPE_UINT8,
        }[p.kind]
        assert p.param_type == expected
        if p.kind == "bool":
            assert isinstance(value, bool)
        elif p.kind == "float":
            assert value is None and p.optional or isinstance(value, float)
        elif p.kind == "int":
            assert value is None and p.optional or isinstance(value, int)


def test_words_are_pinned_to_the_configuration_choices():
    for path, words in CHOICES.items():
        block, key = path.rsplit(".", 1)
        obj: Any = Config()
        for part in block.split("."):
            obj = getattr(obj, part)
        rng = field_range(next(f for f in dataclasses.fields(obj) if f.name == key))
        assert rng is not None and rng.choices is not None
        assert sorted(rng.choices) == sorted(words), path


def test_live_keys_exist():
    for block, keys in LIVE_KEYS.items():
        obj: Any = Config()
        for part in block.split("."):
            obj = getattr(obj, part)
        assert keys <= {f.name for f in dataclasses.fields(obj)}, block


def test_the_documented_list_is_the_table():
    doc = (ROOT / "docs" / "params.md").read_text(encoding="utf-8")
    assert markdown_table() in doc, (
        "docs/params.md is out of date: paste the output of\n"
        "python -c 'import companion.params as p; print(p.markdown_table(), end=\"\")'"
    )


# --------------------------------------------------------------------------- reading


def test_read_by_name_and_by_index_agree_for_every_parameter():
    pipe = Pipeline()
    for p in PARAMS:
        by_name = read(pipe, p.name)
        by_index = read(pipe, "", p.index)
        assert len(by_name) == 1 and len(by_index) == 1, p.name
        for m in (by_name[0], by_index[0]):
            assert m.get_type() == "PARAM_VALUE"
            assert m.param_id == p.name
            assert (m.param_index, m.param_count, m.param_type) == (p.index, N, p.param_type)
            assert m.param_value == f32(wire_of(p, get_value(Config(), p)))


def test_list_sends_every_parameter_once_paced_by_the_timer():
    pipe = Pipeline()
    req = gcs(mavlink.MAVLink_param_request_list_message(1, 0))
    first = parsed(pipe.on_message(req, 100.0))
    assert len(first) == LIST_BURST
    got = list(first)
    t = 100.0
    while pipe.params.next_due_s() < math.inf:
        assert pipe.params.next_due_s() > t  # paced, not all at once
        t = pipe.params.next_due_s()
        got += [m for m in parsed(pipe.on_timer(t)) if m.get_type() == "PARAM_VALUE"]
    assert sorted(m.param_index for m in got) == list(range(N))
    assert {m.param_count for m in got} == {N}
    assert [m.param_id for m in got] == [p.name for p in PARAMS]
    # a new list request starts over
    again = parsed(pipe.on_message(req, t + 1.0))
    assert [m.param_index for m in again] == list(range(LIST_BURST))


def test_only_requests_addressed_to_us_are_answered():
    pipe = Pipeline()
    assert read(pipe, "ENG_PUB_RATE", comp=1) == []
    assert read(pipe, "ENG_PUB_RATE", comp=0) == []  # read and set: our component only
    assert pipe.decoder.rejections["unhandled_type"] == 2  # the link's normal traffic
    other_system = mavlink.MAVLink_param_request_list_message(42, 191)
    assert pipe.on_message(gcs(other_system), 0.0) == []
    other_comp = mavlink.MAVLink_param_request_list_message(1, 1)
    assert pipe.on_message(gcs(other_comp), 0.0) == []
    broadcast = mavlink.MAVLink_param_request_list_message(0, 0)
    assert len(pipe.on_message(gcs(broadcast), 0.0)) == LIST_BURST


def test_an_unknown_name_or_index_gets_no_value():
    pipe = Pipeline()
    assert read(pipe, "NO_SUCH_PARAM") == []
    assert read(pipe, "", N) == []
    assert pipe.decoder.rejections["unknown_param"] == 2
    answer = set_param(pipe, "NO_SUCH_PARAM", 1.0)
    assert [m.get_type() for m in answer] == ["STATUSTEXT"]
    assert answer[0].text == "CMP PARAM NO_SUCH_PARAM unknown"
    assert pipe.params.changes == 0
    assert len(read(pipe, "ENG_PUB_RATE")) == 1  # still serving


# --------------------------------------------------------------------------- setting


def candidates(p: Param, current: Any) -> list[float]:
    """Numbers to try for a new value of ``p`` (the configuration decides which is valid)."""
    if p.kind == "bool":
        return [0.0 if current else 1.0]
    if p.kind == "choice":
        return [float(i) for i in range(len(p.choices)) if p.choices[i] != current]
    if p.choices:  # an integer enumeration
        return [float(int(c)) for c in p.choices if c != current]
    if current is None or (isinstance(current, float) and not math.isfinite(current)):
        return [1.0, 5.0, 100.0]
    if p.kind == "int":
        return [float(current + 1), float(current - 1), float(current + 10)]
    return [real32(current * 1.25) if current else 0.5, real32(current * 0.8) or -0.5, 1.0]


def new_value(p: Param, config: Config) -> tuple[float, Any]:
    """A number the configuration accepts for ``p`` that changes it, and its value."""
    from companion.params import value_of

    current = get_value(config, p)
    for number in candidates(p, current):
        value = value_of(p, number)
        try:
            with_value(config, p, value)
        except ConfigError:
            continue
        return number, value
    raise AssertionError(f"no candidate value for {p.name}")


@pytest.mark.parametrize("p", PARAMS, ids=lambda p: p.name)
def test_every_parameter_takes_a_valid_value(p: Param):
    pipe = Pipeline()
    number, value = new_value(p, Config())
    answer = set_param(pipe, p.name, number)
    echo = answer[0]
    assert (echo.get_type(), echo.param_id, echo.param_index) == ("PARAM_VALUE", p.name, p.index)
    assert echo.param_value == f32(number)
    assert get_value(pipe.params.config, p) == value
    texts = [m.text for m in answer if m.get_type() == "STATUSTEXT"]
    if p.live:
        assert get_value(pipe.config, p) == value
        assert texts == []
    else:
        assert get_value(pipe.config, p) == get_value(Config(), p)
        assert texts == [f"CMP PARAM {p.name} applies after restart"]
    assert pipe.params.changes == 1
    # what the service persists gives the same configuration at the next start
    config, applied, problems = load_overrides(Config(), saved_form(pipe.params.overrides))
    assert problems == [] and list(applied) == [p.name]
    assert config == pipe.params.config
    # and the value reads back
    assert read(pipe, p.name)[0].param_value == f32(number)


def test_a_value_equal_on_the_wire_changes_nothing():
    pipe = Pipeline()
    p = BY_NAME["BLD_ACC_VRW"]
    exact = get_value(Config(), p)
    assert real32(exact) != exact  # the default is not a 32-bit float
    answer = set_param(pipe, p.name, real32(exact))
    assert [m.get_type() for m in answer] == ["PARAM_VALUE"]
    assert pipe.params.changes == 0 and get_value(pipe.params.config, p) == exact


def test_a_ground_station_decimal_is_kept_as_typed():
    pipe = Pipeline()
    set_param(pipe, "BLD_LEVER_X", 0.3)
    assert pipe.params.config.blend.lever_arm_b_m == (0.3, 0.0, 0.0)


@pytest.mark.parametrize(
    ("name", "number", "why"),
    [
        ("ENG_PUB_RATE", 60.0, "must be in (0, 50]"),
        ("LNK_HB_RATE", 0.0, "must be in [0.1, 10]"),
        ("ENG_STATUS_RATE", 20.0, "must be <= ENG_PUB_RATE (10)"),
        ("HDG_MIN_CYCLES", 10.5, "must be an integer"),
        ("HDG_PARK_CHECK", 2.0, "must be 0 or 1"),
        ("ENG_NAVIGATOR", 3.0, "must be 0..2"),
        ("PHS_GROUND_HGT", math.nan, "must be a number"),
        ("OUT_STALE_MOTION", 1.0, "must be in (0, 1)"),
        ("INT_APPROACH_CAT", 7.0, "7 is not one of ['NONE', 'CAT_I', 'CAT_II', 'CAT_III']"),
        ("DEC_SYSID", 300.0, "must be in [1, 255]"),
    ],
)
def test_a_refused_value_echoes_the_old_one_and_says_why(name, number, why):
    pipe = Pipeline()
    p = BY_NAME[name]
    before = get_value(Config(), p)
    answer = set_param(pipe, name, number)
    assert [m.get_type() for m in answer] == ["PARAM_VALUE", "STATUSTEXT"]
    assert answer[0].param_value == f32(wire_of(p, before))
    assert answer[1].text == f"CMP PARAM {name} {why}"[:50].rstrip()
    assert answer[1].severity == mavlink.MAV_SEVERITY_WARNING
    assert pipe.params.config == Config() and pipe.config == Config()
    assert pipe.params.changes == 0 and pipe.params.overrides == {}
    assert pipe.decoder.rejections["param_refused"] == 1


def test_a_check_between_keys_sees_the_values_set_before():
    pipe = Pipeline()
    assert len(set_param(pipe, "ENG_PUB_RATE", 20.0)) == 1
    assert len(set_param(pipe, "ENG_STATUS_RATE", 20.0)) == 1  # <= 20 now
    answer = set_param(pipe, "ENG_PUB_RATE", 5.0)
    assert answer[1].text.startswith("CMP PARAM ENG_PUB_RATE ENG_STATUS_RATE must be <=")


# --------------------------------------------------------------------------- persistence


def test_saved_values_load_in_order_and_bad_ones_are_dropped():
    saved = {
        "version": 1,
        "params": {
            "ENG_PUB_RATE": 20.0,
            "ENG_STATUS_RATE": 15.0,  # valid only after ENG_PUB_RATE
            "ENG_NAVIGATOR": "singer",
            "BLD_LEVER_Z": -0.25,
            "DEC_SYSID": None,
            "HDG_MIN_FIX": 4,
            "NOT_A_PARAM": 1.0,
            "OUT_MAX_BRIDGE": -5.0,
            "ENC_OUTPUT": "bogus",
            "HDG_AUTO_APPLY": "yes",
        },
    }
    config, applied, problems = load_overrides(Config(), saved)
    assert config.engine.publish_rate_hz == 20.0 and config.engine.status_rate_hz == 15.0
    assert config.engine.navigator == "singer"
    assert config.blend.lever_arm_b_m == (0.0, 0.0, -0.25)
    assert config.decoder.system_id is None and int(config.heading.min_fix_type) == 4
    assert list(applied) == [
        "ENG_PUB_RATE",
        "ENG_STATUS_RATE",
        "ENG_NAVIGATOR",
        "BLD_LEVER_Z",
        "DEC_SYSID",
        "HDG_MIN_FIX",
    ]
    assert [line.split(":")[0] for line in problems] == [
        "NOT_A_PARAM",
        "OUT_MAX_BRIDGE",
        "ENC_OUTPUT",
        "HDG_AUTO_APPLY",
    ]
    assert load_overrides(Config(), {"nothing": 1})[2] == ["no 'params' table"]


def test_an_optional_key_is_unset_by_zero_as_in_the_toml_it_is_absent():
    config = merge_config(Config(), {"blend": {"gnss_err_tau_s": 30.0}})
    pipe = Pipeline(config)
    answer = set_param(pipe, "BLD_GNSS_TAU", 0.0)
    assert answer[0].param_value == 0.0
    assert pipe.params.config.blend.gnss_err_tau_s is None
    assert saved_form(pipe.params.overrides)["params"] == {"BLD_GNSS_TAU": None}


# --------------------------------------------------------------------------- applied live


def flight(seconds: float) -> list[tuple[float, Any]]:
    out = []
    for t, msg in TlogReader(FIXTURE):
        if out and t - out[0][0] > seconds:
            break
        out.append((t, msg))
    return out


def run(pipe: Pipeline, records: list[tuple[float, Any]]) -> list[Any]:
    sent: list[bytes] = []
    for t, msg in records:
        sent += pipe.on_message(msg, t)
    return parsed(sent)


def test_the_publication_rate_changes_at_once_and_never_stalls():
    # on the tick of publish_rate_hz (publish_on_fix off): the rate is the configured one
    records = flight(40.0)
    half = len(records) // 2
    for rate_hz in (5.0, 20.0):
        config = Config()
        config = dataclasses.replace(
            config, engine=dataclasses.replace(config.engine, publish_on_fix=False)
        )
        pipe = Pipeline(config)
        before = [m for m in run(pipe, records[:half]) if m.get_type() == "GLOBAL_POSITION_INT"]
        assert set_param(pipe, "ENG_PUB_RATE", rate_hz)[0].param_value == rate_hz
        after = [m for m in run(pipe, records[half:]) if m.get_type() == "GLOBAL_POSITION_INT"]
        t_before = [m.time_boot_ms / 1000.0 for m in before[-20:]]
        t_after = [m.time_boot_ms / 1000.0 for m in after]
        assert max(b - a for a, b in zip(t_before, t_before[1:], strict=False)) <= 0.11
        gaps = [b - a for a, b in zip(t_after, t_after[1:], strict=False)]
        # no stall at the change: the next publication within the longer of the two periods
        assert t_after[0] - t_before[-1] <= max(0.1, 1.0 / rate_hz) + 0.02
        assert abs(len(t_after) / (t_after[-1] - t_after[0]) - rate_hz) < 0.1 * rate_hz
        assert max(gaps) <= 1.0 / rate_hz + 0.02


def test_a_lower_status_rate_does_not_wait_for_the_old_period_index():
    records = flight(30.0)
    pipe = Pipeline()
    run(pipe, records[: len(records) // 2])
    set_param(pipe, "ENG_STATUS_RATE", 0.5)
    after = [
        m.time_boot_ms / 1000.0
        for m in run(pipe, records[len(records) // 2 :])
        if m.get_type() == "NAMED_VALUE_FLOAT" and m.name == "CMP_HACC"
    ]
    assert len(after) >= 5
    gaps = [b - a for a, b in zip(after, after[1:], strict=False)]
    assert all(abs(g - 2.0) < 0.15 for g in gaps), gaps


def test_new_stream_rates_are_requested_from_the_autopilot_at_once():
    pipe = Pipeline()
    run(pipe, flight(3.0))  # the autopilot is known
    answer = set_param(pipe, "SR_GPS_RAW_INT", 4.0)
    requests = [
        m
        for m in answer
        if m.get_type() == "COMMAND_LONG"
        and m.command == mavlink.MAV_CMD_SET_MESSAGE_INTERVAL
        and m.param1 == mavlink.MAVLINK_MSG_ID_GPS_RAW_INT
    ]
    assert [m.param2 for m in requests] == [250_000.0]
    assert pipe.rates.rates_hz["GPS_RAW_INT"] == 4.0


def test_gps_input_follows_the_encoder_parameters_at_once():
    records = flight(20.0)
    pipe = Pipeline()
    run(pipe, records[:300])
    set_param(pipe, "ENC_GPS_ID", 1.0)
    set_param(pipe, "ENC_MIN_HACC", 7.0)
    out = [m for m in run(pipe, records[300:]) if m.get_type() == "GPS_INPUT"]
    assert out and all(m.gps_id == 1 and m.horiz_accuracy >= 7.0 for m in out)


def test_the_heartbeat_follows_its_new_rate_from_the_next_one():
    pipe = Pipeline()
    pipe.on_timer(0.0)
    assert pipe.next_due_s() == 1.0
    set_param(pipe, "LNK_HB_RATE", 5.0, t_rx_s=0.05)
    assert pipe.next_due_s() == pytest.approx(0.2)
    set_param(pipe, "LNK_HB_RATE", 0.5, t_rx_s=0.1)
    assert pipe.next_due_s() == pytest.approx(0.2)  # the one already due stays
    pipe.on_timer(0.2)
    assert pipe.next_due_s() == pytest.approx(2.2)


def test_the_approach_category_and_outage_keys_reach_the_running_estimators():
    pipe = Pipeline()
    run(pipe, flight(5.0))
    set_param(pipe, "INT_APPROACH_CAT", 3.0)
    set_param(pipe, "OUT_MAX_BRIDGE", 30.0)
    set_param(pipe, "HDG_AUTO_APPLY", 1.0)
    engine = pipe.engine
    assert int(engine.integrity.protection.config.approach_category) == 3
    assert engine.outage.config.max_bridge_s == 30.0
    assert engine.heading.config.auto_apply is True
    engine._reset()  # an autopilot reboot keeps them
    assert engine.outage.config.max_bridge_s == 30.0
    assert int(engine.integrity.protection.config.approach_category) == 3


def test_keys_built_into_a_running_component_are_refused_live():
    engine = Engine()
    with pytest.raises(ValueError, match="navigator"):
        engine.reconfigure("engine", dataclasses.replace(engine.config, navigator="singer"))
    with pytest.raises(ValueError, match="cannot be changed"):
        engine.reconfigure("blend", engine._blend_config)
    encoder = Encoder()
    with pytest.raises(ValueError, match="dialect"):
        encoder.reconfigure(EncoderConfig(dialect="common"))
    pipe = Pipeline()
    with pytest.raises(ValueError, match="baud"):
        pipe.reconfigure(
            dataclasses.replace(Config(), link=dataclasses.replace(Config().link, baud=57600))
        )
    assert pipe.config == Config()


def test_every_live_key_is_one_the_running_pipeline_applies():
    """Each parameter marked live goes through Pipeline.reconfigure (which refuses any
    other) and lands where the running component reads it."""
    for p in PARAMS:
        if not p.live:
            continue
        pipe = Pipeline()
        number, value = new_value(p, Config())
        set_param(pipe, p.name, number)
        assert get_value(pipe.config, p) == value, p.name
        holder: Any = {
            "engine": pipe.engine.config,
            "outage": pipe.engine.outage.config,
            "heading": pipe.engine.heading.config,
            "integrity": pipe.engine.integrity.protection.config,
            "encoder": pipe.encoder.config,
            "streams": pipe.config.streams,
            "link": pipe.config.link,
        }[p.block]
        assert getattr(holder, p.key) == value, p.name


def test_optional_hint_is_what_the_table_says():
    for p in PARAMS:
        obj: Any = Config()
        for part in p.block.split("."):
            obj = getattr(obj, part)
        hint = typing.get_type_hints(type(obj))[p.key]
        assert p.optional == (type(None) in typing.get_args(hint)), p.name


def test_publishing_on_fix_can_be_turned_off_and_on_live():
    records = flight(40.0)
    third = len(records) // 3
    pipe = Pipeline()

    def times(part: list[tuple[float, Any]]) -> list[float]:
        out = run(pipe, part)
        return [m.time_boot_ms / 1000.0 for m in out if m.get_type() == "GLOBAL_POSITION_INT"]

    on = times(records[:third])
    assert set_param(pipe, "ENG_PUB_ON_FIX", 0)[0].param_value == 0
    off = times(records[third : 2 * third])
    assert set_param(pipe, "ENG_PUB_ON_FIX", 1)[0].param_value == 1
    on_again = times(records[2 * third :])
    # on the tick: every publication on a tenth of a second; on fixes: not so
    assert all(abs(t * 10.0 - round(t * 10.0)) < 1e-6 for t in off[1:])
    for part in (on[5:], on_again[5:]):
        assert sum(abs(t * 10.0 - round(t * 10.0)) > 1e-6 for t in part) > len(part) // 2
    every = on + off + on_again
    gaps = [b - a for a, b in zip(every, every[1:], strict=False)]
    assert min(gaps) >= 0.08 - 1e-9 and max(gaps) <= 0.2 + 0.03
