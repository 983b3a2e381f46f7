"""What the ``urdaemon`` command line accepts: every command's arguments and help texts.

The commands of ``TOOL_MODULES`` bring their own parsers; each command's work is done by the module
that ``entry.py`` dispatches it to.
"""

from __future__ import annotations

import argparse
import importlib
import json
import re
import sys
from collections.abc import Sequence
from typing import Any

from urdaemon import __version__, cli_args

__all__ = ["NUMBER_LIST_OPTIONS", "TOOL_MODULES", "build_parser", "join_number_lists"]

NUMBER_LIST_OPTIONS: frozenset[str] = frozenset({"--joints", "--pose", "--wall"})
"""Options whose value is a comma-separated list of numbers, which may start with a minus sign."""
_NEGATIVE = re.compile(r"-[0-9.]")

TOOL_MODULES: tuple[str, ...] = (
    "urdaemon.introspect.doctor_command",
    "urdaemon.foxglove_bridge.command",
    "urdaemon.introspect.list_info_hz",
    "urdaemon.recording.record_command",
    "urdaemon.replay.command",
    "urdaemon.router",
)
"""Modules that add commands of their own: each has ``add_parsers(sub)``, whose parsers set ``run``
(``args`` → exit code) as a default; the module imports nothing heavy until ``run`` is called."""


def join_number_lists(words: Sequence[str]) -> list[str]:
    """``--wall -0.69,0.2,...`` → ``--wall=-0.69,0.2,...`` for the options of ``NUMBER_LIST_OPTIONS``:
    argparse takes a separate word starting with '-' for an option unless it is one plain number, so a
    list whose first number is negative needs the ``=``. Only a word starting with '-' and a digit or
    '.' is joined; every other word, and every other option, is left as it is."""
    out: list[str] = []
    i = 0
    while i < len(words):
        word = words[i]
        if word in NUMBER_LIST_OPTIONS and i + 1 < len(words) and _NEGATIVE.match(words[i + 1]):
            out.append(f"{word}={words[i + 1]}")
            i += 2
        else:
            out.append(word)
            i += 1
    return out


class _Parser(argparse.ArgumentParser):
    """The top-level parser: joins the negative number lists (``join_number_lists``) before parsing."""

    def parse_known_args(  # type: ignore[override]
        self, args: Sequence[str] | None = None, namespace: argparse.Namespace | None = None
    ) -> tuple[argparse.Namespace, list[str]]:
        words = sys.argv[1:] if args is None else args
        return super().parse_known_args(join_number_lists(words), namespace)


def build_parser() -> argparse.ArgumentParser:
    """The ``urdaemon`` parser: every command, in the order ``--help`` lists them."""
    parser = _Parser(prog="urdaemon", description="Drive a cell of Universal Robots arms over Zenoh.")
    parser.add_argument("--version", action="version", version=f"urdaemon {__version__}")
    parser.add_argument("-v", "--verbose", action="store_true", help="log debug messages")
    sub = parser.add_subparsers(dest="command", required=True)
    _add_serve(sub)
    _add_fake_robot(sub)
    _add_cell_tools(sub)
    _add_client_tools(sub)
    _add_goal_tools(sub)
    _add_calibration(sub)
    _add_view(sub)
    for name in TOOL_MODULES:
        importlib.import_module(name).add_parsers(sub)
    return parser


def _add_view(sub: Any) -> None:
    """``view``: the live 3-D view of a cell in the browser (urdaemon/view/, the ``view`` extra)."""
    from urdaemon.client import DEFAULT_ENDPOINT

    view = sub.add_parser(
        "view", help="serve a live 3-D view of a cell with joint sliders, jog and stop (the view extra)"
    )
    source = view.add_mutually_exclusive_group()
    source.add_argument("--connect", default=None, help=f"daemon endpoint (default {DEFAULT_ENDPOINT})")
    source.add_argument(
        "--config", default=None, help="cell file: start it with every robot on the mock backend and view it"
    )
    view.add_argument("--zenoh-config", metavar="FILE", default=None, help="Zenoh JSON5 config (e.g. TLS)")
    view.add_argument("--cell", default=None, help="cell name (default: the one cell served)")
    view.add_argument("--host", default="127.0.0.1", help="address the page is served on (default 127.0.0.1)")
    view.add_argument(
        "--port",
        type=_view_port_arg,
        default=8080,
        help="port of the page (default 8080; taken: the next free one; 0: any free port)",
    )


