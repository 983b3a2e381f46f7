"""Our control URScript: rendering, parameter checks, and a structural check of the script against §4/§5."""

from __future__ import annotations

import enum
import re
import socket
from typing import Any

import pytest

from urdaemon.description.urmodels import load_ur_model
from urdaemon.fakeur.fake_arm import FakeArm
from urdaemon.fakeur.urscript import compile_program
from urdaemon.fakeur.urscript.script_host import ScriptHost
from urdaemon.protocols import reverse, script_command, trajectory_point
from urdaemon.protocols._buffer import Side
from urdaemon.protocols.primary import (
    CommandReceived,
    PrimaryConnection,
    ProgramReceived,
    headless_program,
)
from urdaemon.urscript import (
    PLACEHOLDERS,
    URCAP_MARKERS,
    ScriptParameters,
    render_control_script,
    render_template,
)

HOST = "10.0.0.7"
CONNECT_ORDER = ("trajectory_socket", "script_command_socket", "reverse_socket")
"""urcl's order: the daemon counts the program as running once the reverse socket connects (§4)."""
SOCKET_FRAME_INTS = {
    "reverse_socket": reverse.FRAME_INTS,
    "trajectory_socket": trajectory_point.FRAME_INTS,
    "script_command_socket": script_command.FRAME_INTS,
}


@pytest.fixture(scope="module")
def params() -> ScriptParameters:
    return ScriptParameters(
        HOST,
        reverse_port=51001,
        trajectory_port=51003,
        script_command_port=51004,
        servoj_lookahead=0.1,
        servoj_gain=300,
        tool_setup=("set_tool_voltage(24)", "set_tool_communication(True, 115200, 0, 1, 1.5, 3.5)"),
    )


@pytest.fixture(scope="module")
def script(params: ScriptParameters) -> str:
    return render_control_script(params)


# -- helpers: a small structural reader of URScript ------------------------------------------------------


def _code(line: str) -> str:
    """The line without its ``#`` comment; a ``#`` inside a string literal is kept."""
    quote = ""
    for index, char in enumerate(line):
        if quote:
            if char == quote:
                quote = ""
        elif char in "\"'":
            quote = char
        elif char == "#":
            return line[:index]
    return line


_OPENERS = ("def", "thread", "if", "while", "for", "sec")


def _check_blocks(text: str) -> int:
    """The number of blocks; AssertionError unless each closes with ``end`` at its opener's indentation."""
    stack: list[tuple[str, int, int]] = []  # keyword, indentation, line number
    blocks = 0
    for number, raw in enumerate(text.splitlines(), 1):
        code = _code(raw).rstrip()
        if not code.strip():
            continue
        indent = len(code) - len(code.lstrip(" "))
        assert "\t" not in code[:indent], f"line {number}: tab indentation"
        word = re.match(r"\s*(\w*)", code)
        keyword = word[1] if word else ""
        if stack and keyword not in ("end", "elif", "else"):
            assert indent > stack[-1][1], f"line {number}: not indented inside its block: {raw!r}"
        if keyword in _OPENERS and code.endswith(":"):
            stack.append((keyword, indent, number))
            blocks += 1
        elif keyword in ("elif", "else"):
            assert code.endswith(":"), f"line {number}: {keyword} without ':'"
            assert stack, f"line {number}: {keyword} outside a block"
            assert stack[-1][0] == "if", f"line {number}: {keyword} inside {stack[-1][0]}"
            assert indent == stack[-1][1], f"line {number}: {keyword} not aligned with its if"
        elif keyword == "end":
            assert code.strip() == "end", f"line {number}: text after end"
            assert stack, f"line {number}: end without a block"
            assert indent == stack.pop()[1], f"line {number}: end not aligned with its block"
        else:
            assert not code.endswith(":"), f"line {number}: ':' ends a line that opens no block: {raw!r}"
    assert not stack, f"unclosed blocks: {stack}"
    return blocks


def _code_text(text: str) -> str:
    return "\n".join(_code(line) for line in text.splitlines())


def _numbers(text: str) -> dict[str, float]:
    """Top-level numeric constants ``UD_NAME = <number>``."""
    pattern = re.compile(r"^(UD_[A-Z0-9_]+) = (-?\d+(?:\.\d+)?)$", re.MULTILINE)
    return {name: float(value) for name, value in pattern.findall(text)}


def _table(text: str, prefix: str) -> dict[str, int]:
    return {
        name.removeprefix(prefix): int(value)
        for name, value in _numbers(text).items()
        if name.startswith(prefix)
    }


def _members(cls: type[enum.IntEnum]) -> dict[str, int]:
    return {member.name: int(member) for member in cls}


