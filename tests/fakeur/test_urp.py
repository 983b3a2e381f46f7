"""PolyScope ``.urp`` programs -> URScript (``fakeur.urp``): node by node, the whole file, refusals.

The fixtures are written here: gzip-compressed XML shaped like the programs PolyScope saves (the
layout of UR's client library's test programs ``wait_program.urp`` and ``external_control.urp``,
urcl's tests/resources/dockerursim/programs, Apache-2.0), not copies of them.
"""

from __future__ import annotations

import asyncio
import gzip
import re
import threading
from collections.abc import AsyncIterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pytest

from tests.helpers import fake_address
from urdaemon.fakeur import dashboard_answers
from urdaemon.fakeur import urp as urp_module
from urdaemon.fakeur.controller import FakeController
from urdaemon.fakeur.urp import MAX_URP_BYTES, UrpProgram, UrpRefused, translate
from urdaemon.fakeur.urscript import ScriptCompileError, compile_program
from urdaemon.protocols import dashboard as dash

KINEMATICS = """<kinematics status="NOT_INITIALIZED" validChecksum="false">
    <deltaTheta value="0.0, 0.0, 0.0, 0.0, 0.0, 0.0"/>
    <a value="0.0, -0.425, -0.3922, 0.0, 0.0, 0.0"/>
  </kinematics>"""


def urp(nodes: str, *, once: bool = False, name: str = "demo", before: str = "") -> bytes:
    """A gzipped program whose MainProgram holds ``nodes`` (and a BeforeStart sequence if given)."""
    sequence = f'<SpecialSequence type="BeforeStart"><children>{before}</children></SpecialSequence>'
    xml = (
        f'<URProgram name="{name}" installation="default" directory="/ursim/programs" createdIn="5.12.4">'
        f"{KINEMATICS}<children>{sequence if before else ''}"
        f'<MainProgram runOnlyOnce="{str(once).lower()}" InitVariablesNode="false">'
        f"<children>{nodes}</children></MainProgram></children></URProgram>"
    )
    return gzip.compress(xml.encode("utf-8"), mtime=0)


def chars(text: str) -> str:
    """An expression as PolyScope stores it: one ExpressionChar per character."""
    escaped = {'"': "&quot;", "<": "&lt;", ">": "&gt;", "&": "&amp;"}
    return "".join(f'<ExpressionChar character="{escaped.get(c, c)}"/>' for c in text)


def body(nodes: str) -> list[str]:
    """The statements (no step labels, no indentation) a run-once program of ``nodes`` translates to."""
    script = translate(urp(nodes, once=True), "demo.urp").script
    assert script is not None
    lines = [line.strip() for line in script.splitlines()]
    assert lines[0] == "def demo():"
    assert lines[-1] == "end"
    return [line for line in lines[1:-1] if not line.startswith("$")]


WAIT_PROGRAM = '<Wait type="Sleep"><waitTime>0.01</waitTime></Wait>'
EXTERNAL_CONTROL = (
    '<Contributed strategyClass="com.fzi.externalcontrol.ExternalControlNode" '
    'strategyProgramNodeType="External Control"><dataModel/></Contributed>'
)
WAYPOINT = (
    '<Waypoint type="Fixed" name="Waypoint_1"><motionParameters{blend}/>'
    '<position><JointAngles angles="0.1, -1.5, 1.2, -1.2, -1.57, 0.0"/>'
    '<TCPOffset pose="0.0, 0.0, 0.0, 0.0, 0.0, 0.0"/></position></Waypoint>'
)