def _view_port_arg(text: str) -> int:
    """``view --port``: 0 (any free port) or a port number."""
    return 0 if text.strip() == "0" else cli_args.port(allow_zero=False)(text)


def _add_serve(sub: Any) -> None:
    """``serve``: run the daemon for a cell file."""
    serve = sub.add_parser("serve", help="run the daemon for a cell file")
    serve.add_argument("--config", required=True, help="cell file (YAML)")
    serve.add_argument(
        "--listen", action="append", help="Zenoh listen endpoint, overrides the cell file (repeatable)"
    )


def _add_fake_robot(sub: Any) -> None:
    """``fake-robot``: the fake controllers and their fault options."""
    fake = sub.add_parser(
        "fake-robot", help="serve fake UR controllers (RTDE, primary, dashboard) on loopback"
    )
    source = fake.add_mutually_exclusive_group(required=True)
    source.add_argument("--model", help="UR model of one fake robot, e.g. ur10e")
    source.add_argument(
        "--config", help="cell file: one fake for every robot with backend 'ur', at its address"
    )
    fake.add_argument("--address", default="127.0.0.5", help="address of the one fake (default 127.0.0.5)")
    fake.add_argument("--controller-version", default="5.15.0", help="e.g. 5.15.0 (e-Series) or 3.15.7 (CB3)")
    fake.add_argument("--calibration", help="calibration file: the fake reports these DH parameters")
    fake.add_argument("--powered", action="store_true", help="start powered on with brakes released")
    fake.add_argument(
        "--urcap", metavar="HOST:PORT", help="External Control URCap mode: play fetches the script from here"
    )
    fake.add_argument(
        "--refuse", action="append", default=[], metavar="SERVICE", help="refuse connections to a service"
    )
    fake.add_argument(
        "--split", action="append", default=[], metavar="SERVICE", help="split every write of a service"
    )
    fake.add_argument(
        "--delay", type=cli_args.seconds(True), default=0.0, help="delay every write by S seconds"
    )
    fake.add_argument(
        "--late-start", type=cli_args.seconds(True), default=0.0, help="start listening only after S seconds"
    )
    fake.add_argument(
        "--phases",
        choices=("aligned", "spread"),
        default="aligned",
        help="several fakes: tick together, one burst of RTDE packages per period (default), or spread "
        "over the period, each at its own phase like independent controllers",
    )
    fake.add_argument(
        "--programs",
        metavar="DIR",
        help="program directory: 'load NAME' resolves NAME under it; URScript files (.script) and "
        "PolyScope programs (.urp, translated to URScript) play; the default External Control program "
        "is always there",
    )
    fake.add_argument(
        "--wall",
        action="append",
        default=[],
        metavar="X,Y,Z,NX,NY,NZ[,K]",
        help="a wall every fake arm touches: a point and the normal toward the free side in the base frame "
        "(m), optionally its stiffness K in N/m (default 20000); try tool contact and force mode on it",
    )


def _add_cell_tools(sub: Any) -> None:
    """``check`` and ``urdf``: read a cell file offline."""
    check = sub.add_parser("check", help="validate a cell file and print a summary")
    check.add_argument("--config", required=True)
    check.add_argument(
        "--skip-devices",
        action="store_true",
        help="do not look for servo arms' I²C buses and serial ports (checking on another machine "
        "than the one that drives them); serve still refuses them when missing",
    )

    urdf = sub.add_parser("urdf", help="print the cell URDF")
    urdf.add_argument("--config", required=True)

    # its arguments are transport_security's own (parsed there: see entry.py), not loaded for every command
    sub.add_parser(
        "client-config",
        help="write a client's Zenoh config (TLS certificates) for a cell file; use it with --zenoh-config",
        add_help=False,
    )


