"""The configuration as MAVLink parameters: the table of names, and the parameter server.

Every key of the configuration that a number can carry is a parameter of component
191 under a name of at most 16 characters: the block's prefix and an abbreviation
of the key (:data:`PREFIXES`, :data:`TABLE`), one parameter per item of a
fixed-length list (``BLD_LEVER_X``). The table is written out, never derived, so a
name stays what it is when keys are added; a parameter's index is its place in the
table. docs/params.md lists it (:func:`markdown_table` writes that list).

Types (:mod:`companion.mavlink.params` carries them on the wire): numbers REAL32,
integers INT32, booleans UINT8 (0 or 1); a key with a fixed set of words (``navigator
= "blend"``) is an INT32 index into its words, pinned in :data:`CHOICES`; an optional
key whose range excludes 0 reads 0 when unset and is unset by 0. Keys no number can
carry cleanly are not parameters (:data:`NOT_EXPOSED` says why, key by key).

A value set is validated exactly as the TOML file's (:func:`companion.config.merge_config`:
the same coercion, ranges and checks between keys); a refused one leaves everything
as it was. What a change does, per key (:data:`LIVE_KEYS`): applied to the running
service at once (the component that reads the key states it can), or kept and
applied when the service restarts. The values set are what the service persists
(``params.json`` beside ``link.state_file``) and loads over the TOML configuration
at start (:func:`load_overrides`).

:class:`ParamServer` answers the protocol's requests (already decoded and addressed
to us) with the messages to send: PARAM_VALUE, and a one-line STATUSTEXT ``CMP PARAM
<NAME> <why>`` when a value is refused, unknown, or waits for a restart.
"""

from __future__ import annotations

import dataclasses
import enum
import logging
import math
import re
import types
import typing
from dataclasses import dataclass
from typing import Any

from companion.config import Config, ConfigError, merge_config
from companion.engine import LIVE_KEYS as ENGINE_LIVE_KEYS
from companion.mavlink.encode import LIVE_KEYS as ENCODER_LIVE_KEYS
from companion.mavlink.params import (
    INT32_MAX,
    INT32_MIN,
    MAV_PARAM_TYPE_INT32,
    MAV_PARAM_TYPE_REAL32,
    MAV_PARAM_TYPE_UINT8,
    PARAM_ID_MAX_CHARS,
    ParamCodec,
    ParamList,
    ParamRead,
    ParamRequest,
    ParamSet,
    is_integral,
    printable_name,
    real32,
)
from companion.params_table import TABLE
from companion.ranges import field_range
from companion.types import Severity

log = logging.getLogger(__name__)

PREFIXES: dict[str, str] = {
    "link": "LNK",
    "recorder": "REC",
    "streams": "SR",
    "engine": "ENG",
    "outage": "OUT",
    "heading": "HDG",
    "blend": "BLD",
    "integrity": "INT",
    "integrity.phase": "PHS",
    "spoof": "SPF",
    "potential": "POT",
    "coast": "CST",
    "baro": "BAR",
    "imu_innovations": "IMU",
    "decoder": "DEC",
    "encoder": "ENC",
    "raw": "RAW",
}
"""Configuration block -> the prefix of its parameters' names."""


CHOICES: dict[str, tuple[str, ...]] = {
    "engine.navigator": ("blend", "singer", "passthrough"),
    "heading.track_source": ("auto", "velocity", "position"),
    "blend.mode": ("attitude_aided", "strapdown"),
    "blend.gnss_error_model": ("gauss_markov", "white"),
    "blend.cov_discretisation": ("second_order", "van_loan"),
    "potential.velocity_mode": ("measured", "carried"),
    "encoder.output": ("auto", "gps_input", "global_position_sensor"),
    "raw.receiver_port": ("UART1", "UART2", "USB", "SPI", "I2C"),
    "raw.bands": ("all", "l1"),
    "engine.gap_attitude": ("auto", "autopilot", "rates"),
}
"""Keys holding one of a fixed set of words: the parameter is the word's index here
(pinned: a new word is appended)."""

_SIGNING_WHY = "signing is set on the companion computer, never over the links it protects"