TABLE = [
    ("wait sleep", WAIT_PROGRAM, ["sleep(0.01)"]),
    (
        "wait digital input",
        '<Wait type="DigitalInput"><pin referencedName="digital_in[2]"/>'
        "<digitalValue>1</digitalValue></Wait>",
        ["while (not(get_standard_digital_in(2) == True)):", "sync()", "end"],
    ),
    (
        "wait tool input low",
        '<Wait type="DigitalInput"><pin referencedName="tool_in[0]"/><digitalValue>0</digitalValue></Wait>',
        ["while (not(get_tool_digital_in(0) == False)):", "sync()", "end"],
    ),
    (
        "wait condition",
        f'<Wait type="Condition"><expression>{chars("x > 2")}</expression></Wait>',
        ["while (not(x > 2)):", "sync()", "end"],
    ),
    (
        "script line",
        '<Script type="Line"><expression>' + chars('textmsg("hi")') + "</expression></Script>",
        ['textmsg("hi")'],
    ),
    (
        "script file",
        '<Script type="File"><cachedContents>x = 1\ntextmsg(x)\n</cachedContents>'
        '<file resolves-to="file">/programs/a.script</file></Script>',
        ["x = 1", "textmsg(x)"],
    ),
    (
        "assignment",
        '<Assignment valueSource="Expression"><variable name="count" prefersPersistentValue="false">'
        f"<initializeExpression/></variable><expression>{chars('count + 1')}</expression></Assignment>",
        ["global count = count + 1"],
    ),
    (
        "set digital output",
        '<Set type="DigitalOutput"><pin referencedName="digital_out[3]"/>'
        "<digitalValue>1</digitalValue></Set>",
        ["set_standard_digital_out(3, True)"],
    ),
    (
        "set configurable output",
        '<Set type="DigitalOutput"><pin referencedName="config_out[1]"/><digitalValue>0</digitalValue></Set>',
        ["set_configurable_digital_out(1, False)"],
    ),
    (
        "set tool output",
        '<Set type="DigitalOutput"><pin referencedName="tool_out[1]"/><digitalValue>1</digitalValue></Set>',
        ["set_tool_digital_out(1, True)"],
    ),
    (
        "popup message",
        '<Popup type="Message" haltProgram="false" message="Hello"/>',
        ['popup("Hello", "Message", False, False, blocking=True)'],
    ),
    (
        "popup error that halts",
        '<Popup type="Error" haltProgram="true" message="Stop &quot;now&quot;"/>',
        ['popup("Stop \'now\'", "Error", False, True, blocking=True)', "halt"],
    ),
    ("comment", '<Comment comment="only a note"/>', []),
    (
        "folder",
        f'<Folder name="Setup"><children>{WAIT_PROGRAM}<Comment comment="x"/></children></Folder>',
        ["sleep(0.01)"],
    ),
    ("halt", "<Halt/>", ["halt"]),
    (
        "movej",
        '<Move motionType="MoveJ" speed="1.0472" acceleration="1.3963" useActiveTCP="true">'
        f"<children>{WAYPOINT.format(blend='')}</children></Move>",
        ["movej([0.1, -1.5, 1.2, -1.2, -1.57, 0.0], a=1.3963, v=1.0472)"],
    ),
    (
        "movel with a blend",
        '<Move motionType="MoveL" speed="0.25" acceleration="1.2">'
        "<children>" + WAYPOINT.format(blend=' blendRadius="0.01"') + "</children></Move>",
        ["movel([0.1, -1.5, 1.2, -1.2, -1.57, 0.0], a=1.2, v=0.25, r=0.01)"],
    ),
    (
        "old-style waypoint joints",
        '<Move motionType="MoveJ" speed="1" acceleration="1"><children>'
        '<Waypoint type="Fixed" name="W"><position joints="0, 0, 0, 0, 0, 1"/></Waypoint></children></Move>',
        ["movej([0, 0, 0, 0, 0, 1], a=1, v=1)"],
    ),
]


