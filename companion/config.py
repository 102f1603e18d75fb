"""Configuration: one frozen dataclass per block, loaded from TOML.

Each block's dataclass lives beside the code it configures (``EngineConfig`` in
``engine/config.py``, ``OutageConfig`` in ``nav/outage.py`` ...) with its
defaults, each field's range declared beside it (:mod:`companion.ranges`) and
the checks that relate fields in ``__post_init__`` (raising ``ValueError``).
This module holds the service's own blocks (``[link]``, ``[streams]``),
composes them all into :class:`Config` and loads TOML. An unknown block or key,
a value of the wrong type or a value the block rejects is a :class:`ConfigError`
whose one-line message names ``[block] key``.

``companion config-template`` prints every block with its keys, defaults and
documentation: the example ``companion/systemd/companion.toml`` is that output. An IMU
grade's preset (:mod:`companion.presets`) is a whole :class:`Config` that a file's keys
override (``base``) and that the template can print.
"""

from __future__ import annotations

import ast
import dataclasses
import inspect
import sys
import types
import typing
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

if sys.version_info >= (3, 11):
    import tomllib
else:  # Python 3.10 (JetPack 6): the same parser, from PyPI
    import tomli as tomllib

from companion.engine.config import EngineConfig
from companion.integrity.coast import CoastConfig
from companion.integrity.monitor import IntegrityConfig
from companion.integrity.spoof import SpoofConfig
from companion.mavlink.decode import DecoderConfig
from companion.mavlink.encode import EncoderConfig
from companion.mavlink.link import LinkError, parse_url
from companion.mavlink.signing import SigningConfig
from companion.nav.baro import BaroConfig
from companion.nav.blend import BlendConfig
from companion.nav.heading import HeadingConfig
from companion.nav.imu_innovations import ImuInnovationConfig
from companion.nav.outage import OutageConfig
from companion.nav.potential import PotentialConfig
from companion.ranges import check_ranges, ranged
from companion.raw.link import RawConfig
from companion.recorder import RecorderConfig


class ConfigError(ValueError):
    """A configuration file or value is wrong; the message names the key."""


@dataclass(frozen=True, slots=True)
class LinkConfig:
    """Where the autopilot and the ground station are, and how the service behaves on them."""

    master: str = "serial:/dev/ttyAMA0:921600"
    """Autopilot link: serial:DEVICE:BAUD, a device path, udpin:HOST:PORT, udpout:HOST:PORT,
    tcp:HOST:PORT (client) or tcpin:HOST:PORT (server)."""
    gcs: str = ""
    """Optional ground-station link (same URL forms); empty for none."""
    baud: int = ranged(921600, gt=0)
    """Serial baud rate when the URL does not give one."""
    heartbeat_rate_hz: float = ranged(1.0, ge=0.1, le=10.0)
    """Our HEARTBEAT rate."""
    reconnect_s: float = ranged(1.0, gt=0.0)
    """Wait before re-opening a link that dropped."""
    state_file: str = "/var/lib/companion/state.json"
    """Where the heading correction of the current flight is kept across a restart."""
    record_dir: str = "/var/lib/companion/logs"
    """Flight recorder folder (every message in and out, as .tlog; caps in [recorder]);
    empty to disable."""
    no_autopilot_warn_s: float = ranged(5.0, gt=0.0)
    """Warn when the autopilot link goes this long without an autopilot HEARTBEAT, with what
    it delivered (bytes, frames, bad frames): wrong baud rate, not MAVLink, wrong port?"""
    no_autopilot_repeat_s: float = ranged(30.0, gt=0.0)
    """... and again at this interval until one arrives."""

    def __post_init__(self) -> None:
        check_ranges(self)
        if not self.master:
            raise ValueError("master must name a link")
        # a malformed URL is fatal here, at load; a link that cannot open is retried
        for key in ("master", "gcs"):
            url = getattr(self, key)
            if url:
                try:
                    parse_url(url, self.baud)
                except LinkError as exc:
                    raise ValueError(f"{key}: {exc}") from None


