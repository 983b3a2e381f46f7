"""ur_rtde 1.6.5's ``servoC`` leaves its control script unable to take the next command: the evidence
behind the ``client`` row of docs/fake-robot.md's table (``servoC``).

ur_rtde sends servoC (command 12 in ``input_int_register_0``) as a real-time command: it does not wait
for the script and never writes the register back to 0. Its script, though, treats 12 as a regular
command: it runs it once, writes "done" (2) to ``output_int_register_0`` and writes "ready" (1) again
only once the register reads 0. The next non-real-time call (``servoStop``) waits for "ready", which
only the client could bring, and gives up: False after ur_rtde's 3 s limit, clearing the register on
its way out. This test shows the fake runs the script exactly so (the registers as the script leaves
them), and that a second ``servoStop`` then works, so the fake does not imitate the client's mistake
away. Not a reproduction of a fake bug: the fake was right before and stays so.
"""

from __future__ import annotations

from typing import Any

import pytest

from tests.fakeur.judges import RtdeWatch, fake_robot, pose_off, wait_until

rtde_control = pytest.importorskip("rtde_control")
rtde_receive = pytest.importorskip("rtde_receive")

pytestmark = pytest.mark.timeout(180)

REGISTERS = ("input_int_register_0", "output_int_register_0")
SERVOC, READY, DONE = 12, 1, 2


def test_servoc_leaves_the_script_done_until_the_client_clears_its_command() -> None:
    with fake_robot("ur10e", "--powered", "--controller-version", "5.26.0") as fake:
        receiver: Any = rtde_receive.RTDEReceiveInterface(fake.address)
        control: Any = rtde_control.RTDEControlInterface(fake.address)
        watch = RtdeWatch(fake.address, REGISTERS)
        try:
            assert watch.next_samples(2)["output_int_register_0"] == READY
            pose = list(receiver.getActualTCPPose())
            target = [pose[0], pose[1], pose[2] - 0.02, *pose[3:]]
            assert control.servoC(target, 0.05, 0.5, 0.0) is True
            assert wait_until(
                lambda: not pose_off(list(receiver.getActualTCPPose()), target, 1e-4, 1e-3), 15.0
            )
            # the client never cleared its command: the script said done once and waits for a 0
            sample = watch.next_samples(5)
            assert (sample["input_int_register_0"], sample["output_int_register_0"]) == (SERVOC, DONE), sample
            assert control.servoStop(10.0) is False, (
                "ur_rtde waits for ready, which only its own clear brings"
            )
            assert watch.wait_for(lambda: watch.sample.get("output_int_register_0") == READY, 10.0)
            assert watch.sample["input_int_register_0"] == 0, "ur_rtde cleared its command on giving up"
            assert control.servoStop(10.0) is True, "the script takes the next command"
            assert control.isProgramRunning()
        finally:
            watch.close()
            control.stopScript()
            control.disconnect()
            receiver.disconnect()