IF_CHAIN = (
    f'<If type="If" checkContinuously="false"><expression>{chars("x == 1")}</expression>'
    "<children><Halt/></children></If>"
    f'<If type="ElseIf" checkContinuously="false"><expression>{chars("x ≟ 2")}</expression>'
    f"<children>{WAIT_PROGRAM}</children></If>"
    '<If type="Else" checkContinuously="false"><expression/><children><Comment comment="x"/>'
    "</children></If>"
)
VARIABLE = (
    '<Assignment valueSource="Expression"><variable name="count" prefersPersistentValue="false">'
    f"<initializeExpression/></variable><expression>{chars('0')}</expression></Assignment>"
)
TABLE += [
    (
        "set an output register to an expression reading it",
        '<Set type="ExpressionOutput"><pin referencedName="GP_int_out[24]"/><expression>'
        '<ExpressionIO><pin referencedName="GP_int_out[24]"/></ExpressionIO>'
        f"{chars('+1')}</expression></Set>",
        ["write_output_integer_register(24, read_output_integer_register(24)+1)"],
    ),
    (
        "a node between waypoints",
        '<Move motionType="MoveJ" speed="1" acceleration="2"><children>'
        '<Set type="DigitalOutput"><pin referencedName="digital_out[0]"/><digitalValue>1</digitalValue></Set>'
        + WAYPOINT.format(blend="")
        + "</children></Move>",
        ["set_standard_digital_out(0, True)", "movej([0.1, -1.5, 1.2, -1.2, -1.57, 0.0], a=2, v=1)"],
    ),
    ("if elif else", IF_CHAIN, ["if (x == 1):", "halt", "elif (x == 2):", "sleep(0.01)", "else:", "end"]),
    (
        "if alone, then a node",
        f'<If type="If"><expression>{chars("x ≠ 1")}</expression><children><Halt/></children></If><Halt/>',
        ["if (x != 1):", "halt", "end", "halt"],
    ),
    (
        "while loop",
        f'<Loop type="While" checkContinuously="false"><expression>{chars("x ≤ 3")}</expression>'
        f"<children>{WAIT_PROGRAM}</children></Loop>",
        ["while (x <= 3):", "sleep(0.01)", "end"],
    ),
    (
        "tokens and variable references",
        VARIABLE + '<Assignment valueSource="Expression"><variable reference="../../Assignment/variable"/>'
        "<expression><ExpressionVariable><ProgramVariable reference="
        '"../../../../Assignment/variable"/></ExpressionVariable>'
        f"{chars(' + 1')}</expression></Assignment>"
        f'<If type="If"><expression><ExpressionToken token=" not "/>{chars("(count ≥ 1)")}</expression>'
        "<children><Halt/></children></If>",
        ["global count = 0", "global count = count + 1", "if ( not (count >= 1)):", "halt", "end"],
    ),
    (
        "a suppressed node does not run",
        f'<SuppressedNode><suppressedNode class="Halt"/></SuppressedNode>{WAIT_PROGRAM}',
        ["sleep(0.01)"],
    ),
]


@pytest.mark.parametrize(("nodes", "expected"), [(n, e) for _, n, e in TABLE], ids=[t[0] for t in TABLE])
def test_each_program_node_translates_to_its_urscript(nodes: str, expected: list[str]) -> None:
    assert body(nodes) == expected


@pytest.mark.parametrize("nodes", [n for _, n, _ in TABLE], ids=[t[0] for t in TABLE])
@pytest.mark.parametrize("series", [("e", (5, 15)), ("cb3", (3, 15))])
def test_every_translation_compiles_on_both_series(nodes: str, series: tuple[str, tuple[int, int]]) -> None:
    """What the translator writes is URScript the interpreter accepts (``x`` and ``count`` defined first)."""
    declare = chars("global x = 0 global count = 0")
    setup = f'<Script type="Line"><expression>{declare}</expression></Script>'
    script = translate(urp(setup + nodes, once=True), "demo.urp").script
    assert script is not None
    compile_program(script, *series)


def test_a_looping_program_runs_its_body_forever_and_a_run_once_program_once() -> None:
    """Reproduction: ``load wait_program.urp`` and ``play`` failed on the fake (a .urp was unreadable)."""
    looping = translate(urp(WAIT_PROGRAM, name="wait_program"), "wait_program.urp")
    assert looping.loops
    assert not looping.external_control
    assert looping.script == (
        "def wait_program():\n"
        "  while (True):\n"
        '    $ 1 "Robot Program"\n'
        '    $ 2 "Wait: 0.01"\n'
        "    sleep(0.01)\n"
        "  end\n"
        "end\n"
    )
    once = translate(urp(WAIT_PROGRAM, once=True), "demo.urp")
    assert not once.loops
    assert once.script is not None
    assert "while" not in once.script
    assert compile_program(looping.script, "e", (5, 15)).kind == "def"


def test_the_before_start_sequence_runs_once_before_the_loop() -> None:
    script = translate(urp(WAIT_PROGRAM, before="<Halt/>"), "demo.urp").script
    assert script is not None
    assert script.index("halt") < script.index("while (True):")


def test_a_thread_node_runs_beside_the_main_program() -> None:
    xml = gzip.decompress(urp(WAIT_PROGRAM)).decode()
    thread = f'<Thread name="Thread_1" runOnlyOnce="false"><children>{WAIT_PROGRAM}</children></Thread>'
    data = gzip.compress(xml.replace("</MainProgram>", "</MainProgram>" + thread).encode())
    script = translate(data, "demo.urp").script
    assert script is not None
    statements = [line.strip() for line in script.splitlines() if not line.strip().startswith("$")]
    assert statements[1:6] == ["thread Thread_1():", "while (True):", "sleep(0.01)", "end", "end"]
    assert statements[6] == "threadId_Thread_1 = run Thread_1()"
    assert statements.index("threadId_Thread_1 = run Thread_1()") < statements.index("while (True):", 3)
    compile_program(script, "e", (5, 15))


