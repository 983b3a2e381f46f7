"""A PolyScope 3 program stored as plain XML, shaped like UR's RTDE client example
``rtde_control_loop.urp`` (UniversalRobots/RTDE_Python_Client_Library, examples/): its nodes and
expressions are written here from what that file holds (a BeforeStart sequence, an If around a MoveL
to a pose variable, a While loop, a Thread with Loop Forever), not copied from it.

The program: an RTDE client writes a pose into input float registers 0..5 and sets input int register 0
to 1; the thread copies the registers into ``setp``; the main program moves there, says so with output
int register 0 = 0, waits for the client to clear input int register 0, then asks for the next pose.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import pytest

from tests.fakeur.test_controller import Link, fake
from tests.fakeur.test_urp import chars
from urdaemon.fakeur.urp import UrpRefused, translate
from urdaemon.fakeur.urscript import compile_program
from urdaemon.protocols import dashboard as dash
from urdaemon.protocols import rtde
from urdaemon.protocols._buffer import Side

pytestmark = pytest.mark.timeout(120)

SETP = "../../../../../../SpecialSequence/children/Assignment/variable"
"""Where a node six levels under the program (the If's expression variable, the thread's assignment)
finds the BeforeStart assignment's variable; the waypoint, two levels deeper, goes up two more."""


def line(text: str) -> str:
    return f'<Script type="Line"><expression>{chars(text)}</expression></Script>'


def condition(text: str, *, token: str = "", variable: str = "", rest: str = "") -> str:
    """An expression: text, an editor token, a program variable, more text (as PolyScope 3 stores it)."""
    parts = chars(text)
    if token:
        parts += f'<ExpressionToken token="{token}"/>'
    if variable:
        parts += f'<ExpressionVariable><ProgramVariable reference="{variable}"/></ExpressionVariable>'
    return f"<expression>{parts}{chars(rest)}</expression>"


def declared(name: str) -> str:
    """A variable's first use: its name (later uses refer to this element by its path)."""
    return f'<variable name="{name}" prefersPersistentValue="false"><initializeExpression/></variable>'


def assignment(variable: str, value: str) -> str:
    return (
        f'<Assignment valueSource="Expression">{variable}<expression>{chars(value)}</expression></Assignment>'
    )


THREAD_BODY = (
    assignment(
        '<variable name="tmp" prefersPersistentValue="false"><initializeExpression/></variable>',
        "p[0,0,0,0,0,0]",
    )
    + "".join(line(f"tmp[{i}] = read_input_float_register({i})") for i in range(6))
    + assignment(f'<variable reference="{SETP}"/>', "tmp")
    + line("sync()")
)
PROGRAM = (
    '<?xml version="1.0" encoding="UTF-8"?>\n'
    '<URProgram createdIn="3.2.19275.0" lastSavedIn="3.6.1.30595" name="rtde_control_loop" '
    'directory="/home/ur/ursim-current/programs" installation="default">\n  <children>\n'
    '    <SpecialSequence type="BeforeStart"><children>'
    + assignment(
        '<variable name="setp" prefersPersistentValue="false"><initializeExpression/></variable>',
        "p[0,0,0,0,0,0]",
    )
    + line('rtde_set_watchdog("input_int_register_0", 1, "PAUSE")')
    + line("write_output_integer_register(0, 1)")
    + "</children></SpecialSequence>\n"
    '    <MainProgram runOnlyOnce="false" motionType="MoveJ" speed="1.0471975511965976" '
    'acceleration="1.3962634015954636" useActiveTCP="false"><children>'
    '<If type="If" checkContinuously="false">'
    + condition(
        "read_input_integer_register(0)\u225f1",
        token=" and ",
        variable=SETP,
        rest="\u2260p[0, 0, 0, 0, 0, 0]",
    )
    + "<children>"
    '<Comment comment="Valid pose received from client"/>'
    '<Move motionType="MoveL" speed="0.08" acceleration="1.2" useActiveTCP="false">'
    '<feature class="GeomFeatureReference" referencedName="Joint_0_name"/><children>'
    '<Waypoint type="Variable" name="Waypoint" kinematicsFlags="-1"><motionParameters/>'
    f'<variable reference="../../{SETP}"/></Waypoint>'
    "</children></Move>"
    '<Comment comment="Confirm that move was executed"/>'
    + line("write_output_integer_register(0, 0)")
    + '<Loop type="While" checkContinuously="false">'
    + condition("read_input_integer_register(0)\u225f1")
    + f"<children>{line('sync()')}</children></Loop>"
    + line("write_output_integer_register(0, 1)")
    + "</children></If>"
    + line("sync()")
    + "</children></MainProgram>\n"
    '    <Thread name="Thread_1" runOnlyOnce="false"><children>'
    f'<Loop type="Forever"><children>{THREAD_BODY}</children></Loop>'
    "</children></Thread>\n  </children>\n</URProgram>\n"
).encode("utf-8")
"""The program, plain XML (not gzip-compressed), as UR's example is stored."""