@dataclass(frozen=True, slots=True)
class StreamsConfig:
    """Message rates the service asks the autopilot for (Hz); 0 leaves a stream alone."""

    gps_raw_int_hz: float = ranged(10.0, ge=0.0, le=1000.0)
    gps2_raw_hz: float = ranged(10.0, ge=0.0, le=1000.0)
    gps_rtk_hz: float = ranged(1.0, ge=0.0, le=1000.0)
    raw_imu_hz: float = ranged(50.0, ge=0.0, le=1000.0)
    scaled_imu2_hz: float = ranged(50.0, ge=0.0, le=1000.0)
    highres_imu_hz: float = ranged(50.0, ge=0.0, le=1000.0)
    attitude_hz: float = ranged(25.0, ge=0.0, le=1000.0)
    attitude_quaternion_hz: float = ranged(25.0, ge=0.0, le=1000.0)
    extended_sys_state_hz: float = ranged(2.0, ge=0.0, le=1000.0)
    vfr_hud_hz: float = ranged(2.0, ge=0.0, le=1000.0)
    global_position_int_hz: float = ranged(5.0, ge=0.0, le=1000.0)

    def __post_init__(self) -> None:
        check_ranges(self)

    def rates_hz(self) -> dict[str, float]:
        """Requested rates keyed by MAVLink message name (only those > 0)."""
        return {
            f.name.removesuffix("_hz").upper(): getattr(self, f.name)
            for f in dataclasses.fields(self)
            if getattr(self, f.name) > 0.0
        }


@dataclass(frozen=True, slots=True)
class Config:
    """The whole configuration."""

    link: LinkConfig = field(default_factory=LinkConfig)
    recorder: RecorderConfig = field(default_factory=RecorderConfig)
    streams: StreamsConfig = field(default_factory=StreamsConfig)
    engine: EngineConfig = field(default_factory=EngineConfig)
    outage: OutageConfig = field(default_factory=OutageConfig)
    heading: HeadingConfig = field(default_factory=HeadingConfig)
    blend: BlendConfig = field(default_factory=lambda: BlendConfig.for_grade("mems"))
    """The GNSS/INS blend; its noise defaults are a typical autopilot MEMS IMU's (for a
    tactical-grade IMU, the preset ``--grade tactical``: :mod:`companion.presets`)."""
    integrity: IntegrityConfig = field(default_factory=IntegrityConfig)
    potential: PotentialConfig = field(default_factory=PotentialConfig)
    coast: CoastConfig = field(default_factory=lambda: CoastConfig.for_grade("mems"))
    """The coasting inertial references (``engine.inertial_reference``): the IMU grade's
    figures; the preset ``--grade tactical`` has the tactical grade's."""
    baro: BaroConfig = field(default_factory=BaroConfig)
    """The barometer's height and its calibration against GNSS (:mod:`companion.nav.baro`)."""
    imu_innovations: ImuInnovationConfig = field(default_factory=ImuInnovationConfig)
    """The in-flight IMU grade check on the blend's GNSS innovations
    (``engine.imu_grade_check``; :mod:`companion.nav.imu_innovations`)."""
    decoder: DecoderConfig = field(default_factory=DecoderConfig)
    encoder: EncoderConfig = field(default_factory=EncoderConfig)
    signing: SigningConfig = field(default_factory=SigningConfig)
    """MAVLink 2 message signing per link ([signing.autopilot], [signing.gcs])."""
    raw: RawConfig = field(default_factory=RawConfig)
    """The raw receiver: carrier-phase positions checked by FIS-RAIM (docs/raw.md)."""
    spoof: SpoofConfig = field(default_factory=lambda: SpoofConfig.for_grade("mems"))
    """Receivers moving unlike the IMU (a spoofer that tracks the vehicle): the IMU
    grade's figures; the preset ``--grade tactical`` has the tactical grade's."""


