"""The TCP offset on a `ur` robot, end to end against the fake controller (issue 17: "a TCP offset
per robot ... sent to UR robots").

The backend sends ``SetTcpOffset`` on the script command link; our control script (run by the fake's
URScript interpreter) calls ``set_tcp`` with it, which sets the fake arm's TCP; the fake's RTDE
``actual_TCP_pose`` then is the flange pose with that offset. Each test compares that pose with
``UrKinematics.forward(q, tcp)`` on the arm's own model (1e-9). Every wait is on the backend's cycles
or the fake's, bounded in count and time.
"""

from __future__ import annotations

import contextlib
from collections.abc import AsyncIterator, Sequence

import pytest

from tests.helpers import fake_address
from tests.ur.test_links_harness import HOME, JOINTS, UrRun, program_is_running, robot_config
from urdaemon.backends.ur.backend import UrBackend
from urdaemon.description.ik import UrKinematics
from urdaemon.description.urmodels import load_ur_model
from urdaemon.errors import BackendError
from urdaemon.fakeur.controller import FakeController
from urdaemon.fakeur.reports import _OUTPUTS

pytestmark = pytest.mark.timeout(120)

CELL_TCP = (0.0, 0.0, 0.12, 0.0, 0.0, 0.0)
"""The cell file's ``tcp`` (a straight 12 cm tool)."""
NEW_TCP = (0.01, -0.02, 0.2, 0.1, -0.2, 0.3)
"""A TCP set with ``set_tcp``: offset and turned, so every axis of the pose shows it."""
PENDANT_TCP = [0.0, 0.05, 0.05, 0.0, 0.0, 0.0]
"""The controller's TCP after a program restart without the daemon's (the installation's TCP)."""


@contextlib.asynccontextmanager
async def _tcp_run(tcp: Sequence[float], *, start: bool = True) -> AsyncIterator[UrRun]:
    """A fake UR10e and a ``UrBackend`` for it whose cell file gives ``tcp``."""
    address = fake_address()
    robot = robot_config(address).model_copy(update={"tcp": tuple(tcp)})
    fake = FakeController("ur10e", address=address, initial_positions=HOME, powered=True)
    await fake.start()
    run = UrRun(UrBackend(robot, JOINTS, expected_hash=None), fake)
    try:
        if start:
            run.start()
        yield run
    finally:
        await run.stop()
        await fake.close()


def _rtde_tcp_pose(run: UrRun) -> tuple[float, ...]:
    """The fake's RTDE ``actual_TCP_pose`` now."""
    return tuple(_OUTPUTS["actual_TCP_pose"](run.fake.arm))


def _expected_pose(run: UrRun, tcp: Sequence[float]) -> tuple[float, ...]:
    """The TCP pose of the arm's joints now with ``tcp``, on its own (nominal) model."""
    return tuple(UrKinematics(load_ur_model("ur10e")).forward(run.fake.arm.q, tcp))


def _has_tcp(run: UrRun, tcp: Sequence[float]) -> bool:
    return run.fake.arm.tcp_offset == pytest.approx(list(tcp), abs=1e-6)


async def test_the_cell_files_tcp_is_the_controllers_from_the_first_connection() -> None:
    """Reproduction: a cell file with ``tcp: [0, 0, 0.12, 0, 0, 0]``; the program connected and the
    controller's TCP stayed at the flange (the backend never sent it), so the robot's own TCP pose
    differed from the daemon's tcp_pose by the whole tool."""
    async with _tcp_run(CELL_TCP) as run:
        assert run.backend.tcp == CELL_TCP
        await run.until(lambda: program_is_running(run), what="the program runs")
        await run.until(lambda: _has_tcp(run, CELL_TCP), what="the controller has the cell's TCP")
        assert _rtde_tcp_pose(run) == pytest.approx(_expected_pose(run, CELL_TCP), abs=1e-9)
        assert _rtde_tcp_pose(run) != pytest.approx(_expected_pose(run, [0.0] * 6), abs=1e-3)


