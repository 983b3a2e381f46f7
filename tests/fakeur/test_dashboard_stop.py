"""The dashboard's ``stop`` with no program playing answers ``Stopped``, as a controller does.

urcl's ``ExampleRobotWrapper::initializeRobotWithDashboard`` sends ``stop`` on a fresh URSim ("stop
program, if there is one running") and gives up unless the reply is ``Stopped``; ur_rtde's
``DashboardClient.stop`` throws on any other reply, and its ``reuploadScript`` (like its constructor and
``reconnect`` when a script runs) ends its own script first and then sends ``stop``. Both work against
controllers, so a controller answers ``Stopped`` when nothing plays.

Reproduction on the old fake: it answered ``Failed to execute: stop`` whenever nothing played, so
``DashboardClient.stop()`` and ``RTDEControlInterface.reuploadScript()`` raised that text.
"""

from __future__ import annotations

import pytest

from tests.fakeur.judges import PrimaryWatch, fake_robot, wait_until
from tests.fakeur.test_controller_life import _ask, _dashboard, manual_fake
from urdaemon.protocols import dashboard as dash
from urdaemon.protocols.rtde_variables import RuntimeState

pytestmark = pytest.mark.timeout(120)


async def test_stop_with_nothing_playing_is_stopped_on_the_wire() -> None:
    async with manual_fake(powered=True) as (controller, clock):
        link = await _dashboard(controller.address)
        assert controller.arm.runtime_state is RuntimeState.STOPPED
        for _ in range(2):  # and again: stopping a stopped controller stays a success
            reply = await _ask(link, dash.Stop(), dash.CommandReply)
            assert reply.success, reply.text
            assert reply.text == "Stopped"
        state = await _ask(link, dash.GetProgramState(), dash.ProgramStateReply)
        assert state.state is dash.ProgramState.STOPPED  # what urcl's commandStop then waits for
        clock.turn(1)
        link.close()


async def test_stop_on_a_powered_off_arm_is_stopped() -> None:
    async with manual_fake() as (controller, _clock):
        link = await _dashboard(controller.address)
        reply = await _ask(link, dash.Stop(), dash.CommandReply)
        assert reply.success, reply.text
        link.close()


def test_ur_rtde_dashboard_stop_with_nothing_running() -> None:
    dashboard_client = pytest.importorskip("dashboard_client")
    with fake_robot("ur10e", "--powered") as fake:
        client = dashboard_client.DashboardClient(fake.address)
        client.connect()
        try:
            client.stop()  # raises the reply unless it is "Stopped"
            assert "STOPPED" in client.programState()
        finally:
            client.disconnect()


def test_ur_rtde_reupload_script_stops_its_own_script_then_runs_anew() -> None:
    rtde_control = pytest.importorskip("rtde_control")
    with fake_robot("ur10e", "--powered") as fake:
        primary = PrimaryWatch(fake.address)
        control = rtde_control.RTDEControlInterface(fake.address)
        try:
            assert control.isProgramRunning()
            try:
                assert control.reuploadScript()
            except RuntimeError as err:
                raise AssertionError(f"reuploadScript raised {err}\n{primary.describe()}") from None
            # it returns once the script is sent; the script runs a few cycles later
            assert wait_until(control.isProgramRunning, 10.0), primary.describe()
            started = [t for t in primary.texts() if "PROGRAM_XXX_STARTED" in t]
            assert len(started) == 2, primary.describe()  # its first script, then the one re-uploaded
            assert not primary.runtime_exceptions(), primary.describe()
        finally:
            control.stopScript()
            control.disconnect()
            primary.close()
