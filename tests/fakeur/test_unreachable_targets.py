"""Unreachable and out-of-limit motion targets as urcl's URSim tests see them (issue 33, point 7).

* ``movel(p[10,0,0,0,0,0])``: urcl's ``test_send_script_blocking_fail_on_robot_errors`` expects a
  protective stop with its error code (``RobotErrorCodeException``), then unlocks and moves on;
  ``unfeasible_movel_target_results_in_failure`` waits for the protective stop, unlocks and stops the
  program. Reproduction on the old fake: a runtime exception (``RobotRuntimeException``), no stop.
* ``movej([-123, 0, 0, 0, 0, 0])``: ``unfeasible_movej_target_results_in_failure`` expects the External
  Control trajectory to end with a failure by itself, which urcl's executor reports when the script's
  sockets close: the program must stop. Reproduction on the old fake: a protective stop that paused the
  program, so the trajectory never ended.
* ``movej(p[10,0,0,0,0,0])`` stays a runtime exception
  (``test_send_script_blocking_fail_on_runtime_exception``).
"""

from __future__ import annotations

from typing import Any

import pytest

from tests.fakeur.test_controller import Link
from tests.fakeur.test_controller_life import manual_fake
from urdaemon.model import SafetyMode
from urdaemon.protocols import primary as prim
from urdaemon.protocols._buffer import Side
from urdaemon.protocols.rtde_variables import RuntimeState

pytestmark = pytest.mark.timeout(60)

_SAID = (prim.ErrorCodeMessage, prim.SafetyModeMessage, prim.RuntimeExceptionMessage, prim.KeyMessage)


async def _run(script: bytes) -> Any:
    """Send ``script`` on the primary interface; what the fake said and did within 1000 cycles."""
    async with manual_fake(powered=True) as (controller, clock):
        link = await Link.open(prim.PrimaryConnection(Side.DAEMON), controller.address, 30001)
        await link.next(prim.VersionMessage)
        link.writer.write(script)
        await link.writer.drain()
        await controller.until(lambda: controller.programs.main is not None, cycles=0)
        arm = controller.arm
        clock.until(
            lambda: arm.safety_mode is not SafetyMode.NORMAL or controller.programs.main is None, 1000
        )
        clock.turn(1)
        said = [await link.next(_SAID)]
        while not isinstance(said[-1], (prim.SafetyModeMessage, prim.RuntimeExceptionMessage)):
            said.append(await link.next(_SAID))
        state = (arm.safety_mode, arm.runtime_state, controller.programs.main is not None)
        link.close()
        return said, state


def _kinds(said: list[Any]) -> list[type[Any]]:
    return [type(m) for m in said if not isinstance(m, prim.KeyMessage)]


async def test_movel_to_an_unreachable_pose_is_a_protective_stop_with_its_error_code() -> None:
    said, state = await _run(b"def far():\n  movel(p[10, 0, 0, 0, 0, 0], a=1.2, v=0.25)\nend\n")
    assert _kinds(said) == [prim.ErrorCodeMessage, prim.SafetyModeMessage], said
    error = next(m for m in said if isinstance(m, prim.ErrorCodeMessage))
    assert error.code == 209
    assert state == (SafetyMode.PROTECTIVE_STOP, RuntimeState.PAUSED, True), "paused in the movel"


async def test_movej_beyond_the_joint_limits_stops_the_program_with_a_runtime_exception() -> None:
    said, state = await _run(b"def far():\n  movej([-123, 0, 0, 0, 0, 0], a=1.4, v=1.05)\nend\n")
    assert _kinds(said) == [prim.RuntimeExceptionMessage], said
    assert "joint limits" in said[-1].text
    assert state == (SafetyMode.NORMAL, RuntimeState.STOPPED, False), "the program ended"


async def test_movej_to_an_unreachable_pose_stays_a_runtime_exception() -> None:
    said, state = await _run(b"def far():\n  movej(p[10, 0, 0, 0, 0, 0], a=1.4, v=1.05)\nend\n")
    assert _kinds(said) == [prim.RuntimeExceptionMessage], said
    assert state[0] is SafetyMode.NORMAL
