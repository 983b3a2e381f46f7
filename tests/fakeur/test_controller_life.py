"""The robot's life as URSim shows it, on a fake whose clock the test turns by hand (no real time):
power and brakes, restart safety, the programs directory, the dashboard's state questions, the robot
mode data's length per version and the real-time interface (30003)."""

from __future__ import annotations

import asyncio
import contextlib
import itertools
import struct
from collections.abc import AsyncIterator, Callable
from pathlib import Path
from typing import Any

import pytest

from tests.fakeur.test_controller import Link
from tests.helpers import fake_address
from urdaemon.fakeur import controller as fake_controller
from urdaemon.fakeur.controller import FakeController
from urdaemon.fakeur.fake_arm import FakeArm
from urdaemon.fakeur.reports import realtime_state
from urdaemon.fakeur.shared_clock import SharedClock
from urdaemon.model import RobotMode, SafetyMode
from urdaemon.protocols import dashboard as dash
from urdaemon.protocols import primary as prim
from urdaemon.protocols import realtime as rt
from urdaemon.protocols._buffer import Side

pytestmark = pytest.mark.timeout(60)


class ManualClock(SharedClock):
    """A shared clock that never ticks by itself: ``turn(n)`` runs n controller cycles now."""

    def __init__(self, period: float) -> None:
        super().__init__(period)
        self.ticks: list[Callable[[], None]] = []

    def add(self, tick: Callable[[], None], slot: int, loop: asyncio.AbstractEventLoop) -> None:
        self.ticks.append(tick)

    def remove(self, tick: Callable[[], None]) -> None:
        self.ticks.remove(tick)

    def turn(self, cycles: int) -> None:
        for _ in range(cycles):
            for tick in self.ticks:
                tick()

    def until(self, done: Callable[[], bool], limit: int = 5000) -> int:
        """Turn until ``done()`` (at most ``limit`` cycles); the cycles it took."""
        for n in range(limit):
            if done():
                return n
            self.turn(1)
        raise AssertionError(f"not done within {limit} cycles")


@contextlib.asynccontextmanager
async def manual_fake(**kwargs: Any) -> AsyncIterator[tuple[FakeController, ManualClock]]:
    """A started fake on a run-specific address, ticking only when the test turns its clock."""
    controller = FakeController(kwargs.pop("model", "ur10e"), address=fake_address(), **kwargs)
    clock = ManualClock(controller.step_time)
    controller.use_clock(clock, 0)
    await controller.start()
    try:
        for _ in range(100):  # the clock task registers on its first turn
            if clock.ticks:
                break
            await asyncio.sleep(0)
        assert clock.ticks
        yield controller, clock
    finally:
        await controller.close()


async def _dashboard(address: str) -> Link:
    link = await Link.open(dash.DashboardConnection(Side.DAEMON), address, 29999)
    await link.next(dash.Banner)
    return link


async def _ask(link: Link, command: Any, kind: type[Any] = object) -> Any:
    await link.send(command)
    return await link.next(kind)


async def test_brake_release_from_power_off_powers_on_and_releases() -> None:
    """Reproduction: ``brake release`` on a powered-off fake was refused ("Failed to execute"), so
    every urcl example that starts from POWER_OFF aborted; URSim powers on and releases."""
    async with manual_fake() as (controller, clock):
        link = await _dashboard(controller.address)
        reply = await _ask(link, dash.BrakeRelease(), dash.CommandReply)
        assert reply.success, reply.text
        clock.until(lambda: controller.arm.robot_mode is RobotMode.RUNNING)
        assert controller.arm.safety_mode is SafetyMode.NORMAL
        link.close()


async def test_set_robotmode_run_on_the_primary_interface_from_power_off_releases_too() -> None:
    async with manual_fake() as (controller, clock):
        _, writer = await asyncio.open_connection(controller.address, 30001)
        writer.write(b"set robotmode run\n")
        await writer.drain()
        # the fake reads it on its own task; no cycle runs meanwhile, the handled read wakes this
        await controller.until(lambda: controller.arm.robot_mode is not RobotMode.POWER_OFF, cycles=0)
        clock.until(lambda: controller.arm.robot_mode is RobotMode.RUNNING)
        writer.close()


async def test_restart_safety_ends_in_power_off_with_safety_normal() -> None:
    async with manual_fake(powered=True) as (controller, clock):
        controller.protective_stop()
        clock.turn(5)
        link = await _dashboard(controller.address)
        reply = await _ask(link, dash.RestartSafety(), dash.CommandReply)
        assert reply.success, reply.text
        clock.turn(5)
        assert controller.arm.robot_mode is RobotMode.POWER_OFF
        assert controller.arm.safety_mode is SafetyMode.NORMAL
        link.close()