# -- rendering --------------------------------------------------------------------------------------------


def test_rendering_fills_every_placeholder(script: str) -> None:
    assert "{{" not in script
    assert "}}" not in script
    assert script.isascii()  # the controller takes ASCII only (§2.4)
    assert 'socket_open("10.0.0.7", 51003, "trajectory_socket")' in script
    assert "UD_MULT = 1000000" in script
    assert "UD_SERVO_LOOKAHEAD = 0.1\n" in script
    assert "UD_SERVO_GAIN = 300\n" in script


def test_tool_setup_lines_run_in_the_header_before_connecting(script: str) -> None:
    header = script[: script.index("# HEADER_END")]
    assert "\nset_tool_voltage(24)\nset_tool_communication(True, 115200, 0, 1, 1.5, 3.5)\n" in header


def test_empty_tool_setup_leaves_no_trace() -> None:
    text = render_control_script(ScriptParameters(HOST))
    assert "set_tool_voltage(" not in _code_text(text).split("def ud_run_command")[0]
    assert "{{" not in text


def test_rendering_is_deterministic(params: ScriptParameters, script: str) -> None:
    assert render_control_script(params) == script


def test_numbers_render_as_urscript_literals() -> None:
    text = render_control_script(ScriptParameters(HOST, servoj_lookahead=0.2, servoj_gain=512.5))
    assert "UD_SERVO_LOOKAHEAD = 0.2\n" in text
    assert "UD_SERVO_GAIN = 512.5\n" in text


def _connect_back(server_ip: str) -> tuple[list[str], dict[str, bool]]:
    """Run the script rendered for ``server_ip`` in the fake's interpreter against three loopback
    listeners until its control loop starts; the sockets in the order it reported them connected, and
    for each listener whether the script's connection reached it."""
    listeners = {name: socket.create_server(("127.0.0.1", 0)) for name in CONNECT_ORDER}
    ports = {name: listener.getsockname()[1] for name, listener in listeners.items()}
    text = render_control_script(
        ScriptParameters(
            server_ip,
            reverse_port=ports["reverse_socket"],
            trajectory_port=ports["trajectory_socket"],
            script_command_port=ports["script_command_socket"],
        )
    )
    model = load_ur_model("ur10e")
    arm = FakeArm(model, model.dh, initial_positions=(0.0, -1.57, 1.57, -1.57, -1.57, 0.0), powered=True)
    messages: list[str] = []
    host = ScriptHost(arm, step_time=0.002, version=(5, 10), message=lambda kind, text: messages.append(text))
    run = compile_program(text, series="e", version=(5, 10)).start(host)
    try:
        for _ in range(500):  # a connection on loopback completes within a cycle or two
            run.step()
            arm.step(0.002)
            if run.done or any("control active" in m for m in messages):
                break
        assert run.error is None
        connected = [m.removeprefix("urdaemon: connected ") for m in messages if "connected " in m]
        reached = {}
        for name, listener in listeners.items():
            listener.setblocking(False)
            try:
                peer, _ = listener.accept()  # queued by the kernel when the script connected
            except BlockingIOError:
                reached[name] = False
            else:
                peer.close()
                reached[name] = True
        return connected, reached
    finally:
        run.stop()
        host.close()
        for listener in listeners.values():
            listener.close()


def test_the_script_connects_back_to_the_three_rendered_endpoints_in_order() -> None:
    connected, reached = _connect_back("127.0.0.1")
    assert connected == list(CONNECT_ORDER)
    assert reached == dict.fromkeys(CONNECT_ORDER, True)


def test_host_names_are_accepted() -> None:
    text = render_control_script(ScriptParameters("daemon-pc.cell.local"))
    assert 'socket_open("daemon-pc.cell.local", 50001, "reverse_socket")' in text
    compile_program(text, series="e", version=(5, 10))
    # and the controller resolves the name when it connects
    connected, reached = _connect_back("localhost")
    assert connected == list(CONNECT_ORDER)
    assert all(reached.values())