NOT_EXPOSED: dict[str, str] = {
    "link.master": "a link URL (text)",
    "link.gcs": "a link URL (text)",
    "link.state_file": "a file path (text); not to be changed over the air",
    "link.record_dir": "a folder path (text); not to be changed over the air",
    "decoder.own_component": "our own component id: the address of this very protocol",
    "encoder.dialect": "a pymavlink module name (text)",
    "encoder.statustext_interval_overrides": "a list of (alert code, interval) pairs",
    "integrity.phase.field_elevation_msl_m": (
        "optional, and every number (0 m too) is an elevation: no number means unset"
    ),
    "potential.velocity_weights": "a list of any length",
    "potential.velocity_fit_orders": "a list of any length",
    "potential.fit_horizons_s": "a list of any length",
    "signing.autopilot.mode": _SIGNING_WHY,
    "signing.autopilot.key_file": _SIGNING_WHY,
    "signing.autopilot.passphrase": _SIGNING_WHY,
    "signing.autopilot.link_id": _SIGNING_WHY,
    "signing.gcs.mode": _SIGNING_WHY,
    "signing.gcs.key_file": _SIGNING_WHY,
    "signing.gcs.passphrase": _SIGNING_WHY,
    "signing.gcs.link_id": _SIGNING_WHY,
    "raw.device": "a device path (text)",
    "raw.file": "a file path (text); a recording for tests",
}
"""Configuration keys that are not parameters, and why: set them in the TOML file."""

LIVE_KEYS: dict[str, frozenset[str]] = {
    **ENGINE_LIVE_KEYS,
    "encoder": ENCODER_LIVE_KEYS,
    "streams": frozenset(f.name for f in dataclasses.fields(Config().streams)),
    "link": frozenset({"heartbeat_rate_hz"}),
}
"""Keys a running service takes at once, by block. The engine's and the encoder's own
declarations, and the pipeline's: new stream rates are requested from the autopilot at
once, the heartbeat follows its new rate. Every other parameter takes effect when the
service restarts."""

LIST_BURST = 10
"""PARAM_VALUEs sent at once while answering a list request ..."""
LIST_PERIOD_S = 0.1
"""... and the period of the bursts (100 parameters/s: about 4 kB/s on the link, so that
an autopilot routing them to a radio link does not drop them)."""

_PATH = re.compile(r"^([a-z_.]+)\.([a-z0-9_]+)(?:\[(\d)\])?$")


@dataclass(frozen=True, slots=True)
class Param:
    """One parameter: its name, the configuration key it carries, its type."""

    index: int
    name: str
    block: str
    """The configuration block (``integrity.phase`` for a sub-block)."""
    key: str
    item: int | None
    """The item of a fixed-length list, else None."""
    kind: str
    """``float``, ``int``, ``bool`` or ``choice``."""
    choices: tuple[Any, ...] = ()
    """``choice``: the words in index order; an integer enumeration: its members."""
    optional: bool = False
    """Unset (None) is allowed: it reads 0 and 0 sets it."""
    live: bool = False
    """Applied to the running service at once (else at the next start)."""

    @property
    def path(self) -> str:
        """The configuration key as written in this table (``blend.lever_arm_b_m[0]``)."""
        return f"{self.block}.{self.key}" + ("" if self.item is None else f"[{self.item}]")

    @property
    def param_type(self) -> int:
        """MAV_PARAM_TYPE on the wire."""
        if self.kind == "float":
            return MAV_PARAM_TYPE_REAL32
        if self.kind == "bool":
            return MAV_PARAM_TYPE_UINT8
        return MAV_PARAM_TYPE_INT32


class ParamError(ValueError):
    """A value a parameter cannot take; the message is the reason, one line."""


def _block_of(config: Config, block: str) -> Any:
    obj: Any = config
    for part in block.split("."):
        obj = getattr(obj, part)
    return obj