def test_the_program_name_becomes_a_def_name() -> None:
    assert translate(urp(WAIT_PROGRAM, name="my program-2"), "x.urp").name == "my_program_2"
    assert translate(urp(WAIT_PROGRAM, name="2nd"), "x.urp").name == "p2nd"


def test_the_external_control_node_alone_is_the_external_control_program() -> None:
    program = translate(urp(EXTERNAL_CONTROL, once=True, name="external_control"), "external_control.urp")
    assert program.external_control
    assert program.script is None


@pytest.mark.parametrize(
    ("data", "reason"),
    [
        (urp('<Loop type="Counting"><children/></Loop>'), '<Loop type="Counting">'),
        (urp('<If type="Else"><children/></If>'), "follows no <If>"),
        (urp('<If type="If" checkContinuously="true"><children/></If>'), "checkContinuously"),
        (urp('<Timer action="Start"/>'), "<Timer>"),
        (urp('<Assignment valueSource="Operator"><variable name="x"/></Assignment>'), "Operator"),
        (
            urp('<Assignment valueSource="Expression"><variable reference="../No/variable"/></Assignment>'),
            "not in the program",
        ),
        (
            urp('<Contributed strategyClass="x.Grip" strategyProgramNodeType="RG Grip"/>'),
            "<Contributed> (RG Grip)",
        ),
        (urp('<Wait type="AnalogInput"><pin referencedName="analog_in[0]"/></Wait>'), "AnalogInput"),
        (urp('<Set type="AnalogOutput"/>'), "AnalogOutput"),
        (urp('<Move motionType="MoveP" speed="1" acceleration="1"/>'), "MoveP"),
        (
            urp(
                '<Move motionType="MoveL" speed="1" acceleration="1"><children>'
                '<Waypoint type="Fixed" name="P1"><position><TCPOffset pose="0,0,0,0,0,0"/></position>'
                "</Waypoint></children></Move>"
            ),
            "P1 carries no joint angles",
        ),
        (urp('<Set type="DigitalOutput"><pin referencedName="digital_out[x]"/></Set>'), "digital_out[x]"),
        (urp(WAIT_PROGRAM + EXTERNAL_CONTROL), "External Control"),
        (urp(""), "empty"),
        (b"not gzip at all", "gzip"),
        (gzip.compress(b"<URProgram><children>", mtime=0), "malformed"),
        (gzip.compress(b"<Installation/>", mtime=0), "<Installation>"),
        (gzip.compress(b"<URProgram><children/></URProgram>", mtime=0), "MainProgram"),
        (gzip.compress(b"<URProgram>" + b" " * (MAX_URP_BYTES + 1) + b"</URProgram>", mtime=0), "larger"),
        (gzip.compress(b"<URProgram/>", mtime=0)[:-6], "truncated"),
    ],
    ids=lambda value: value if isinstance(value, str) else "urp",  # the same ids in every xdist worker
)
def test_a_program_the_fake_cannot_play_is_refused_naming_why(data: bytes, reason: str) -> None:
    with pytest.raises(UrpRefused) as refused:
        translate(data, "bad.urp")
    assert reason in refused.value.reason


def test_a_script_node_with_an_error_compiles_to_the_controllers_refusal() -> None:
    """The translation does not check URScript: the compiler refuses the program as it would any other."""
    script = translate(urp(f'<Script type="Line"><expression>{chars("movej(")}</expression></Script>'), "x")
    assert script.script is not None
    with pytest.raises(ScriptCompileError):
        compile_program(script.script, "e", (5, 15))


UR_PROGRAM = Path(__file__).parents[1] / "data" / "urp"
"""UR's timing_debug.urp and the script PolyScope generated for it (see its README.md)."""


def _statements(script: str) -> list[str]:
    """A script's statements without step labels, comments, blank lines or spacing."""
    lines = (line.strip() for line in script.splitlines())
    return [re.sub(r"\s+", "", line) for line in lines if line and not line.startswith(("$", "#"))]