async def test_programs_load_from_a_directory_relative_names_resolved_under_it(tmp_path: Path) -> None:
    """Reproduction: ``load`` knew only ``/programs/external_control.urp``; a programs directory,
    relative names, ``isProgramSaved`` and a loaded script file did not exist."""
    (tmp_path / "pick.script").write_text('textmsg("picked")\n', encoding="ascii")
    async with manual_fake(powered=True, programs=tmp_path) as (controller, clock):
        link = await _dashboard(controller.address)
        assert (await _ask(link, dash.GetLoadedProgram(), dash.LoadedProgramReply)).path is None
        missing = await _ask(link, dash.Load("missing.urp"), dash.CommandReply)
        assert not missing.success
        assert missing.text == "File not found: missing.urp"
        default = await _ask(link, dash.Load("external_control.urp"), dash.CommandReply)
        assert default.success, default.text
        loaded = await _ask(link, dash.Load("pick.script"), dash.CommandReply)
        assert loaded.success
        assert loaded.text == f"Loading program: {tmp_path}/pick.script"
        path = (await _ask(link, dash.GetLoadedProgram(), dash.LoadedProgramReply)).path
        assert path == f"{tmp_path}/pick.script"
        saved = await _ask(link, dash.IsProgramSaved(), dash.ProgramSavedReply)
        assert (saved.saved, saved.program) == (True, "pick.script")
        primary = await Link.open(prim.PrimaryConnection(Side.DAEMON), controller.address, 30001)
        await primary.next(prim.VersionMessage)
        assert (await _ask(link, dash.Play(), dash.CommandReply)).success
        await controller.programs.settled()  # compiled off the event loop
        clock.turn(3)
        assert (await primary.next(prim.TextMessage)).text == "picked"
        primary.close()
        link.close()


@pytest.mark.parametrize(
    ("version", "role", "mode"),
    [((5, 15, 0, 0), None, dash.OperationalMode.NONE), ((3, 15, 7, 0), dash.UserRole.PROGRAMMER, None)],
)
async def test_user_role_and_operational_mode_are_answered_per_series(
    version: tuple[int, int, int, int], role: dash.UserRole | None, mode: dash.OperationalMode | None
) -> None:
    """``getUserRole`` exists on CB3, ``get operational mode`` on e-Series (no password set: NONE);
    the other series does not understand them. Before, both were answered with ``ok``-less echoes."""
    model = "ur10e" if version[0] >= 5 else "ur10"
    async with manual_fake(model=model, controller_version=version) as (controller, _):
        link = await _dashboard(controller.address)
        role_reply = await _ask(link, dash.GetUserRole(), dash.UserRoleReply)
        assert role_reply.role is role, role_reply.text
        mode_reply = await _ask(link, dash.GetOperationalMode(), dash.OperationalModeReply)
        assert mode_reply.mode is mode, mode_reply.text
        if role is None:
            assert role_reply.text.startswith("could not understand")
        if mode is None:
            assert mode_reply.text.startswith("could not understand")
        link.close()


@pytest.mark.parametrize(("version", "length"), [((5, 15, 0, 0), 47), ((3, 15, 7, 0), 46)])
async def test_robot_mode_data_has_the_length_the_controller_version_sends(
    version: tuple[int, int, int, int], length: int
) -> None:
    """Reproduction: a CB3 fake sent the e-Series' 47-byte ROBOT_MODE_DATA; a CB3 sends 46."""
    model = "ur10e" if version[0] >= 5 else "ur10"
    async with manual_fake(model=model, controller_version=version) as (controller, clock):
        reader, writer = await asyncio.open_connection(controller.address, 30001)
        version_length = struct.unpack(">i", await reader.readexactly(4))[0]
        await reader.readexactly(version_length - 4)  # the VERSION message comes first
        clock.turn(1)  # then the robot state
        state_length, state_type = struct.unpack(">iB", await reader.readexactly(5))
        assert state_type == prim.PackageType.ROBOT_STATE
        body = await reader.readexactly(state_length - 5)
        sub_length, sub_type = struct.unpack_from(">IB", body)
        assert sub_type == prim.SubPackageType.ROBOT_MODE_DATA
        assert sub_length == length
        writer.close()


@pytest.mark.parametrize(
    ("version", "size", "step"), [((5, 15, 0, 0), 1196, 0.002), ((3, 15, 7, 0), 1108, 0.008)]
)
async def test_realtime_interface_streams_one_message_per_cycle_in_the_versions_layout(
    version: tuple[int, int, int, int], size: int, step: float
) -> None:
    """Reproduction: the fake had no port 30003 (ur_rtde and python-urx need it)."""
    model = "ur10e" if version[0] >= 5 else "ur10"
    async with manual_fake(model=model, controller_version=version, powered=True) as (controller, clock):
        reader, writer = await asyncio.open_connection(controller.address, 30003)
        await controller.until(lambda: bool(controller._realtime_clients), cycles=0)  # accepted
        clock.turn(5)
        client = rt.RealtimeConnection(Side.DAEMON)
        states: list[Any] = []
        for _ in range(100):
            data = await asyncio.wait_for(reader.read(65536), 5.0)
            assert data
            assert struct.unpack_from(">i", data)[0] == size
            states += client.receive_data(data)
            if len(states) >= 5:
                break
        assert len(states) == 5
        assert {round(b.time - a.time, 6) for a, b in itertools.pairwise(states)} == {step}
        assert states[-1].q_actual == pytest.approx(controller.arm.q)
        assert states[-1].robot_mode == int(RobotMode.RUNNING)
        writer.close()


async def test_realtime_state_is_encoded_only_while_a_client_is_connected(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    async with manual_fake() as (controller, clock):
        built = 0

        def counting(arm: FakeArm) -> rt.RealtimeState:
            nonlocal built
            built += 1
            return realtime_state(arm)

        monkeypatch.setattr(fake_controller, "realtime_state", counting)  # what the controller calls
        clock.turn(20)
        assert built == 0
        _, writer = await asyncio.open_connection(controller.address, 30003)
        await controller.until(lambda: bool(controller._realtime_clients), cycles=0)  # accepted
        clock.turn(20)
        assert built == 20
        writer.close()