def _build(index: int, name: str, path: str) -> Param:
    m = _PATH.match(path)
    if m is None:
        raise ValueError(f"{name}: bad configuration key {path!r}")
    block, key, item = m.group(1), m.group(2), m.group(3)
    default = _block_of(Config(), block)
    hints = typing.get_type_hints(type(default))
    hint = hints[key]
    optional = False
    if typing.get_origin(hint) in (typing.Union, types.UnionType):
        arms = [a for a in typing.get_args(hint) if a is not type(None)]
        optional = len(arms) == 1 and len(typing.get_args(hint)) == 2
        hint = arms[0]
    if item is not None:
        hint = typing.get_args(hint)[int(item)]
    choices: tuple[Any, ...] = ()
    if f"{block}.{key}" in CHOICES:
        kind, choices = "choice", CHOICES[f"{block}.{key}"]
    elif hint is bool:
        kind = "bool"
    elif hint is float:
        kind = "float"
    elif hint is int:
        kind = "int"
    elif isinstance(hint, type) and issubclass(hint, enum.IntEnum):
        kind, choices = "int", tuple(hint)
    else:
        raise ValueError(f"{name}: {path} ({hint}) cannot be a parameter")
    return Param(
        index=index,
        name=name,
        block=block,
        key=key,
        item=None if item is None else int(item),
        kind=kind,
        choices=choices,
        optional=optional,
        live=key in LIVE_KEYS.get(block, frozenset()),
    )


PARAMS: tuple[Param, ...] = tuple(_build(i, name, path) for i, (name, path) in enumerate(TABLE))
"""Every parameter, in index order."""
BY_NAME: dict[str, Param] = {p.name: p for p in PARAMS}


# --------------------------------------------------------------------------- values


def get_value(config: Config, p: Param) -> Any:
    """The configuration's value of ``p`` (the item, for a list's item)."""
    value = getattr(_block_of(config, p.block), p.key)
    return value if p.item is None else value[p.item]


def wire_of(p: Param, value: Any) -> float | int | bool:
    """The number ``p`` carries for the configuration value ``value``."""
    if value is None:
        return 0
    if p.kind == "choice":
        return p.choices.index(value)
    if p.kind == "bool":
        return bool(value)
    if p.kind == "int":
        return int(value)
    return float(value)


def value_of(p: Param, number: float) -> Any:
    """The configuration value the number ``number`` (from the wire) sets ``p`` to.

    Raises
    ------
    ParamError
        ``number`` is no value of the parameter's type (NaN; not an integer; a
        boolean other than 0 or 1; an index past the words).
    """
    if math.isnan(number):
        raise ParamError("must be a number")
    if p.optional and number == 0.0:
        return None
    if p.kind == "float":
        return real32(number)
    if not is_integral(number):
        raise ParamError("must be an integer")
    n = int(number)
    if p.kind == "bool":
        if n not in (0, 1):
            raise ParamError("must be 0 or 1")
        return bool(n)
    if p.kind == "choice":
        if not 0 <= n < len(p.choices):
            raise ParamError(f"must be 0..{len(p.choices) - 1}")
        return p.choices[n]
    if not INT32_MIN <= n <= INT32_MAX:
        raise ParamError("out of the INT32 range")
    return n


def with_value(config: Config, p: Param, value: Any) -> Config:
    """``config`` with ``p`` set to ``value``, validated as the TOML file's values are.

    Raises
    ------
    ConfigError
        The configuration refuses the value (range, type, a check between keys).
    """
    if p.item is not None:
        items = list(getattr(_block_of(config, p.block), p.key))
        items[p.item] = value
        value = items
    if isinstance(value, enum.Enum):
        value = value.value
    table: dict[str, Any] = {p.key: value}
    for part in reversed(p.block.split(".")[1:]):
        table = {part: table}
    return merge_config(config, {p.block.split(".")[0]: table})


def _same(p: Param, a: Any, b: Any) -> bool:
    """Equal as the wire carries them (a REAL32 cannot tell 0.1 from 0.1 + 1e-12)."""
    if p.kind == "float" and a is not None and b is not None:
        return real32(a) == real32(b)
    return bool(a == b)


def reason(p: Param, error: ConfigError) -> str:
    """The configuration's refusal in the parameters' words: ``must be in (0, 50]``, with
    the keys of the block spelled as their parameters' names."""
    text = re.sub(r"^\[[^\]]*\]\s*", "", str(error))
    text = re.sub(r",? got .*$", "", text)
    names = {q.key: q.name for q in PARAMS if q.block == p.block and q.item is None}
    names[p.key] = p.name
    text = re.sub(r"\b[a-z][a-z0-9_]*\b", lambda m: names.get(m.group(0), m.group(0)), text)
    text = text.removeprefix(p.name).lstrip(" :")
    return text