def load_config(path: Path | None, base: Config | None = None) -> Config:
    """Read a TOML file (``None``: no keys). Raises ConfigError naming the key.

    The file's keys replace those of ``base`` (default: ``Config()``, all defaults; an IMU
    grade's preset from :func:`companion.presets.grade_config`).
    """
    if path is None:
        return Config() if base is None else base
    try:
        with open(path, "rb") as fh:
            data = tomllib.load(fh)
    except FileNotFoundError:
        raise ConfigError(f"config file not found: {path}") from None
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"{path}: not valid TOML: {exc}") from None
    except OSError as exc:
        raise ConfigError(f"{path}: cannot read: {exc.strerror}") from None
    return config_from_dict(data, base)


def config_from_dict(data: dict[str, Any], base: Config | None = None) -> Config:
    """Build a Config from parsed TOML: ``base`` (default ``Config()``) with the keys of
    ``data`` replaced. Raises ConfigError naming the key."""
    return merge_config(Config() if base is None else base, data)


def merge_config(config: Config, data: dict[str, Any]) -> Config:
    """``config`` with the keys of ``data`` (TOML-shaped: ``{block: {key: value}}``,
    sub-blocks as sub-tables) replaced, each block validated as a TOML file's is (the
    same coercion, ranges and checks). Raises ConfigError naming the key.

    ``None`` unsets an optional key (TOML has no null; the parameter protocol and its
    saved values have)."""
    blocks: dict[str, Any] = {}
    known_blocks = [f.name for f in dataclasses.fields(Config)]
    for block, table in data.items():
        if block not in known_blocks:
            raise ConfigError(f"unknown block [{block}] (known: {', '.join(known_blocks)})")
        if not isinstance(table, dict):
            raise ConfigError(f"[{block}] must be a table")
        blocks[block] = _build_block(block, getattr(config, block), table)
    return dataclasses.replace(config, **blocks)


def _build_block(block: str, default: Any, table: dict[str, Any]) -> Any:
    """The block's default with the keys of ``table`` replaced (validated)."""
    cls = type(default)
    hints = typing.get_type_hints(cls)
    known = {f.name for f in dataclasses.fields(cls)}
    kwargs: dict[str, Any] = {}
    for key, value in table.items():
        if key not in known:
            raise ConfigError(f"[{block}] unknown key '{key}' (known: {', '.join(sorted(known))})")
        current = getattr(default, key)
        if dataclasses.is_dataclass(current):  # a nested block: a TOML sub-table
            if not isinstance(value, dict):
                raise ConfigError(f"[{block}.{key}] must be a table")
            kwargs[key] = _build_block(f"{block}.{key}", current, value)
        else:
            kwargs[key] = _coerce(block, key, hints[key], value)
    try:
        return dataclasses.replace(default, **kwargs)
    except (ValueError, TypeError) as exc:
        raise ConfigError(f"[{block}] {exc}") from None


def _coerce(block: str, key: str, hint: Any, value: Any) -> Any:
    """Check a TOML value against a field's type hint (ints accepted for floats,
    lists for tuples)."""
    where = f"[{block}] {key}"
    origin = typing.get_origin(hint)
    args = typing.get_args(hint)
    if origin in (typing.Union, types.UnionType):
        if value is None and type(None) in args:
            return None
        errors = []
        for arm in args:
            if arm is type(None):
                continue
            try:
                return _coerce(block, key, arm, value)
            except ConfigError as exc:
                errors.append(str(exc))
        raise ConfigError(errors[0] if errors else f"{where}: bad value {value!r}")
    if hint is bool:
        if not isinstance(value, bool):
            raise ConfigError(f"{where} must be true or false, not {value!r}")
        return value
    if hint is float:
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise ConfigError(f"{where} must be a number, not {value!r}")
        return float(value)
    if hint is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise ConfigError(f"{where} must be an integer, not {value!r}")
        return value
    if hint is str:
        if not isinstance(value, str):
            raise ConfigError(f"{where} must be a string, not {value!r}")
        return value
    if origin is tuple:
        if not isinstance(value, list):
            raise ConfigError(f"{where} must be a list, not {value!r}")
        item = args[0] if args else Any
        return (
            tuple(_coerce(block, key, item, v) for v in value) if item is not Any else tuple(value)
        )
    if inspect.isclass(hint) and issubclass(hint, str | int) and hasattr(hint, "__members__"):
        try:
            return hint(value)
        except ValueError:
            raise ConfigError(
                f"{where}: {value!r} is not one of {list(hint.__members__)}"
            ) from None
    return value


