"""``Backend.set_tcp`` on the backends without a controller of their own (issue 17's ``set_tcp``
service: "mock/servo keep it"): the mock and the servo arm keep the TCP offset and refuse what is not
six finite numbers, changing nothing then. (The `ur` backend's is tested on the fake:
tests/ur/test_set_tcp_fake.py.)"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import pytest

from urdaemon.backends import MockBackend, ServoBackend
from urdaemon.backends.base import Backend
from urdaemon.cell import load_cell
from urdaemon.errors import BackendError

SERVO = Path(__file__).resolve().parents[2] / "configs" / "servo_arm.yaml"
TCP = (0.01, 0.0, 0.15, 0.0, math.pi / 2, 0.0)


def _mock() -> MockBackend:
    return MockBackend("a", ("a_j1", "a_j2", "a_j3"), 500.0)


def _servo() -> ServoBackend:
    robot = load_cell(SERVO).robots[0]
    assert robot.servo is not None
    names = tuple(f"{robot.prefix}{j.name}" for j in robot.servo.joints)
    return ServoBackend(robot.name, names, robot.prefix, robot.servo, publish=lambda _: None)


BACKENDS = pytest.mark.parametrize("make", [_mock, _servo], ids=["mock", "servo"])


@BACKENDS
async def test_set_tcp_keeps_the_offset(make: Any) -> None:
    """Reproduction: ``set_tcp`` did not exist on any backend (AttributeError); the service had nothing
    to call. The backend starts with no offset and keeps the one it is given, as floats."""
    backend: Backend = make()
    assert backend.tcp == (0.0,) * 6
    await backend.set_tcp(list(TCP))
    assert backend.tcp == TCP
    await backend.set_tcp((0, 0, 0, 0, 0, 0))
    assert backend.tcp == (0.0,) * 6
    assert all(type(v) is float for v in backend.tcp)


@BACKENDS
@pytest.mark.parametrize(
    "pose",
    [(0.0, 0.0, 0.1), (0.0,) * 7, (0.0, 0.0, math.inf, 0.0, 0.0, 0.0), (math.nan,) * 6, ("a",) * 6],
    ids=["three", "seven", "inf", "nan", "text"],
)
async def test_set_tcp_refuses_what_is_not_six_finite_numbers(make: Any, pose: Any) -> None:
    """Reproduction: as above; now a malformed offset is a one-line BackendError and the kept offset
    stays."""
    backend: Backend = make()
    await backend.set_tcp(TCP)
    with pytest.raises(BackendError, match=r"six finite numbers \[x, y, z, rx, ry, rz\]"):
        await backend.set_tcp(pose)
    assert backend.tcp == TCP