# --------------------------------------------------------------------------- persistence


def load_overrides(config: Config, saved: Any) -> tuple[Config, dict[str, Any], list[str]]:
    """``config`` with the values saved by :class:`ParamServer` (the content of
    ``params.json``: ``{"version": 1, "params": {NAME: value}}``) applied in the order
    they were set, each validated as a PARAM_SET is.

    Returns the configuration, the values applied (to be kept persisted) and one line
    per value dropped (unknown name, a value the configuration now refuses).
    """
    problems: list[str] = []
    applied: dict[str, Any] = {}
    params = saved.get("params") if isinstance(saved, dict) else None
    if not isinstance(params, dict):
        return config, applied, ["no 'params' table"]
    for name, value in params.items():
        p = BY_NAME.get(name)
        if p is None:
            problems.append(f"{name}: no such parameter")
            continue
        if p.kind == "choice" and value not in p.choices:
            problems.append(f"{name}: {value!r} is not one of {list(p.choices)}")
            continue
        if p.kind != "choice" and not (value is None or isinstance(value, bool | int | float)):
            problems.append(f"{name}: {value!r} is not a number")
            continue
        try:
            config = with_value(config, p, value)
        except ConfigError as exc:
            problems.append(f"{name}: {reason(p, exc)}")
            continue
        applied[name] = get_value(config, p)
    return config, applied, problems


def saved_form(overrides: dict[str, Any]) -> dict[str, Any]:
    """What :class:`ParamServer`'s values set look like in ``params.json``."""
    return {
        "version": 1,
        "params": {k: (v.value if isinstance(v, enum.Enum) else v) for k, v in overrides.items()},
    }


# --------------------------------------------------------------------------- the server


@dataclass(slots=True)
class Answer:
    """What a request gives: messages to send, the running configuration to adopt (a
    live parameter set), and the rejection reason to count (None: accepted)."""

    messages: list[Any]
    config: Config | None = None
    rejection: str | None = None


class ParamServer:
    """The parameter protocol of component 191 (see the module docstring).

    ``config`` is the configuration the parameters read: the running one plus the
    values set that wait for a restart. ``overrides`` holds every value set over
    MAVLink, in the order set (what the driver persists); ``changes`` counts its
    changes (the driver saves when it moves).
    """

    def __init__(self, config: Config, dialect: str) -> None:
        self.config = config
        self.overrides: dict[str, Any] = {}
        self.changes = 0
        self._codec = ParamCodec(dialect)
        self._list_next: int | None = None
        self._list_due_s = math.inf

    # ------------------------------------------------------------------ requests

    def handle(self, request: ParamRequest, running: Config, t_rx_s: float) -> Answer:
        """The answer to one request addressed to us; ``running`` is the configuration the
        service runs with, ``t_rx_s`` the driver's clock (paces a list)."""
        if isinstance(request, ParamList):
            self._list_next = 0
            self._list_due_s = t_rx_s
            return Answer(self.on_timer(t_rx_s))
        if isinstance(request, ParamRead):
            if request.index >= 0:
                p = PARAMS[request.index] if request.index < len(PARAMS) else None
            else:
                p = BY_NAME.get(request.name)
            if p is None:
                return Answer([], rejection="unknown_param")
            return Answer([self._value(p)])
        if isinstance(request, ParamSet):
            return self._set(request, running)
        return Answer([], rejection="unhandled_type")

    def next_due_s(self) -> float:
        """When :meth:`on_timer` next has PARAM_VALUEs to send (inf: nothing pending)."""
        return self._list_due_s

    def on_timer(self, t_rx_s: float) -> list[Any]:
        """The next burst of a list being answered, when due."""
        start = self._list_next
        if start is None or t_rx_s < self._list_due_s:
            return []
        stop = min(start + LIST_BURST, len(PARAMS))
        if stop >= len(PARAMS):
            self._list_next, self._list_due_s = None, math.inf
        else:
            self._list_next, self._list_due_s = stop, t_rx_s + LIST_PERIOD_S
        return [self._value(p) for p in PARAMS[start:stop]]

    # ------------------------------------------------------------------ internals

    def _value(self, p: Param) -> Any:
        number = wire_of(p, get_value(self.config, p))
        return self._codec.param_value(p.name, number, p.param_type, len(PARAMS), p.index)

    def _text(self, severity: Severity, p_name: str, why: str) -> Any:
        return self._codec.statustext(int(severity), f"CMP PARAM {p_name} {why}")

    def _refuse(self, p: Param, number: float, why: str) -> Answer:
        log.warning("PARAM_SET %s = %r refused: %s", p.name, number, why)
        return Answer(
            [self._value(p), self._text(Severity.WARNING, p.name, why)],
            rejection="param_refused",
        )

    def _set(self, request: ParamSet, running: Config) -> Answer:
        p = BY_NAME.get(request.name)
        if p is None:
            name = printable_name(request.name)
            log.warning("PARAM_SET of unknown parameter %s", name)
            return Answer(
                [self._text(Severity.WARNING, name, "unknown")], rejection="unknown_param"
            )
        try:
            value = value_of(p, request.value)
        except ParamError as exc:
            return self._refuse(p, request.value, str(exc))
        if _same(p, value, get_value(self.config, p)):
            return Answer([self._value(p)])  # nothing changes (a ground station writing all)
        try:
            stored = with_value(self.config, p, value)
        except ConfigError as exc:
            return self._refuse(p, request.value, reason(p, exc))
        self.config = stored
        self.overrides.pop(p.name, None)
        self.overrides[p.name] = get_value(stored, p)
        self.changes += 1
        log.info("parameter %s set to %r (%s)", p.name, value, p.path)
        answer = Answer([self._value(p)])
        if p.live:
            try:
                answer.config = with_value(running, p, value)
                return answer
            except ConfigError as exc:  # another value waiting for the restart decides
                log.info("%s: not applicable before the restart (%s)", p.name, exc)
        if not _same(p, value, get_value(running, p)):
            answer.messages.append(self._text(Severity.NOTICE, p.name, "applies after restart"))
        return answer