def test_a_polyscope_program_translates_as_polyscope_generates_it() -> None:
    """The translation of UR's own saved program matches, statement for statement, the script
    PolyScope wrote for it, from its BeforeStart sequence on (PolyScope's installation preamble and
    waypoint variables aside), but for the waypoints: PolyScope moves to the inverse kinematics of
    the taught pose near the taught joints, the fake to the taught joints themselves."""
    program = translate((UR_PROGRAM / "timing_debug.urp").read_bytes(), "timing_debug.urp")
    assert program.loops
    assert program.script is not None
    ours = _statements(program.script)
    theirs = _statements((UR_PROGRAM / "timing_debug.script").read_text(encoding="utf-8"))
    start = theirs.index("globalvar_4=4")
    assert ours[0] == "deftiming_debug():"
    assert len(ours[1:]) == len(theirs[start:]) == 75
    moves = 0
    for mine, polyscope in zip(ours[1:], theirs[start:], strict=True):
        if polyscope.startswith("movej(get_inverse_kin(Waypoint_"):
            moves += 1
            assert mine.startswith("movej([")
            assert mine.endswith("],a=1.3962634015954636,v=1.0471975511965976)")
        else:
            assert mine == polyscope
    assert moves == 2
    compile_program(program.script, "e", (5, 23))


