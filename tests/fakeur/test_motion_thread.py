"""One thread controls the arm: a motion command from a second thread stops the program.

Reproduction (issue 33, point 3): ur_rtde's ``stopJ``/``stopL`` run ``stopj``/``stopl`` in its script's
main thread while its speed thread still loops on ``speedj``/``speedl``. The fake let the latest command
win, so the speed thread took the arm back every cycle and it never came to rest. A controller refuses
the second thread with the runtime exception "Another thread is already controlling the robot", which
stops the program, and the arm with it (docs/fake-robot.md, "Script threads").
"""

from __future__ import annotations

from collections.abc import Iterator
from typing import Any

import pytest

from tests.fakeur.judges import PrimaryWatch, fake_robot, wait_until
from tests.fakeur.test_controller_life import manual_fake
from urdaemon.fakeur.controller import FakeController
from urdaemon.fakeur.urscript.lib_motion import ANOTHER_THREAD

pytestmark = pytest.mark.timeout(120)

STILL = 1e-6
"""rad/s: a joint at rest."""
MOVER = """
thread mover():
  while True:
    speedj([0.2, 0, 0, 0, 0, -0.1], a=1.0)
  end
end
"""
"""A thread that keeps the arm at speed, as ur_rtde's speed thread does."""


def _at_rest(controller: FakeController) -> bool:
    return max(abs(v) for v in controller.arm.qd) < STILL


@pytest.mark.parametrize("stop", ["stopj(2)", "stopl(0.5)", "movej([0, -1.57, 1.57, -1.57, -1.57, 0])"])
async def test_a_motion_from_a_second_thread_stops_the_program_and_the_arm(stop: str) -> None:
    text = f'def two():\n{MOVER}  run mover()\n  sleep(0.5)\n  {stop}\n  textmsg("after")\nend\n'
    async with manual_fake(powered=True) as (controller, clock):
        controller.programs.submit("two", text)
        await controller.until(lambda: controller.programs.main is not None, cycles=0)
        script = controller.programs.main
        assert script is not None
        clock.turn(300)  # 0.6 s: the mover is at speed, then main commands motion
        assert script.run.error is not None, "the second thread's motion was accepted"
        assert script.run.error.message == ANOTHER_THREAD
        assert (script.run.error.line, script.run.error.column) == (10, 3)
        assert controller.programs.main is None, "the program stopped"
        for _ in range(1000):  # bounded: 2 s of cycles to come to rest
            if _at_rest(controller):
                break
            clock.turn(1)
        assert _at_rest(controller)


async def test_killing_the_controlling_thread_hands_control_over() -> None:
    """ur_rtde's speedStop kills its speed thread, then stops in the main thread: that works."""
    text = f"def handover():\n{MOVER}  h = run mover()\n  sleep(0.5)\n  kill h\n  stopj(2)\n  halt\nend\n"
    async with manual_fake(powered=True) as (controller, clock):
        controller.programs.submit("handover", text)
        await controller.until(lambda: controller.programs.main is not None, cycles=0)
        script = controller.programs.main
        assert script is not None
        for _ in range(2000):
            if script.run.done:
                break
            clock.turn(1)
        assert script.run.done
        assert script.run.error is None, script.run.error
        assert _at_rest(controller)


# ---- the judge: ur_rtde ---------------------------------------------------------------------------------

rtde_control = pytest.importorskip("rtde_control")
rtde_receive = pytest.importorskip("rtde_receive")


@pytest.fixture
def rtde() -> Iterator[tuple[Any, Any, PrimaryWatch]]:
    with fake_robot("ur10e", "--powered") as fake:
        primary = PrimaryWatch(fake.address)
        receiver = rtde_receive.RTDEReceiveInterface(fake.address, 500.0)
        control = rtde_control.RTDEControlInterface(fake.address)
        try:
            yield control, receiver, primary
        finally:
            control.disconnect()
            receiver.disconnect()
            primary.close()


@pytest.mark.parametrize("kind", ["joint", "tool"])
def test_ur_rtde_speed_then_stop_comes_to_rest(rtde: tuple[Any, Any, PrimaryWatch], kind: str) -> None:
    control, receiver, primary = rtde
    if kind == "joint":
        assert control.speedJ([0.2, 0.0, 0.0, 0.0, 0.0, -0.1], 0.5, 0.0), primary.describe()
    else:
        assert control.speedL([0.05, 0.0, 0.0, 0.0, 0.0, 0.0], 0.25, 0.0), primary.describe()
    assert wait_until(lambda: max(abs(v) for v in receiver.getActualQd()) > 0.02, 20.0), primary.describe()
    try:  # the script stops with the controller's error: ur_rtde may answer False or raise
        if kind == "joint":
            control.stopJ(2.0)
        else:
            control.stopL(0.5)
    except RuntimeError:
        pass
    start = receiver.getTimestamp()

    def at_rest() -> bool:
        return bool(max(abs(v) for v in receiver.getActualQd()) < STILL)

    assert wait_until(at_rest, 20.0), f"still moving: {receiver.getActualQd()}\n{primary.describe()}"
    # within 2 s of controller time (RTDE timestamps: 1000 packages at 500 Hz), not a wall-clock wait
    assert receiver.getTimestamp() - start < 2.0
    assert primary.wait_for(lambda: any(ANOTHER_THREAD in t for t in primary.texts()), 10.0), (
        primary.describe()
    )
