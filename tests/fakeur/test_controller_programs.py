"""The fake controller's programs and outputs after the split: scripts compiled off the event loop in
their order of arrival, the targets and TCP speeds it reports, the RTDE bit-register words, and a
pausing program reported as playing (the fake's clock turned by hand)."""

from __future__ import annotations

import asyncio
import gzip
import math
import threading
from pathlib import Path
from typing import Any

import pytest

import urdaemon.fakeur.urscript as urscript
from tests.fakeur.test_controller import Link
from tests.fakeur.test_controller_life import ManualClock, _ask, _dashboard, manual_fake
from urdaemon.fakeur.controller import FakeController
from urdaemon.fakeur.dashboard_answers import dashboard_reply
from urdaemon.fakeur.reports import realtime_state, robot_state
from urdaemon.protocols import dashboard as dash
from urdaemon.protocols import primary as prim
from urdaemon.protocols import rtde
from urdaemon.protocols._buffer import Side
from urdaemon.protocols.rtde_variables import RuntimeState

pytestmark = pytest.mark.timeout(60)

MOVE = "def {name}():\n  movej([{q}], a=0.5, v=0.3)\nend\n"
"""A long joint move: 1 rad of base at 0.3 rad/s takes seconds of controller time."""


async def _primary(controller: FakeController) -> Link:
    link = await Link.open(prim.PrimaryConnection(Side.DAEMON), controller.address, 30001)
    await link.next(prim.VersionMessage)
    return link


async def _send(controller: FakeController, port: int, text: str) -> None:
    link = await Link.open(prim.PrimaryConnection(Side.DAEMON), controller.address, port)
    link.writer.write(text.encode("ascii"))
    await link.writer.drain()
    link.close()


async def _start(controller: FakeController, text: str) -> None:
    """Send a def program on the primary interface and wait until it has started."""
    link = await _primary(controller)
    link.writer.write(text.encode("ascii"))
    started = await link.next(prim.KeyMessage)
    assert started.title == "PROGRAM_XXX_STARTED", started
    link.close()


def _state(controller: FakeController) -> RuntimeState:
    """The arm's runtime state (a function: mypy would otherwise narrow the attribute for good)."""
    return controller.arm.runtime_state


def _far(controller: FakeController) -> str:
    q = list(controller.arm.q)
    q[0] += 1.0
    return ", ".join(f"{v:.6f}" for v in q)


