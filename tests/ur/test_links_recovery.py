"""Issue 13 findings 4 and 6, the ``ur`` backend's part: dashboard refusals, one start-up or restart at
a time, absurd numbers refused clearly, RTDE protocol v1, start-up without a dashboard, a status that
forgets the robot's modes when the links drop, and readiness reasons that say why and what to do."""

from __future__ import annotations

import asyncio
import contextlib

import pytest

from tests.ur.test_links_harness import program_is_running, ur_run
from urdaemon.errors import BackendError, UrDaemonError
from urdaemon.fakeur.dashboard_answers import dashboard_reply
from urdaemon.fakeur.faults import FaultInjector
from urdaemon.model import Lifecycle, RobotMode, SafetyMode
from urdaemon.protocols import dashboard as dash
from urdaemon.protocols import primary as prim
from urdaemon.protocols import script_command

pytestmark = pytest.mark.timeout(90)


async def test_an_unknown_dashboard_command_is_refused_with_the_robots_reply() -> None:
    """Reproduction: the ``dashboard`` service with a line the controller does not know. The controller
    answers "could not understand: '...'" and the daemon reported ``ok: true``."""
    async with ur_run() as run:
        await run.until(lambda: program_is_running(run), what="ready")
        ok, text = await run.backend.dashboard("make coffee")
        assert ok is False
        assert text == "could not understand: 'make coffee'"
        ok, text = await run.backend.dashboard("robotmode")  # a query still answers
        assert (ok, text) == (True, "Robotmode: RUNNING")


async def test_resend_program_many_times_at_once_sends_one_program() -> None:
    """Reproduction: 14 ``resend_program`` calls within a few ms sent 14 programs (each replacing the
    one before it while it connected back). Now the first sends one; the others are refused while it
    is still connecting back."""
    async with ur_run() as run:
        await run.until(lambda: program_is_running(run), what="ready")
        sent = run.programs_sent
        results = await asyncio.gather(
            *(run.backend.resend_program() for _ in range(14)), return_exceptions=True
        )
        refused = [r for r in results if isinstance(r, BackendError)]
        assert len(refused) == 13, results
        assert all("still connecting back" in str(r) for r in refused)
        assert run.programs_sent == sent + 1
        await run.until(lambda: program_is_running(run), what="ready again")


async def test_a_second_startup_while_one_is_under_way_is_refused() -> None:
    """Reproduction: two ``startup`` calls at once on a powered-off robot both ran the whole power-on
    sequence (a second program could follow). The second is refused while the first is under way."""
    async with ur_run(powered=False, startup=False) as run:
        await run.until(lambda: run.backend.state.robot_mode is RobotMode.POWER_OFF, what="powered off")
        first = asyncio.ensure_future(run.backend.startup())
        await asyncio.sleep(0)  # let the first take the lock
        with pytest.raises(BackendError, match="already under way"):
            await run.backend.startup()
        with pytest.raises(BackendError, match="already under way"):
            await run.backend.resend_program()
        await first
        await run.until(lambda: program_is_running(run), what="ready")
        assert run.programs_sent >= 1, "the one start-up sent the program"


async def test_absurd_payload_and_force_numbers_are_clear_refusals() -> None:
    """Reproduction: ``set_payload`` with mass 1e9 or cog 1e6, and force mode with a 1e9 wrench, raised
    an internal error (the script-command codec cannot scale them into int32) with a traceback; a
    passthrough point of 1e9 rad failed the same way after START had gone out."""
    async with ur_run() as run:
        await run.until(lambda: program_is_running(run), what="ready")
        backend = run.backend
        with pytest.raises(BackendError, match="payload"):
            await backend.set_payload(1e9, (0.0, 0.0, 0.0))
        with pytest.raises(BackendError, match="payload"):
            await backend.set_payload(1.0, (1e6, 0.0, 0.0))
        with pytest.raises(BackendError, match="finite"):
            await backend.set_payload(float("nan"), (0.0, 0.0, 0.0))
        wrench = script_command.StartForceMode(
            task_frame=(0.0,) * 6,
            selection=(0, 0, 1, 0, 0, 0),
            wrench=(0.0, 0.0, 1e9, 0.0, 0.0, 0.0),
            force_type=2,
            limits=(0.1,) * 6,
        )
        with pytest.raises(BackendError, match="force mode"):
            await backend.force_mode(wrench)
        huge = ((1e9, 0.0, 0.0, 0.0, 0.0, 0.0), (0.0,) * 6, None, 1.0)
        with pytest.raises(BackendError, match="trajectory"):
            backend.encode_passthrough_point(*huge)  # refused before any START could go out
        assert backend.passthrough_problem() is None, "no START went out: no passthrough is running"
        await run.cycles_pass(10)
        assert program_is_running(run), "the links survived the refusals"


