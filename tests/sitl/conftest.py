"""The ``sitl`` tests run real autopilot simulators (ArduPilot SITL, PX4 SIH) inside a
private network namespace; they skip, with the reason, where the simulators are absent
(see :mod:`tests.sitl.locate`)."""

from __future__ import annotations

import pytest


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    for item in items:
        if "tests/sitl/" in item.nodeid.replace("\\", "/"):
            item.add_marker(pytest.mark.sitl)
