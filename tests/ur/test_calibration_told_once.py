"""A calibration mismatch is logged once per robot hash, not again on every reconnection.

On a busy PC the RTDE link may drop and the backend reconnects; each connection checks the robot's
kinematics hash again. The same mismatch found again is already known: one WARNING until the robot
reports another hash. The ``calibration_mismatch`` event goes out on every connection (events are not
kept, so a client that subscribed late hears it on the next one).
"""

from __future__ import annotations

import logging
from typing import Any

import pytest

from urdaemon.backends.ur.robot_messages import RobotMessages


class _Kinematics:
    def __init__(self, digest: str) -> None:
        self.digest = digest

    def kinematics_hash(self) -> str:
        return self.digest


class _Primary:
    """A primary link that reports the kinematics hashes it is given, one per connection."""

    def __init__(self, *digests: str) -> None:
        self.digests = list(digests)

    async def wait_kinematics(self, timeout: float) -> _Kinematics:
        return _Kinematics(self.digests.pop(0))


async def test_the_same_mismatch_found_on_reconnection_is_told_once(caplog: pytest.LogCaptureFixture) -> None:
    notices: list[tuple[str, str]] = []
    messages = RobotMessages("alice", lambda kind, text: notices.append((kind, text)), program=Any)  # type: ignore[arg-type]
    primary: Any = _Primary("calib_1", "calib_1", "calib_1", "calib_2", "calib_9", "calib_2")
    with caplog.at_level(logging.WARNING, logger="urdaemon.ur"):
        for _ in range(6):
            await messages.check_calibration(primary, "calib_9", "warning")
            if not primary.digests:
                break
    told = [r.getMessage() for r in caplog.records if "kinematics hash" in r.getMessage()]
    assert [text.split()[6].rstrip(",") for text in told] == ["calib_1", "calib_2", "calib_2"], told
    assert [kind for kind, _ in notices] == ["calibration_mismatch"] * 5
    assert messages.calibration_ok is False
