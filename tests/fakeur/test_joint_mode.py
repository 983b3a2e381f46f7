"""One joint mode on every interface: 239 (JOINT_POWER_OFF_MODE) without power, 255 (JOINT_IDLE_MODE)
powered with the brakes on, 253 (JOINT_RUNNING_MODE) once running (UR's client interface tables;
docs/fake-robot.md, "RTDE inputs, units and small fixes")."""

from __future__ import annotations

from typing import Any

import pytest

from tests.fakeur.judges import fake_robot
from tests.fakeur.test_controller import Link, fake
from tests.helpers import rtde_sample
from urdaemon.fakeur.reports import realtime_state, robot_state
from urdaemon.model import RobotMode
from urdaemon.protocols import dashboard as dash
from urdaemon.protocols import primary as prim
from urdaemon.protocols._buffer import Side

pytestmark = pytest.mark.timeout(120)

_ON_THE_WAY = (RobotMode.POWER_OFF, RobotMode.BOOTING, RobotMode.POWER_ON)
"""Robot modes a power-on passes through before the arm is IDLE."""


@pytest.mark.parametrize(
    ("commands", "mode", "expected"),
    [
        ((), RobotMode.POWER_OFF, 239),
        ((dash.PowerOn(),), RobotMode.IDLE, 255),
        ((dash.PowerOn(), dash.BrakeRelease()), RobotMode.RUNNING, 253),
    ],
)
async def test_rtde_realtime_and_primary_report_the_same_joint_mode(
    commands: tuple[Any, ...], mode: RobotMode, expected: int
) -> None:
    """Reproduction: powered off, RTDE and the real-time interface said 255 where the primary said 239."""
    async with fake() as controller:
        dashboard = await Link.open(dash.DashboardConnection(Side.DAEMON), controller.address, 29999)
        await dashboard.next(dash.Banner)
        for command in commands:
            await dashboard.send(command)
            assert (await dashboard.next(dash.CommandReply)).success
            await controller.until(lambda: controller.arm.robot_mode not in _ON_THE_WAY)
        arm = controller.arm
        await controller.until(lambda: arm.robot_mode is mode)
        sample = await rtde_sample(controller.address, ("robot_mode", "joint_mode", "tool_mode"))
        assert sample["robot_mode"] == int(mode)
        assert sample["joint_mode"] == (expected,) * 6
        assert sample["tool_mode"] == expected
        assert realtime_state(arm).joint_modes == (float(expected),) * 6
        state = robot_state(arm, controller.model, controller.controller_version)
        joints = state.get(prim.JointData)
        tool = state.get(prim.ToolData)
        assert joints is not None
        assert tool is not None
        assert joints.joint_mode == (expected,) * 6
        assert tool.tool_mode == expected
        dashboard.close()


def test_ur_rtde_reads_joint_power_off_mode_from_an_unpowered_fake() -> None:
    rtde_receive = pytest.importorskip("rtde_receive")
    with fake_robot("ur10e") as fake_process:
        receiver = rtde_receive.RTDEReceiveInterface(fake_process.address)
        try:
            assert list(receiver.getJointMode()) == [239] * 6
        finally:
            receiver.disconnect()