async def test_scripts_compile_off_the_event_loop_and_start_in_their_order(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """Reproduction: the controller compiled every script on the event loop (lark parsing, 30-55 ms
    for our control script the first time), stalling the clock of every fake in the process. Now
    each is compiled in a worker thread, and a def, a bare line and a sec program sent back to back
    on one connection still start in that order."""
    compiled: list[tuple[int, str]] = []
    compile_program = urscript.compile_program

    def recording(text: str, *args: Any, **kwargs: Any) -> Any:
        compiled.append((threading.get_ident(), text.split("(")[0]))
        return compile_program(text, *args, **kwargs)

    monkeypatch.setattr(urscript, "compile_program", recording)
    async with manual_fake(powered=True) as (controller, clock):
        link = await _primary(controller)
        await _send(
            controller,
            30001,
            "def first():\n  while True:\n    sync()\n  end\nend\n"
            "write_output_integer_register(1, 5)\n"
            "sec beside():\n  write_output_integer_register(2, 7)\nend\n",
        )
        started = await link.next(prim.KeyMessage)
        assert (started.title, started.text) == ("PROGRAM_XXX_STARTED", "first")
        stopped = await link.next(prim.KeyMessage)
        assert (stopped.title, stopped.text) == ("PROGRAM_XXX_STOPPED", "first")
        started = await link.next(prim.KeyMessage)
        assert (started.title, started.text) == ("PROGRAM_XXX_STARTED", "script")
        await controller.programs.settled()
        clock.turn(3)
        assert controller.arm.io.registers_int.get(1) == 5
        assert controller.arm.io.registers_int.get(2) == 7
        assert [text for _, text in compiled] == ["def first", "write_output_integer_register", "sec beside"]
        loop_thread = threading.get_ident()
        assert all(thread != loop_thread for thread, _ in compiled), "compiled on the event loop"
        link.close()


async def test_a_controller_command_waits_for_the_scripts_sent_before_it() -> None:
    """``stop program`` sent right after a def program stops that program, not what ran before."""
    async with manual_fake(powered=True) as (controller, _):
        link = await _primary(controller)
        await _send(
            controller, 30001, "def looping():\n  while True:\n    sync()\n  end\nend\nstop program\n"
        )
        started = await link.next(prim.KeyMessage)
        assert (started.title, started.text) == ("PROGRAM_XXX_STARTED", "looping")
        stopped = await link.next(prim.KeyMessage)
        assert (stopped.title, stopped.text) == ("PROGRAM_XXX_STOPPED", "looping")
        await controller.programs.settled()
        assert controller.programs.main is None
        link.close()


async def _rtde(controller: FakeController, outputs: tuple[str, ...], inputs: tuple[str, ...] = ()) -> Link:
    link = await Link.open(rtde.RtdeConnection(Side.DAEMON), controller.address, 30004)
    await link.send(rtde.RequestProtocolVersion(2))
    assert (await link.next(rtde.ProtocolVersionReply)).accepted
    await link.send(rtde.SetupOutputs(controller.rate_hz, outputs))
    assert (await link.next(rtde.OutputsConfigured)).not_found == ()
    if inputs:
        await link.send(rtde.SetupInputs(inputs))
        configured = await link.next(rtde.InputsConfigured)
        assert configured.not_found == ()
        assert configured.in_use == ()
    await link.send(rtde.Start())
    assert (await link.next(rtde.StartReply)).accepted
    return link


async def _sample(link: Link, clock: ManualClock) -> dict[str, Any]:
    """Turn one cycle and read the package it sent (one per cycle at the controller rate)."""
    clock.turn(1)
    package = await link.next(rtde.DataPackage)
    recipe = link.conn.output_recipe
    assert recipe is not None
    return dict(zip(recipe.names, package.values, strict=True))


async def test_targets_and_tcp_speeds_come_from_the_arm_while_it_moves() -> None:
    """Reproduction: RTDE target_q/target_qd and primary q_target were the actual joints, and
    actual_TCP_speed / target_TCP_speed were always zero, even while the arm moved."""
    outputs: tuple[str, ...] = ("timestamp", "actual_q", "target_q", "target_qd", "actual_TCP_pose")
    outputs = (*outputs, "actual_TCP_speed", "target_TCP_speed")
    async with manual_fake(powered=True) as (controller, clock):
        arm = controller.arm
        await _start(controller, MOVE.format(name="far", q=_far(controller)))
        clock.turn(500)  # a second into the move: at speed
        link = await _rtde(controller, outputs)  # streams from now on: one package per turn
        before = await _sample(link, clock)
        assert before["target_q"] == pytest.approx(arm.target_q, abs=1e-12)
        assert before["target_qd"] == pytest.approx(arm.target_qd, abs=1e-12)
        assert before["target_qd"][0] > 0.1
        after = await _sample(link, clock)
        dt = after["timestamp"] - before["timestamp"]
        start, end = before["actual_TCP_pose"][:3], after["actual_TCP_pose"][:3]
        moved = [(b - a) / dt for a, b in zip(start, end, strict=True)]
        pair = zip(before["actual_TCP_speed"][:3], after["actual_TCP_speed"][:3], strict=True)
        speed = [(a + b) / 2 for a, b in pair]
        assert math.dist(moved, [0.0] * 3) > 0.05, "the TCP moves"
        assert speed == pytest.approx(moved, abs=1e-3), "the TCP speed is the pose's rate of change"
        assert after["target_TCP_speed"][:3] == pytest.approx(after["actual_TCP_speed"][:3], abs=1e-2)
        assert realtime_state(controller.arm).q_target == pytest.approx(arm.target_q, abs=1e-12)
        link.close()


async def test_primary_joint_data_reports_the_target_joints() -> None:
    async with manual_fake(powered=True) as (controller, clock):
        await _start(controller, MOVE.format(name="far", q=_far(controller)))
        clock.turn(500)
        arm = controller.arm
        joints = robot_state(arm, controller.model, controller.controller_version).get(prim.JointData)
        assert joints is not None
        assert joints.q_target == pytest.approx(arm.target_q, abs=1e-12)
        assert joints.q_actual == pytest.approx(arm.q, abs=1e-12)


async def test_rtde_bit_register_words_set_the_inputs_and_report_the_outputs() -> None:
    """Reproduction: ``input_bit_registers0_to_31`` / ``32_to_63`` were accepted as inputs but set
    no register, and the ``*_bit_registers*`` words were always reported as 0."""
    words = ("input_bit_registers0_to_31", "input_bit_registers32_to_63")
    outputs = (*words, "output_bit_registers0_to_31", "output_bit_registers32_to_63")
    async with manual_fake() as (controller, clock):
        controller.arm.io.registers_bit.update({0: True, 31: True, 33: True, 64: True})
        link = await _rtde(controller, outputs, words)
        await link.send(rtde.InputData((0b101, 1 << 31)))
        # the input is handled by the fake's reader task, woken by that read (no cycle runs meanwhile)
        await controller.until(lambda: controller.input_registers.bits.get(0, False), cycles=0)
        sample = await _sample(link, clock)
        bits = controller.input_registers.bits
        assert (bits[0], bits[1], bits[2], bits[32], bits[63]) == (True, False, True, False, True)
        assert sample["input_bit_registers0_to_31"] == 0b101
        assert sample["input_bit_registers32_to_63"] == 1 << 31
        assert sample["output_bit_registers0_to_31"] == 1 | (1 << 31)
        assert sample["output_bit_registers32_to_63"] == 1 << 1
        link.close()


async def test_a_pausing_program_reads_playing_and_play_neither_restarts_nor_jumps(tmp_path: Path) -> None:
    """Reproduction: while the speed scaling ramped to 0 (PAUSING) the dashboard and the real-time
    interface said STOPPED, and ``play`` set the arm PLAYING at full speed scaling at once."""
    async with manual_fake(powered=True, programs=tmp_path) as (controller, clock):
        arm = controller.arm
        (tmp_path / "far.script").write_text(MOVE.format(name="far", q=_far(controller)), encoding="ascii")
        link = await _dashboard(controller.address)
        assert (await _ask(link, dash.Load("far.script"), dash.CommandReply)).success
        assert (await _ask(link, dash.Play(), dash.CommandReply)).success
        await controller.programs.settled()
        script = controller.programs.main
        assert script is not None
        clock.turn(500)
        assert (await _ask(link, dash.Pause(), dash.CommandReply)).success
        clock.turn(2)
        assert _state(controller) is RuntimeState.PAUSING
        scaling = arm.speed_scaling
        assert 0.0 < scaling < 1.0
        state = await _ask(link, dash.GetProgramState(), dash.ProgramStateReply)
        assert state.state is dash.ProgramState.PLAYING
        assert realtime_state(controller.arm).program_state == 2.0
        refused = await _ask(link, dash.Play(), dash.CommandReply)
        assert not refused.success
        assert _state(controller) is RuntimeState.PAUSING
        assert arm.speed_scaling == scaling, "play did not jump the speed scaling"
        assert controller.programs.main is script, "play did not start the program anew"
        clock.until(lambda: _state(controller) is RuntimeState.PAUSED)
        state = await _ask(link, dash.GetProgramState(), dash.ProgramStateReply)
        assert state.state is dash.ProgramState.PAUSED
        assert realtime_state(controller.arm).program_state == 3.0
        assert (await _ask(link, dash.Play(), dash.CommandReply)).success
        assert _state(controller) is RuntimeState.PLAYING
        assert controller.programs.main is script
        link.close()


async def test_a_dashboard_stop_also_stops_a_script_still_being_compiled() -> None:
    """On a controller the script would have started, then stopped: here it must not start afterwards."""
    async with manual_fake(powered=True) as (controller, _):
        controller.programs.submit("late", "def late():\n  while True:\n    sync()\n  end\nend\n")
        assert controller.programs.busy
        assert dashboard_reply(controller, dash.Stop()) == "Stopped"
        await controller.programs.settled()
        assert controller.programs.main is None
        assert _state(controller) is RuntimeState.STOPPED


async def test_a_queued_stop_program_stops_what_came_before_it_and_not_what_came_after() -> None:
    async with manual_fake(powered=True) as (controller, _):
        loop = "def {name}():\n  while True:\n    sync()\n  end\nend\n"
        controller.programs.submit("first", loop.format(name="first"))
        controller.programs.then(controller.programs.stop)
        controller.programs.submit("second", loop.format(name="second"))
        await controller.programs.settled()
        main = controller.programs.main
        assert main is not None
        assert main.name == "second"


WAIT_PROGRAM_URP = (
    '<URProgram name="wait_program" installation="default" directory="/ursim/programs">'
    '<children><MainProgram runOnlyOnce="false" InitVariablesNode="false"><children>'
    '<Wait type="Sleep"><waitTime>0.01</waitTime></Wait>'
    "</children></MainProgram></children></URProgram>"
)
"""A program shaped like urcl's test program wait_program.urp: a 10 ms wait, looping forever."""


def _write_urp(path: Path, xml: str) -> None:
    path.write_bytes(gzip.compress(xml.encode("utf-8"), mtime=0))


def _main(controller: FakeController) -> object:
    """The main program (a function: mypy would otherwise narrow the attribute for good)."""
    return controller.programs.main


async def _program_state(link: Link) -> tuple[dash.ProgramState | None, str | None]:
    reply = await _ask(link, dash.GetProgramState(), dash.ProgramStateReply)
    return reply.state, reply.program


async def test_a_urp_program_plays_pauses_resumes_and_stops_as_on_ursim(tmp_path: Path) -> None:
    """Reproduction: urcl's dashboard_example loads wait_program.urp, then plays, pauses, plays and
    stops it; the fake answered ``play`` with "Failed to execute: play" (it could not read a .urp)."""
    _write_urp(tmp_path / "wait_program.urp", WAIT_PROGRAM_URP)
    async with manual_fake(powered=True, programs=tmp_path) as (controller, clock):
        link = await _dashboard(controller.address)
        assert (await _ask(link, dash.Load("wait_program.urp"), dash.CommandReply)).success
        assert await _program_state(link) == (dash.ProgramState.STOPPED, "wait_program.urp")
        assert (await _ask(link, dash.Play(), dash.CommandReply)).success
        await controller.programs.settled()
        assert await _program_state(link) == (dash.ProgramState.PLAYING, "wait_program.urp")
        clock.turn(100)  # 0.2 s: the 10 ms wait ran many times and the loop goes on
        assert controller.programs.main is not None
        assert await _program_state(link) == (dash.ProgramState.PLAYING, "wait_program.urp")
        assert (await _ask(link, dash.Pause(), dash.CommandReply)).success
        clock.until(lambda: _state(controller) is RuntimeState.PAUSED)
        assert await _program_state(link) == (dash.ProgramState.PAUSED, "wait_program.urp")
        assert (await _ask(link, dash.Play(), dash.CommandReply)).success
        assert await _program_state(link) == (dash.ProgramState.PLAYING, "wait_program.urp")
        clock.turn(10)
        assert (await _ask(link, dash.Stop(), dash.CommandReply)).success
        assert await _program_state(link) == (dash.ProgramState.STOPPED, "wait_program.urp")
        assert _main(controller) is None
        link.close()


async def test_a_urp_with_a_node_the_fake_cannot_run_is_refused_at_load_naming_it(tmp_path: Path) -> None:
    """A program node the fake does not translate must not be dropped silently: ``load`` answers the
    dashboard's "Error while loading program" and a robot message names the node; what was loaded
    before stays loaded."""
    _write_urp(tmp_path / "wait_program.urp", WAIT_PROGRAM_URP)
    _write_urp(tmp_path / "grip.urp", WAIT_PROGRAM_URP.replace("<Wait", '<Timer action="Start"/><Wait'))
    async with manual_fake(powered=True, programs=tmp_path) as (controller, _):
        primary = await _primary(controller)
        link = await _dashboard(controller.address)
        assert (await _ask(link, dash.Load("wait_program.urp"), dash.CommandReply)).success
        refused = await _ask(link, dash.Load("grip.urp"), dash.CommandReply)
        assert not refused.success
        assert refused.text == f"Error while loading program: {tmp_path}/grip.urp"
        message = await primary.next(prim.TextMessage)
        assert "<Timer>" in message.text
        assert "grip.urp" in message.text
        loaded = await _ask(link, dash.GetLoadedProgram(), dash.LoadedProgramReply)
        assert loaded.path == f"{tmp_path}/wait_program.urp"
        link.close()
        primary.close()


async def test_a_urp_holding_the_external_control_node_fetches_the_daemons_script(tmp_path: Path) -> None:
    """A saved External Control program (urcl's external_control.urp) plays as the URCap does: it
    fetches the script from the daemon's script sender and runs it."""
    requests: list[bytes] = []

    async def sender(reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        requests.append(await reader.readline())
        writer.write(b"def fetched():\n  while True:\n    sync()\n  end\nend\n")
        await writer.drain()
        writer.close()

    server = await asyncio.start_server(sender, "127.0.0.1", 0)
    port = server.sockets[0].getsockname()[1]
    node = (
        '<Contributed strategyClass="com.fzi.externalcontrol.ExternalControlNode" '
        'strategyProgramNodeType="External Control"><dataModel/></Contributed>'
    )
    xml = WAIT_PROGRAM_URP.replace('<Wait type="Sleep"><waitTime>0.01</waitTime></Wait>', node)
    _write_urp(tmp_path / "my_control.urp", xml.replace('"false" Init', '"true" Init'))
    try:
        async with manual_fake(powered=True, programs=tmp_path, urcap=("127.0.0.1", port)) as (controller, _):
            primary = await _primary(controller)
            link = await _dashboard(controller.address)
            assert (await _ask(link, dash.Load("my_control.urp"), dash.CommandReply)).success
            assert (await _ask(link, dash.Play(), dash.CommandReply)).success
            started = await primary.next(prim.KeyMessage)  # the URCap's fetch runs on its own task
            assert (started.title, started.text) == ("PROGRAM_XXX_STARTED", "externalControl")
            main = controller.programs.main
            assert main is not None
            assert main.name == "externalControl"
            assert requests == [b"request_program\n"]
            link.close()
            primary.close()
    finally:
        server.close()
        await server.wait_closed()
