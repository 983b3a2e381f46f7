"""The joint torques a controller reports: RTDE's ``target_moment`` and ``actual_current_as_torque`` and
the real-time interface's target moments are the fake arm's dynamics (docs/fake-robot.md, "Dynamics"),
checked against the independent Newton–Euler of tests/description/test_dynamics.py, at rest (the
gravity torques) and under ``direct_torque``, with our own RTDE codec and with ur_rtde.

Reproduction on the code before: all three were zeros (the report table did not list them).
"""

from __future__ import annotations

import asyncio
from collections.abc import Sequence
from typing import Any

import pytest

from tests.description.test_dynamics import Reference
from tests.fakeur.judges import fake_robot, send_script, wait_until
from tests.fakeur.test_controller import fake
from tests.helpers import rtde_sample
from urdaemon.fakeur.fake_arm import joint_torques
from urdaemon.fakeur.reports import realtime_state

pytestmark = pytest.mark.timeout(120)

MODEL = "ur10e"
VERSION = (5, 26, 0, 0)
"""``actual_current_as_torque`` needs 5.23 (UR's release notes), ``direct_torque`` 5.26's friction
arguments are not used here."""
GRAVITY = (0.0, 0.0, 9.82)
NAMES = ("actual_q", "actual_qd", "target_qdd", "target_moment", "actual_current_as_torque")
TORQUE = (0.5, 0.0, 0.0, 0.0, 0.0, 0.0)
"""N·m on the base on top of the gravity compensation: it turns slowly (far from its speed limit, which
would clamp the motion), the arm stays up."""


def _newton_euler(q: Sequence[float], qd: Sequence[float], qdd: Sequence[float]) -> list[float]:
    return [float(v) for v in Reference(MODEL).rnea(q, qd, qdd, GRAVITY)]


def _off(actual: Sequence[float], expected: Sequence[float]) -> float:
    return max(abs(a - b) for a, b in zip(actual, expected, strict=True))


async def test_at_rest_the_reported_torques_are_the_gravity_torques() -> None:
    async with fake(powered=True, controller_version=VERSION) as controller:
        sample: dict[str, Any] = await rtde_sample(controller.address, NAMES)
        hold = _newton_euler(sample["actual_q"], [0.0] * 6, [0.0] * 6)
        assert max(abs(v) for v in hold) > 10.0, "the shoulder and elbow hold the arm up"
        assert _off(sample["target_moment"], hold) < 1e-9, (sample["target_moment"], hold)
        assert sample["actual_current_as_torque"] == sample["target_moment"]
        moments = realtime_state(controller.arm).m_target
        assert _off(moments, hold) < 1e-9, (moments, hold)


async def test_under_direct_torque_the_reports_are_the_torques_that_move_the_arm() -> None:
    async with fake(powered=True, controller_version=VERSION) as controller:
        arm = controller.arm
        await controller.until(lambda: arm.robot_mode.name == "RUNNING")
        script = (
            "def torque():\n  i = 0\n  while i < 5000:\n"
            f"    direct_torque({list(TORQUE)}, friction_comp=False)\n    i = i + 1\n  end\nend\n"
        )
        await asyncio.to_thread(send_script, controller.address, 30002, script)
        await controller.until(lambda: arm.qd[0] > 0.005)
        sample: dict[str, Any] = await rtde_sample(controller.address, NAMES)
        q, qd, qdd = sample["actual_q"], sample["actual_qd"], sample["target_qdd"]
        assert qd[0] > 0.005, "the base turns"
        expected = _newton_euler(q, qd, qdd)
        assert _off(sample["target_moment"], expected) < 1e-9, (sample["target_moment"], expected)
        assert sample["actual_current_as_torque"] == sample["target_moment"]
        # the command on top of gravity (taken one cycle's motion earlier, so not to the last digit)
        hold = _newton_euler(q, [0.0] * 6, [0.0] * 6)
        commanded = [t + g for t, g in zip(TORQUE, hold, strict=True)]
        assert _off(sample["target_moment"], commanded) < 1e-3, (sample["target_moment"], commanded)
        assert _off(realtime_state(arm).m_target, joint_torques(arm)) == 0.0


def test_ur_rtde_reads_the_gravity_torques_as_target_moments() -> None:
    rtde_receive = pytest.importorskip("rtde_receive")
    with fake_robot(MODEL, "--powered", "--controller-version", "5.26.0") as process:
        receiver = rtde_receive.RTDEReceiveInterface(process.address)
        try:
            assert wait_until(lambda: receiver.getTimestamp() > 0.0, 10.0)
            hold = _newton_euler(list(receiver.getActualQ()), [0.0] * 6, [0.0] * 6)
            moments = list(receiver.getTargetMoment())
            assert _off(moments, hold) < 1e-9, (moments, hold)
        finally:
            receiver.disconnect()