def test_the_plain_xml_program_translates_and_compiles() -> None:
    program = translate(PROGRAM, "rtde_control_loop.urp")
    assert program.loops
    script = program.script
    assert script is not None
    statements = [s.strip() for s in script.splitlines() if not s.strip().startswith("$")]
    assert 'rtde_set_watchdog("input_int_register_0", 1, "PAUSE")' in statements
    assert "movel(setp, a=1.2, v=0.08)" in statements
    assert statements.count("while (True):") == 3  # the program's loop, the thread's, Loop Forever
    assert "if (read_input_integer_register(0)==1 and setp!=p[0, 0, 0, 0, 0, 0]):" in statements
    compile_program(script, "cb3", (3, 15))


def test_a_variable_waypoint_relative_to_another_feature_is_refused() -> None:
    other = PROGRAM.replace(b'referencedName="Joint_0_name"', b'referencedName="Plane_1"')
    with pytest.raises(UrpRefused, match="Plane_1"):
        translate(other, "rtde_control_loop.urp")


async def _rtde_client(address: str) -> tuple[Link, dict[str, int]]:
    link = await Link.open(rtde.RtdeConnection(Side.DAEMON), address, 30004)
    await link.send(rtde.RequestProtocolVersion(2))
    await link.next(rtde.ProtocolVersionReply)
    await link.send(rtde.SetupOutputs(125.0, ("output_int_register_0", "actual_TCP_pose")))
    await link.next(rtde.OutputsConfigured)
    names = ("input_int_register_0", *(f"input_double_register_{i}" for i in range(6)))
    await link.send(rtde.SetupInputs(names))
    await link.next(rtde.InputsConfigured)
    await link.send(rtde.Start())
    await link.next(rtde.StartReply)
    return link, {"names": len(names)}


async def _sample(link: Link) -> dict[str, Any]:
    recipe = link.conn.output_recipe
    assert recipe is not None
    return dict(zip(recipe.names, (await link.next(rtde.DataPackage)).values, strict=True))


async def test_ur_example_control_loop_moves_the_arm_to_the_pose_a_client_sends(tmp_path: Path) -> None:
    """What UR's example_control_loop.py does with this program: send a pose, wait for the move."""
    (tmp_path / "rtde_control_loop.urp").write_bytes(PROGRAM)
    async with fake(powered=True, programs=tmp_path) as controller:
        dashboard = await Link.open(dash.DashboardConnection(Side.DAEMON), controller.address, 29999)
        await dashboard.next(dash.Banner)
        link, _ = await _rtde_client(controller.address)
        start = (await _sample(link))["actual_TCP_pose"]
        target = (start[0], start[1], start[2] - 0.05, *start[3:])
        await link.send(rtde.InputData((1, *target)))  # before play: the watchdog starts fed
        for command in (dash.Load("rtde_control_loop.urp"), dash.Play()):
            await dashboard.send(command)
            assert (await dashboard.next(dash.CommandReply)).success
        moved, ready = None, False
        for _ in range(2000):  # 16 s of samples at 125 Hz; the move takes under 1 s
            await link.send(rtde.InputData((1, *target)))  # keeps the 1 Hz watchdog fed
            sample = await _sample(link)
            ready = ready or sample["output_int_register_0"] == 1  # BeforeStart ran: it asks for a pose
            if ready and sample["output_int_register_0"] == 0:  # the move is done
                moved = sample["actual_TCP_pose"]
                break
        assert moved is not None, "the program never confirmed the move"
        assert math.dist(moved[:3], target[:3]) < 1e-3
        assert controller.programs.name is not None
        link.close()
        dashboard.close()