# --------------------------------------------------------------------------- documentation


def _values_doc(p: Param, default: Any) -> str:
    block = _block_of(default, p.block)
    field = next(f for f in dataclasses.fields(block) if f.name == p.key)
    if p.kind == "choice":
        return ", ".join(f"{i} {c}" for i, c in enumerate(p.choices))
    if p.kind == "bool":
        return "0 false, 1 true"
    parts = []
    if p.choices:  # an integer enumeration
        parts.append(", ".join(f"{int(c)} {c.name}" for c in p.choices))
    rng = field_range(field)
    if rng is not None and rng.choices is not None:
        parts.append(", ".join(str(c) for c in rng.choices))
    elif rng is not None and rng.describe() not in ("finite", "a number"):
        parts.append(rng.describe())
    if p.optional:
        parts.append("0 unset")
    return "; ".join(parts)


def markdown_table() -> str:
    """The table of docs/params.md: every parameter, its key, type, values and default
    (the built-in one, before any TOML file) and when a change takes effect."""
    default = Config()
    type_names = {
        MAV_PARAM_TYPE_REAL32: "REAL32",
        MAV_PARAM_TYPE_INT32: "INT32",
        MAV_PARAM_TYPE_UINT8: "UINT8",
    }
    lines = [
        "| index | name | configuration key | type | values | default | applies |",
        "|---|---|---|---|---|---|---|",
    ]
    for p in PARAMS:
        number = wire_of(p, get_value(default, p))
        shown = f"{real32(number):g}" if p.kind == "float" else str(int(number))
        lines.append(
            f"| {p.index} | `{p.name}` | `{p.path}` | {type_names[p.param_type]} | "
            f"{_values_doc(p, default)} | {shown} | {'live' if p.live else 'restart'} |"
        )
    return "\n".join(lines) + "\n"


def _check_table() -> None:
    """The table's own rules (import fails on a broken table; the tests say more)."""
    names = [name for name, _ in TABLE]
    if len(set(names)) != len(names):
        raise ValueError("duplicate parameter names")
    for name in names:
        if len(name) > PARAM_ID_MAX_CHARS or not re.fullmatch(r"[A-Z][A-Z0-9_]*", name):
            raise ValueError(f"bad parameter name {name!r}")
        if name.split("_", 1)[0] not in PREFIXES.values():
            raise ValueError(f"{name}: not a block prefix")


_check_table()