@pytest.mark.parametrize(
    ("field", "kwargs"),
    [
        ("server_ip", {"server_ip": ""}),
        ("server_ip", {"server_ip": 'pc"; halt; "'}),
        ("server_ip", {"server_ip": "bad host"}),
        ("server_ip", {"server_ip": "::1"}),
        ("reverse_port", {"reverse_port": 0}),
        ("reverse_port", {"reverse_port": 65536}),
        ("reverse_port", {"reverse_port": True}),
        ("trajectory_port", {"trajectory_port": "50003"}),
        ("script_command_port", {"script_command_port": 50001}),
        ("servoj_lookahead", {"servoj_lookahead": 0.02}),
        ("servoj_lookahead", {"servoj_lookahead": 0.25}),
        ("servoj_lookahead", {"servoj_lookahead": float("nan")}),
        ("servoj_gain", {"servoj_gain": 99}),
        ("servoj_gain", {"servoj_gain": 2001}),
        ("servoj_gain", {"servoj_gain": False}),
        ("tool_setup", {"tool_setup": "set_tool_voltage(24)"}),
        ("tool_setup", {"tool_setup": ("a\nb",)}),
        ("tool_setup", {"tool_setup": ("textmsg({{SERVER_IP}})",)}),
        ("tool_setup", {"tool_setup": ("# HEADER_END",)}),
        ("tool_setup", {"tool_setup": ('textmsg("\u00b0")',)}),
        ("tool_setup", {"tool_setup": (1,)}),
    ],
)
def test_invalid_parameters_are_refused_naming_the_field(field: str, kwargs: dict[str, Any]) -> None:
    arguments: dict[str, Any] = {"server_ip": HOST, **kwargs}
    with pytest.raises(ValueError, match=rf"\b{field}\b"):
        ScriptParameters(**arguments)


def test_tool_setup_list_becomes_a_tuple() -> None:
    params = ScriptParameters(HOST, tool_setup=["set_tool_voltage(12)"])  # type: ignore[arg-type]
    assert params.tool_setup == ("set_tool_voltage(12)",)


def test_template_with_an_unknown_placeholder_is_refused(params: ScriptParameters) -> None:
    template = " ".join(f"{{{{{name}}}}}" for name in PLACEHOLDERS) + " {{MYSTERY}}"
    with pytest.raises(ValueError, match="MYSTERY"):
        render_template(template, params)


def test_template_missing_a_placeholder_is_refused(params: ScriptParameters) -> None:
    template = " ".join(f"{{{{{name}}}}}" for name in PLACEHOLDERS if name != "REVERSE_PORT")
    with pytest.raises(ValueError, match="REVERSE_PORT"):
        render_template(template, params)


def test_template_with_malformed_braces_is_refused(params: ScriptParameters) -> None:
    template = " ".join(f"{{{{{name}}}}}" for name in PLACEHOLDERS) + " {{A B}}"
    with pytest.raises(ValueError, match="braces"):
        render_template(template, params)


# -- structure --------------------------------------------------------------------------------------------


def test_urcap_markers_present_once_and_in_order(script: str) -> None:
    lines = [line.strip() for line in script.splitlines()]
    positions = []
    for marker in URCAP_MARKERS:
        assert lines.count(marker) == 1, marker
        positions.append(lines.index(marker))
    assert positions == sorted(positions)
    assert lines[0] == "# HEADER_BEGIN"


def test_header_and_control_loop_are_each_balanced(script: str) -> None:
    # the URCap inserts them separately (§4.3), so each part must stand on its own
    header = script[: script.index("# HEADER_END")]
    loop = script[script.index("# NODE_CONTROL_LOOP_BEGINS") : script.index("# NODE_CONTROL_LOOP_ENDS")]
    assert _check_blocks(header) > 20
    assert _check_blocks(loop) > 5
    assert _check_blocks(script) > 25


def test_block_checker_catches_mistakes() -> None:
    with pytest.raises(AssertionError):
        _check_blocks("def f():\n  if x:\n    y = 1\nend\n")
    with pytest.raises(AssertionError):
        _check_blocks("while True:\n  sync()\nend\nend\n")
    with pytest.raises(AssertionError):
        _check_blocks("thread t():\n  else:\n  end\nend\n")
    assert _check_blocks('if a: # comment:\n  textmsg("x:")\nelif b:\n  y = 2\nelse:\n  y = 3\nend\n') == 1


def test_every_read_takes_the_frame_size_of_its_link(script: str) -> None:
    code = _code_text(script)
    constants = _numbers(script)
    reads = re.findall(r'socket_read_binary_integer\(\s*(\w+)\s*,\s*"(\w+)"', code)
    assert {name for _, name in reads} == set(SOCKET_FRAME_INTS)
    for count, name in reads:
        value = int(count) if count.isdigit() else int(constants[count])
        assert value == SOCKET_FRAME_INTS[name], (count, name)
    # no other read function would respect the fixed-size framing
    assert re.findall(r"socket_read_\w+", code) == ["socket_read_binary_integer"] * len(reads)