async def test_set_tcp_sets_the_controllers_tcp_and_rtde_reports_it() -> None:
    """Reproduction: ``Backend.set_tcp`` did not exist on any backend; the `ur` robot's controller
    kept its TCP whatever the daemon's was. Now the script command reaches our control script, whose
    ``set_tcp`` turns the arm's TCP, and RTDE's ``actual_TCP_pose`` is forward(q, tcp)."""
    async with _tcp_run((0.0,) * 6) as run:
        await run.until(lambda: program_is_running(run), what="the program runs")
        await run.backend.set_tcp(NEW_TCP)
        assert run.backend.tcp == NEW_TCP
        await run.until(lambda: _has_tcp(run, NEW_TCP), what="the controller has the new TCP")
        assert _rtde_tcp_pose(run) == pytest.approx(_expected_pose(run, NEW_TCP), abs=1e-9)
        with pytest.raises(BackendError, match="six finite numbers"):
            await run.backend.set_tcp((0.0, 0.0, float("nan"), 0.0, 0.0, 0.0))
        with pytest.raises(BackendError, match="six finite numbers"):
            await run.backend.set_tcp((0.0, 0.0, 0.1))
        assert run.backend.tcp == NEW_TCP, "a refused TCP changes nothing"


async def test_a_tcp_set_before_the_program_connects_is_sent_when_it_does() -> None:
    """Reproduction: ``set_tcp`` while no control program is connected (the daemon starting, the robot
    powered off) was lost: the controller never heard of it. It is kept and sent when the program's
    script command link comes up."""
    async with _tcp_run(CELL_TCP, start=False) as run:
        await run.backend.set_tcp(NEW_TCP)  # nothing connected yet: kept
        run.start()
        await run.until(lambda: program_is_running(run), what="the program runs")
        await run.until(lambda: _has_tcp(run, NEW_TCP), what="the controller has the TCP set before")
        assert _rtde_tcp_pose(run) == pytest.approx(_expected_pose(run, NEW_TCP), abs=1e-9)


async def test_the_tcp_is_sent_again_when_the_program_reconnects() -> None:
    """Reproduction: after ``set_tcp``, the program's script command link dropped and the restarted
    program ran with the installation's TCP (modelled by setting the fake's TCP as the pendant would);
    the daemon never sent its TCP again, so the controller's differed from tcp_pose for good. Now every
    connection of the link gets the daemon's TCP: once after the link drops, and once after an
    explicit program restart."""
    async with _tcp_run(CELL_TCP) as run:
        await run.until(lambda: program_is_running(run), what="the program runs")
        await run.backend.set_tcp(NEW_TCP)
        await run.until(lambda: _has_tcp(run, NEW_TCP), what="the controller has the new TCP")
        link = run.backend.servers.script_command.link
        assert link is not None
        link.close()  # the link is lost: the backend restarts the program (headless)
        run.fake.arm.tcp_offset = list(PENDANT_TCP)  # the new program starts with another TCP
        await run.until(lambda: run.backend.servers.script_command.link not in (None, link), what="relinked")
        await run.until(lambda: program_is_running(run), what="the program runs again")
        await run.until(lambda: _has_tcp(run, NEW_TCP), what="the TCP was sent again")
        assert _rtde_tcp_pose(run) == pytest.approx(_expected_pose(run, NEW_TCP), abs=1e-9)

        before = run.backend.servers.script_command.link
        run.fake.arm.tcp_offset = list(PENDANT_TCP)
        await run.backend.resend_program()
        await run.until(
            lambda: run.backend.servers.script_command.link not in (None, before), what="new link"
        )
        await run.until(lambda: _has_tcp(run, NEW_TCP), what="the TCP was sent to the new program")
        assert _rtde_tcp_pose(run) == pytest.approx(_expected_pose(run, NEW_TCP), abs=1e-9)