async def test_a_controller_that_speaks_only_rtde_v1_is_driven() -> None:
    """Reproduction: a controller that refuses RTDE v2 (the fake with ``rtde_versions=(1,)``). The
    handshake fell back to v1 but still asked for a frequency, which v1's SETUP_OUTPUTS has no room
    for: the codec refused it and the backend never connected."""
    async with ur_run(rtde_versions=(1,)) as run:
        await run.until(lambda: program_is_running(run), what="ready over RTDE v1")
        rtde = run.backend.links.rtde
        assert rtde is not None
        assert rtde.conn.protocol_version == 1
        assert rtde.frequency == 500.0
        start = run.backend.state.controller_time
        await run.cycles_pass(100)
        # one package per controller cycle: the controller's clock moved 100 steps
        assert run.backend.state.controller_time - start == pytest.approx(100 * 0.002, abs=0.011)


async def test_startup_without_a_dashboard_powers_on_over_the_primary_interface() -> None:
    """Reproduction: ``startup: true`` with no dashboard (PolyScope X, or the dashboard refuses the
    connection) on a powered-off robot: the robot never became ready."""
    faults = FaultInjector()
    faults.refused.add("dashboard")
    async with ur_run(powered=False, faults=faults) as run:
        await run.until(lambda: program_is_running(run), what="ready without a dashboard")
        assert run.fake.arm.robot_mode is RobotMode.RUNNING


async def test_urcap_startup_without_a_dashboard_says_what_to_do() -> None:
    """Reproduction: URCap mode, ``startup: true``, the dashboard refused: the robot was never ready
    and its status did not say why. Now it powers on over the primary interface and says that the
    External Control program must be played on the pendant."""
    faults = FaultInjector()
    faults.refused.add("dashboard")
    async with ur_run(powered=False, headless=False, faults=faults) as run:
        await run.until(
            lambda: "start-up failed" in run.backend.state.lifecycle_reason,
            what="a reason naming the failed start-up",
        )
        assert "press play on the pendant" in run.backend.state.lifecycle_reason
        assert run.backend.state.robot_mode is RobotMode.RUNNING
        assert any(kind == "startup_failed" for kind, _ in run.notices)


async def test_the_status_forgets_the_robot_modes_when_the_links_drop() -> None:
    """Reproduction: the fake closes the RTDE link; ``run`` ends. The status kept ``robot_mode:
    RUNNING`` and safety mode NORMAL from the last package, as if the robot were still known."""
    async with ur_run() as run:
        await run.until(lambda: program_is_running(run), what="ready")
        assert run.backend.state.robot_mode is RobotMode.RUNNING
        run.fake.drop("rtde")
        assert run.task is not None
        with contextlib.suppress(UrDaemonError):
            await asyncio.wait_for(run.task, 20.0)
        state = run.backend.state
        assert state.robot_mode is RobotMode.DISCONNECTED
        assert state.safety_mode is SafetyMode.UNDEFINED_SAFETY_MODE
        assert state.program_running is False
        assert state.lifecycle is Lifecycle.DISCONNECTED


async def test_readiness_reasons_say_why_after_a_power_off_and_a_failed_startup() -> None:
    """Reproduction: power the robot off on the dashboard; the status said only ``robot is idle``
    (empty reason). Then an emergency stop makes ``startup`` fail: the reason did not say so."""
    async with ur_run() as run:
        await run.until(lambda: program_is_running(run), what="ready")
        dashboard_reply(run.fake, dash.PowerOff())
        await run.until(lambda: not run.ready, what="not ready")
        await run.until(
            lambda: "powered off" in run.backend.state.lifecycle_reason, what="the reason says powered off"
        )
        run.fake.emergency_stop()
        with pytest.raises(UrDaemonError):
            await run.backend.startup()
        await run.cycles_pass(2)
        reason = run.backend.state.lifecycle_reason
        assert "emergency stop" in reason
        assert "start-up failed: power on refused" in reason


async def test_a_program_the_controller_ended_is_named_with_the_controllers_message() -> None:
    """Reproduction: in URCap mode the controller ends the control program with a runtime error. The
    status said only "waiting for the control program to connect", not what the controller said."""
    async with ur_run(headless=False) as run:
        await run.until(lambda: program_is_running(run), what="ready")
        run.fake._broadcast(prim.RuntimeExceptionMessage(12, 3, "socket_read_binary_integer: timeout"))
        run.fake.programs.stop()
        await run.until(lambda: run.backend.servers.reverse.link is None, what="the program ended")
        await run.until(
            lambda: "the control program ended" in run.backend.state.lifecycle_reason,
            what="the reason names the end",
        )
        reason = run.backend.state.lifecycle_reason
        assert "socket_read_binary_integer: timeout" in reason
