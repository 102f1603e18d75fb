"""The pymavlink dialect module a MAVLink endpoint builds, packs and checks messages with."""

from __future__ import annotations

import importlib
from types import ModuleType


def load_dialect(dialect: str) -> ModuleType:
    """Import ``pymavlink.dialects.v20.<dialect>``.

    Raises
    ------
    ValueError
        If the dialect is not one pymavlink ships.
    """
    if not dialect.isidentifier():
        raise ValueError(f"invalid MAVLink dialect name {dialect!r}")
    try:
        return importlib.import_module(f"pymavlink.dialects.v20.{dialect}")
    except ImportError as exc:
        raise ValueError(f"unknown MAVLink dialect {dialect!r}") from exc