def test_sends_and_closes_target_opened_sockets(script: str) -> None:
    code = _code_text(script)
    opened = set(re.findall(r'socket_open\([^,()]+,[^,()]+,\s*"(\w+)"\)', code))
    assert opened == set(SOCKET_FRAME_INTS)
    sends = re.findall(r'socket_send_(\w+)\([^()]*,\s*"(\w+)"\)', code)
    assert sends
    for kind, name in sends:
        assert kind == "int"  # results are one int32 each (§4.4, §4.5)
        assert name in opened
        assert name != "reverse_socket"  # the robot sends nothing on the reverse link (§4.1)
    assert set(re.findall(r'socket_close\("(\w+)"\)', code)) <= opened
    assert not re.search(r"socket_send_(string|line|byte)", code)


def test_connects_back_in_the_reference_order(script: str) -> None:
    loop = _code_text(script[script.index("# NODE_CONTROL_LOOP_BEGINS") :])
    order = re.findall(r'ud_connect\("(\w+)"\)', loop)
    assert order == list(CONNECT_ORDER)
    assert loop.index("ud_connect(") < loop.index(
        'socket_read_binary_integer(UD_REVERSE_INTS, "reverse_socket"'
    )


def test_mode_constants_match_the_daemon(script: str) -> None:
    assert _table(script, "UD_MODE_") == _members(reverse.ControlMode)


def test_action_and_result_constants_match_the_daemon(script: str) -> None:
    assert _table(script, "UD_TRAJ_") == _members(reverse.TrajectoryAction)
    assert _table(script, "UD_FREEDRIVE_") == _members(reverse.FreedriveAction)
    assert _table(script, "UD_RESULT_") == _members(trajectory_point.TrajectoryResultCode)
    assert _table(script, "UD_CONTACT_") == _members(script_command.ToolContactResultCode)
    assert _table(script, "UD_SPLINE_") == _members(trajectory_point.SplineType)
    motions = _table(script, "UD_MOTION_")
    assert motions == {name: trajectory_point.MotionType[name].value for name in ("MOVEJ", "SPLINE")}
    commands = _table(script, "UD_CMD_")
    implemented = {
        "ZERO_FTSENSOR",
        "SET_PAYLOAD",
        "SET_TOOL_VOLTAGE",
        "START_FORCE_MODE",
        "END_FORCE_MODE",
        "START_TOOL_CONTACT",
        "END_TOOL_CONTACT",
        "SET_GRAVITY",
        "SET_TCP_OFFSET",
        "SET_TARGET_PAYLOAD",
    }
    assert commands == {name: script_command.ScriptCommandId[name].value for name in implemented}
    code = _code_text(script)
    for name in implemented:
        assert f"command_id == UD_CMD_{name}:" in code, name


def test_every_thread_started_is_defined(script: str) -> None:
    code = _code_text(script)
    defined = set(re.findall(r"^thread (\w+)\(\):$", code, re.MULTILINE))
    started = set(re.findall(r"= run (\w+)\(\)", code))
    assert started == defined
    functions = set(re.findall(r"^def (\w+)\(", code, re.MULTILINE))
    called = set(re.findall(r"\b(ud_\w+)\(", code)) - defined
    assert called <= functions


def test_headless_program_arrives_as_one_def(script: str) -> None:
    robot = PrimaryConnection(Side.ROBOT)
    events = robot.receive_data(headless_program(script).encode("ascii"))
    programs = [event for event in events if isinstance(event, ProgramReceived)]
    assert len(programs) == 1
    assert programs[0].kind == "def"
    assert programs[0].name == "externalControl"
    assert 'socket_open("10.0.0.7", 51001, "reverse_socket")' in programs[0].text
    # nothing of the script leaks out of the def as a top-level command
    assert [event for event in events if isinstance(event, CommandReceived)] == [
        CommandReceived("stop program")
    ]
    # the fake controller compiles what it received as one program (5.15: the fixture's tool setup
    # calls set_tool_communication, which the builtin table only knows from 5.15 on)
    assert compile_program(programs[0].text, series="e", version=(5, 15)).kind == "def"


def test_older_controllers_get_set_payload_instead_of_set_target_payload() -> None:
    new = render_control_script(ScriptParameters(server_ip="10.0.0.2", controller_version=(5, 15, 0)))
    old = render_control_script(ScriptParameters(server_ip="10.0.0.2", controller_version=(3, 15, 7)))
    assert "set_target_payload(" in new
    assert "set_target_payload(" not in old, "CB3 / PolyScope < 5.10 has no set_target_payload"
    assert "set_payload(raw[2] / UD_MULT, ud_scaled3(raw, 3))" in old
    assert "= tool_contact(direction=" in new
    assert "= tool_contact(" not in old, "tool_contact is e-Series only"
    before_5_4 = render_control_script(ScriptParameters(server_ip="10.0.0.2", controller_version=(5, 3, 0)))
    assert "= tool_contact(" not in before_5_4, "tool_contact exists from PolyScope 5.4 on"