def _add_client_tools(sub: Any) -> None:
    """``echo``, ``service``, ``dashboard``: Zenoh clients of a serving daemon."""
    from urdaemon.publish import services

    echo = sub.add_parser("echo", help="print samples of a key expression as JSON lines")
    echo.add_argument("key", help="key expression, e.g. demo_cell/alice/joint_states")
    echo.add_argument(
        "--count", type=cli_args.whole_number(0), default=0, help="stop after N samples (0: until Ctrl-C)"
    )
    echo.add_argument(
        "--timeout",
        type=cli_args.seconds(True),
        default=None,
        help=(
            "give up after S seconds without a sample (0: never); not given: wait while something "
            "publishes on the key, give up after 3 s when nothing does"
        ),
    )
    echo.add_argument("--field", default=None, help="print only this field, e.g. position or tcp.pose.0")
    echo.add_argument(
        "--rate", type=cli_args.rate_hz, default=None, help="at most HZ samples a second of each key"
    )
    _connect_arg(echo)

    call = sub.add_parser(
        "service",
        help=f"call a robot service ({', '.join(services.names())}) and print the reply",
        description=_services_listed(),
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    call.add_argument("robot")
    call.add_argument("name", help="service name, e.g. set_io")
    call.add_argument(
        "body",
        nargs="?",
        default="{}",
        help='request as JSON, e.g. \'{"kind": "digital", "pin": 3, "value": true}\'',
    )
    call.add_argument("--cell", default=None)
    call.add_argument("--timeout", type=cli_args.seconds(False), default=60.0, help="seconds (default 60)")
    _connect_arg(call)

    board = sub.add_parser("dashboard", help="send a dashboard command to a robot and print the reply")
    board.add_argument("robot")
    board.add_argument(
        "words", nargs="+", metavar="COMMAND", help="e.g. power on | brake release | robotmode"
    )
    board.add_argument("--cell", default=None)
    _connect_arg(board)


def _services_listed() -> str:
    """``service``'s description: every service, its request and what it does (publish/services.py)."""
    from urdaemon.publish import services

    lines = ["Call a robot service and print its reply. The services:", ""]
    for entry in (*services.SERVICES, services.STOP):
        request = "no request" if entry.request is None else f"request: {_fields(entry.request)}"
        lines.append(f"  {entry.name}: {entry.summary} ({request})")
    return "\n".join(lines)


def _fields(request: type) -> str:
    """A request type's fields as the message names them, optional ones with their default."""
    import dataclasses

    from urdaemon.publish.service_requests import WIRE_NAMES

    shown = []
    for item in dataclasses.fields(request):
        name = WIRE_NAMES.get(item.name, item.name)
        shown.append(
            name if item.default is dataclasses.MISSING else f"{name}? (default {json.dumps(item.default)})"
        )
    return ", ".join(shown)


def _add_goal_tools(sub: Any) -> None:
    """``move``, ``teleop``, ``cancel``, ``stop`` and ``lease``: a robot's goals and commands."""
    _add_move(sub)
    _add_teleop(sub)

    cancel = sub.add_parser("cancel", help="cancel a robot's goal (default: the active one)")
    cancel.add_argument("robot")
    cancel.add_argument(
        "--goal", default=None, metavar="ID", help="the goal to cancel (default: the active one)"
    )
    cancel.add_argument("--cell", default=None)
    _connect_arg(cancel)

    stop = sub.add_parser("stop", help="stop a robot, or with no robot every robot of the cell")
    stop.add_argument("robot", nargs="?", default=None, help="the robot (default: the whole cell)")
    stop.add_argument("--cell", default=None, help="cell name (default: the one cell served)")
    _connect_arg(stop)

    lease = sub.add_parser("lease", help="show who holds a robot's command lease, or take it over")
    lease.add_argument("robot")
    lease.add_argument(
        "--take-over",
        metavar="REASON",
        default=None,
        help="take the lease from its holder (the robot stops; REASON is logged and published), "
        "then release it",
    )
    lease.add_argument("--cell", default=None)
    _connect_arg(lease)


def _add_move(sub: Any) -> None:
    """``move``: to joint positions or a TCP pose (a straight line with ``--linear``)."""
    move = sub.add_parser(
        "move", help="move a robot to joint positions or a TCP pose and wait for the result"
    )
    move.add_argument("robot")
    target = move.add_mutually_exclusive_group(required=True)
    target.add_argument("--joints", help="comma-separated joint positions (rad), controller order")
    target.add_argument(
        "--pose",
        action="append",
        metavar="X,Y,Z,RX,RY,RZ",
        help="TCP pose: metres and a rotation vector (rad), in --frame; with --linear repeat it for "
        "a path through several poses",
    )
    move.add_argument(
        "--linear", action="store_true", help="with --pose: a straight TCP line (from rest), not a joint move"
    )
    move.add_argument(
        "--frame",
        choices=("base", "world"),
        default="base",
        help="the frame of --pose: the robot's base (default, as tcp_pose) or the cell's world",
    )
    move.add_argument(
        "--speed", type=float, default=None, help="with --linear: TCP speed in m/s (default: the cell's)"
    )
    move.add_argument(
        "--duration", type=cli_args.seconds(False), default=None, help="seconds (default: time-optimal)"
    )
    move.add_argument(
        "--cell", default=None, help="cell name (default: found from the robot's liveliness token)"
    )
    move.add_argument("--velocity-scale", type=float, default=1.0, help="within (0, 1], default 1")
    _connect_arg(move)


def _add_teleop(sub: Any) -> None:
    """``teleop``: jog a robot's TCP from the keyboard."""
    from urdaemon import teleop_keys

    keys = "\n".join(f"  {part}" for part in teleop_keys.HELP.split("   "))
    teleop = sub.add_parser(
        "teleop",
        help="jog a robot's TCP from the keyboard (twist commands)",
        description=f"Jog a robot's TCP from the keyboard.\n\n{keys}\n\nA key moves the TCP while it "
        f"is held (the terminal's auto-repeat); {teleop_keys.RELEASE_S:g} s without a key: zero twist.",
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    teleop.add_argument("robot")
    teleop.add_argument(
        "--speed",
        type=float,
        default=teleop_keys.DEFAULT_SPEED,
        help=f"TCP speed in m/s at start (default {teleop_keys.DEFAULT_SPEED:g}; "
        f"{teleop_keys.MIN_SPEED:g}..{teleop_keys.MAX_SPEED:g}; i/k change it)",
    )
    teleop.add_argument(
        "--frame", choices=teleop_keys.FRAMES, default="base", help="twist frame at start (b toggles it)"
    )
    teleop.add_argument("--cell", default=None)
    _connect_arg(teleop)


def _add_calibration(sub: Any) -> None:
    """``calibration``: read a controller's calibration into a file."""
    calibration = sub.add_parser(
        "calibration", help="read a UR controller's kinematics calibration into a calibration file"
    )
    calibration.add_argument("--address", required=True, help="the controller's address")
    calibration.add_argument("--output", required=True, help="calibration file to write (YAML)")
    calibration.add_argument(
        "--port",
        type=cli_args.port(allow_zero=False),
        default=None,
        help="primary interface port (default 30001)",
    )
    calibration.add_argument(
        "--timeout", type=cli_args.seconds(False), default=None, help="give up after S seconds (default 10)"
    )


def _connect_arg(parser: argparse.ArgumentParser) -> None:
    from urdaemon.client import DEFAULT_ENDPOINT

    parser.add_argument(
        "--connect", default=DEFAULT_ENDPOINT, help=f"daemon endpoint (default {DEFAULT_ENDPOINT})"
    )
    parser.add_argument(
        "--zenoh-config",
        metavar="FILE",
        default=None,
        help="Zenoh JSON5 config to start from, e.g. TLS certificates (the endpoint is still --connect)",
    )