def template(values: Config | None = None, about: str = "every key, with its default") -> str:
    """Every block and key with its value in ``values`` (default: ``Config()``, the
    defaults) and its documentation, as TOML; ``about`` completes the first line."""
    lines = [f"# companion configuration: {about}.", ""]
    defaults = Config() if values is None else values
    for block in dataclasses.fields(Config):
        lines += _template_block(block.name, getattr(defaults, block.name))
    return "\n".join(lines)


def _template_block(name: str, default: Any) -> list[str]:
    cls = type(default)
    docs = _attribute_docs(cls)
    summary = (cls.__doc__ or "").strip().splitlines()
    lines = [f"# {summary[0]}"] if summary else []
    lines.append(f"[{name}]")
    nested: list[tuple[str, Any]] = []
    for f in dataclasses.fields(cls):
        value = getattr(default, f.name)
        if dataclasses.is_dataclass(value):
            nested.append((f.name, value))
            continue
        for doc_line in docs.get(f.name, "").splitlines():
            lines.append(f"# {doc_line.strip()}")
        if value is None:  # TOML has no null: an unset optional key stays commented
            lines.append(f"# {f.name} = (unset)")
        else:
            lines.append(f"{f.name} = {_toml_value(value)}")
    lines.append("")
    for sub_name, sub_default in nested:
        lines += _template_block(f"{name}.{sub_name}", sub_default)
    return lines


def _toml_value(value: Any) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, str):
        return '"' + value.replace("\\", "\\\\").replace('"', '\\"') + '"'
    if hasattr(value, "value") and hasattr(type(value), "__members__"):
        return _toml_value(value.value)
    if isinstance(value, tuple | list):
        return "[" + ", ".join(_toml_value(v) for v in value) + "]"
    if isinstance(value, float) and value in (float("inf"), float("-inf")):
        return "inf" if value > 0 else "-inf"
    return repr(value)


def _numpydoc_attributes(doc: str) -> dict[str, str]:
    """The ``Attributes`` section of a numpydoc class docstring, by attribute name
    (``a, b : float`` documents both)."""
    lines = inspect.cleandoc(doc).splitlines()
    docs: dict[str, str] = {}
    try:
        start = next(
            i + 2
            for i, line in enumerate(lines[:-1])
            if line.strip() == "Attributes" and set(lines[i + 1].strip()) == {"-"}
        )
    except StopIteration:
        return docs
    names: list[str] = []
    for line in lines[start:]:
        if line and not line.startswith(" "):
            if " : " not in line:
                break  # the next section's title
            names = [n.strip() for n in line.split(" : ")[0].split(",")]
            continue
        for name in names:
            docs[name] = (docs.get(name, "") + "\n" + line.strip()).strip()
    return docs


def _attribute_docs(cls: type) -> dict[str, str]:
    """Attribute docstrings (the string literal under each field) of a dataclass."""
    try:
        source = inspect.getsource(cls)
    except (OSError, TypeError):
        return {}
    tree = ast.parse(inspect.cleandoc("\n" + source) if source.startswith(" ") else source)
    docs = _numpydoc_attributes(cls.__doc__ or "")
    body = tree.body[0].body if tree.body and isinstance(tree.body[0], ast.ClassDef) else []
    for prev, node in zip(body, body[1:], strict=False):
        if (
            isinstance(prev, ast.AnnAssign)
            and isinstance(prev.target, ast.Name)
            and isinstance(node, ast.Expr)
            and isinstance(node.value, ast.Constant)
            and isinstance(node.value.value, str)
        ):
            docs[prev.target.id] = inspect.cleandoc(node.value.value)
    return docs