def test_a_file_read_only_up_to_the_bound_is_refused_as_too_large() -> None:
    """The dashboard reads at most MAX_URP_BYTES + 1 bytes of a file; a compressed program cut there
    is refused as too large, not as truncated."""
    data = gzip.compress(bytes(range(256)) * (MAX_URP_BYTES // 128), compresslevel=0)
    with pytest.raises(UrpRefused) as refused:
        translate(data[: MAX_URP_BYTES + 1], "big.urp")
    assert "larger than" in refused.value.reason


def _pins_to_the_last_sibling(pins: int, siblings: int) -> bytes:
    """``pins`` Wait nodes whose pin refers to the last of ``siblings`` elements outside the program
    tree (the reviewer's file: a reference resolved by searching every sibling, once per pin)."""
    wait = (
        f'<Wait type="DigitalInput"><pin reference="../../../../../z/a[{siblings}]"/>'
        "<digitalValue>1</digitalValue></Wait>"
    )
    target = '<a referencedName="digital_in[1]"/>'  # the last sibling: the others are <a/>
    xml = (
        '<URProgram name="demo"><children><MainProgram runOnlyOnce="true"><children>'
        f"{wait * pins}</children></MainProgram></children>"
        f"<z>{'<a/>' * (siblings - 1)}{target}</z></URProgram>"
    )
    return gzip.compress(xml.encode(), mtime=0)


def test_a_program_with_too_many_elements_is_refused() -> None:
    """Reproduction: a 720-byte gzip within MAX_URP_BYTES (800 pins referring to the last of 40 001
    siblings, the reviewer's file) translated, searching all siblings for each pin: 0.17 s of every
    fake's clock per ``load`` on the old code."""
    data = _pins_to_the_last_sibling(800, 40_001)
    assert len(data) < 1000
    assert len(gzip.decompress(data)) <= MAX_URP_BYTES
    with pytest.raises(UrpRefused) as refused:
        translate(data, "flood.urp")
    assert f"more than {urp_module.MAX_URP_ELEMENTS} XML elements" in refused.value.reason


def test_references_are_resolved_in_time_linear_in_the_program(monkeypatch: pytest.MonkeyPatch) -> None:
    """Reproduction: each reference searched all its siblings (``findall``), references x siblings
    steps. Now each parent's children are indexed once per translation and each path followed once:
    the work is counted, and bounded by the program's size."""
    trees: list[Any] = []

    class Counting(urp_module._Tree):
        def __init__(self, root: Any) -> None:
            super().__init__(root)
            trees.append(self)

    monkeypatch.setattr(urp_module, "_Tree", Counting)
    pins, siblings = 1500, 3000
    program = translate(_pins_to_the_last_sibling(pins, siblings), "many.urp")
    assert program.script is not None
    assert program.script.count("while (not(get_standard_digital_in(1) == True)):") == pins
    (tree,) = trees
    elements = 6 + 3 * pins + siblings
    assert tree.indexed <= elements  # every element indexed at most once, not once per reference
    assert tree.lookups == 7 * pins  # the path's seven steps, once per pin


def test_a_chain_of_references_is_followed_once_and_a_cycle_is_refused() -> None:
    """A reference to a reference resolves to the element the last one names; a loop of them is
    refused, naming the element."""
    variable = '<variable name="n"/>'
    first = (
        '<Assignment><variable reference="../../Assignment/variable"/>'
        f"<expression>{chars('1')}</expression></Assignment>"
    )
    declared = f"<Assignment>{variable}<expression>{chars('2')}</expression></Assignment>"
    assert body(declared + first) == ["global n = 2", "global n = 1"]
    cycle = (
        '<Assignment><variable reference="../../Assignment[2]/variable"/>'
        f"<expression>{chars('1')}</expression></Assignment>"
        '<Assignment><variable reference="../../Assignment[1]/variable"/>'
        f"<expression>{chars('2')}</expression></Assignment>"
    )
    with pytest.raises(UrpRefused) as refused:
        translate(urp(cycle, once=True), "cycle.urp")
    assert "references in a row" in refused.value.reason


@dataclass
class SlowLoad:
    """A fake whose ``.urp`` translation (of ``slow.urp`` in its programs directory) starts, then waits
    for ``release`` (5 s at most) and records in ``ticks`` how many cycles the fake ran meanwhile."""

    fake: FakeController
    programs: Path
    started: threading.Event
    release: threading.Event
    ticks: list[int]

    async def let_the_clock_tick(self, cycles: int = 5) -> None:
        """Wait for the translation to start, let the fake run ``cycles`` cycles, then release it.

        Counted from the translation's start, not from the request: on a busy machine the fake reads
        the request a cycle or two later (stress_suite.sh saw 4 cycles)."""
        await self.fake.until(self.started.is_set, cycles=2500, timeout=10.0)
        await self.fake.cycles_pass(cycles, timeout=10.0)
        self.release.set()


@pytest.fixture
async def slow_load(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> AsyncIterator[SlowLoad]:
    """A running fake whose ``load`` of ``slow.urp`` translates only once its clock has ticked on: a
    translation on the event loop would wait for that in vain (5 s, then fail)."""
    (tmp_path / "slow.urp").write_bytes(urp(WAIT_PROGRAM))
    started, release = threading.Event(), threading.Event()
    ticks: list[int] = []

    def slow_translate(data: bytes, file_name: str) -> UrpProgram:
        before = fake.cycles
        started.set()
        release.wait(5.0)
        ticks.append(fake.cycles - before)
        return translate(data, file_name)

    monkeypatch.setattr(dashboard_answers, "translate", slow_translate)
    async with FakeController("ur10e", address=fake_address(), programs=tmp_path) as fake:
        try:
            yield SlowLoad(fake, tmp_path, started, release, ticks)
        finally:
            release.set()


async def test_a_load_translates_off_the_event_loop(slow_load: SlowLoad) -> None:
    """Reproduction: ``load`` translated a ``.urp`` on the event loop, so a slow translation (0.17 s
    for the reviewer's file) held every fake's clock. Here the translation waits until the clock
    has ticked on: it would wait in vain (5 s, then fail) if it ran on the loop."""
    fake, programs = slow_load.fake, slow_load.programs
    answer = asyncio.ensure_future(dashboard_answers.dashboard_answer(fake, dash.Load("slow.urp")))
    await slow_load.let_the_clock_tick()
    reply = await asyncio.wait_for(answer, 10.0)
    assert slow_load.started.is_set()
    assert reply == f"Loading program: {programs}/slow.urp"
    assert len(slow_load.ticks) == 1
    assert slow_load.ticks[0] >= 5
    assert fake.loaded_program == f"{programs}/slow.urp"
    assert fake.programs.loaded_urp is not None


async def test_a_dashboard_load_holds_no_clock(slow_load: SlowLoad) -> None:
    """Reproduction: the dashboard server translated a ``.urp`` at ``load`` on the event loop; here
    the translation waits until the fake's clock has ticked on, which it would wait for in vain."""
    fake = slow_load.fake
    reader, writer = await asyncio.open_connection(fake.address, fake.ports.dashboard)
    try:
        await asyncio.wait_for(reader.readline(), 10.0)  # the banner
        writer.write(b"load slow.urp\n")
        await slow_load.let_the_clock_tick()
        reply = await asyncio.wait_for(reader.readline(), 10.0)
    finally:
        writer.close()
    assert reply == f"Loading program: {slow_load.programs}/slow.urp\n".encode()
    assert len(slow_load.ticks) == 1
    assert slow_load.ticks[0] >= 5
