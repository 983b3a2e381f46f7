"""The ``urdaemon`` command: serve, check, urdf, echo, move, teleop, cancel, stop, service, dashboard,
lease, view.

Client commands that command a robot (``move``, ``teleop``, ``cancel``, ``service``, ``dashboard``)
acquire its command lease first and release it when they exit; ``stop`` never needs it; ``lease``
shows or takes it over. Each connects with ``--connect`` and, for TLS, ``--zenoh-config``.

Exit codes: 0 success; 1 a command failed (goal aborted, no answer, refused: also for the lease, with
the daemon's reason naming the holder); 2 bad input (config, arguments; ``teleop`` without a
terminal); 130 ``move`` interrupted by Ctrl-C (its goal canceled first; ``teleop`` quits on Ctrl-C
with 0, the robot stopping).
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import importlib
import json
import logging
import math
import signal
import sys
from collections.abc import Awaitable, Callable, Coroutine, Sequence
from functools import partial
from typing import TYPE_CHECKING, Any

from urdaemon import __version__, cli_args

if TYPE_CHECKING:
    from urdaemon.cell.config import Cell
    from urdaemon.client import Client, RobotClient
    from urdaemon.teleop_keys import TeleopKeys

from urdaemon.errors import ConfigError, DescriptionError, GoalRejected, UrDaemonError

__all__ = ["main"]

EXIT_OK = 0
EXIT_FAILED = 1
EXIT_BAD_INPUT = 2
EXIT_INTERRUPTED = 130
"""``move`` interrupted by Ctrl-C (after it canceled its goal), as shells report SIGINT."""
TOOL_MODULES: tuple[str, ...] = (
    "urdaemon.doctor.command",
    "urdaemon.foxglove_bridge.command",
    "urdaemon.introspect.commands",
    "urdaemon.recording.record_command",
    "urdaemon.replay.command",
    "urdaemon.router",
)
"""Modules that add commands of their own: each has ``add_parsers(sub)``, whose parsers set ``run``
(``args`` → exit code) as a default; the module imports nothing heavy until ``run`` is called."""
STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)
"""Each stops ``serve`` and ``fake-robot`` cleanly; a repeated one while stopping is only logged."""


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="urdaemon", description="Drive a cell of Universal Robots arms over Zenoh."
    )
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

    # its arguments are transport_security's own (parsed there: see main), not loaded for every command
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


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the console script."""
    from urdaemon.logs import setup_logging, shutdown_logging

    words = sys.argv[1:] if argv is None else list(argv)
    if words[:1] == ["client-config"]:
        from urdaemon.transport_security import client_config_main

        return client_config_main(words[1:])
    args = _parser().parse_args(_join_option_values(words))
    args.owns_process = argv is None  # run as the ``urdaemon`` command, not called with arguments
    installed = setup_logging(args.verbose)  # a bounded queue to stderr: never blocks the loop
    try:
        return _dispatch(args)
    finally:
        if installed is not None:
            shutdown_logging()


def _dispatch(args: argparse.Namespace) -> int:
    try:
        run: Callable[[argparse.Namespace], int] | None = getattr(args, "run", None)
        if run is not None:
            return run(args)
        if args.command == "check":
            return _check(args.config, check_devices=not args.skip_devices)
        if args.command == "urdf":
            return _urdf(args.config)
        if args.command == "serve":
            return _serve(args.config, args.listen, args.owns_process)
        if args.command == "fake-robot":
            return _fake_robot(args)
        if args.command == "echo":
            return asyncio.run(_echo(args))
        if args.command == "move":
            return asyncio.run(_move(args))
        if args.command == "teleop":
            return asyncio.run(_teleop(args))
        if args.command == "cancel":
            return asyncio.run(_cancel(args))
        if args.command == "stop":
            return asyncio.run(_stop(args))
        if args.command == "dashboard":
            return asyncio.run(_dashboard(args))
        if args.command == "service":
            return asyncio.run(_call_service(args))
        if args.command == "lease":
            return asyncio.run(_lease(args))
        if args.command == "calibration":
            return _calibration(args)
        if args.command == "view":
            from urdaemon.view.command import view_main

            return view_main(args)
    except (ConfigError, DescriptionError) as err:
        print(f"error: {err}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except KeyboardInterrupt:
        return EXIT_OK
    return EXIT_BAD_INPUT


def _join_option_values(argv: list[str]) -> list[str]:
    """``--joints -0.5,1`` → ``--joints=-0.5,1`` (``--pose`` too): argparse would read a leading '-'
    as an option."""
    out: list[str] = []
    i = 0
    while i < len(argv):
        if argv[i] in ("--joints", "--pose") and i + 1 < len(argv):
            out.append(f"{argv[i]}={argv[i + 1]}")
            i += 2
        else:
            out.append(argv[i])
            i += 1
    return out


def _bad_endpoint(endpoint: str) -> str | None:
    """Why ``endpoint`` is not a Zenoh endpoint (None when it looks like one)."""
    import re

    from urdaemon.cell.config import ENDPOINT_PATTERN

    if not re.match(ENDPOINT_PATTERN, endpoint):
        return f"--connect {endpoint!r} is not a Zenoh endpoint like tcp/127.0.0.1:7447"
    return None


def _bad_connection(args: argparse.Namespace) -> str | None:
    """Why ``--connect`` or ``--zenoh-config`` cannot be used (None when fine)."""
    import os

    problem = _bad_endpoint(args.connect)
    if problem is None and args.zenoh_config is not None and not os.path.isfile(args.zenoh_config):
        problem = f"--zenoh-config {args.zenoh_config!r} is not a file"
    return problem


async def _connect(args: argparse.Namespace) -> Client:
    """A client of ``--connect`` (with ``--zenoh-config`` as its base) whose leases name this command."""
    from urdaemon.client import Client, default_holder

    return await Client.connect(
        args.connect, config_file=args.zenoh_config, holder=default_holder(f"urdaemon {args.command}")
    )


def _bad_target(args: argparse.Namespace) -> str | None:
    """Why the endpoint, robot or cell name of a client command cannot be used (None when fine)."""
    import re

    from urdaemon.cell.config import NAME_PATTERN

    problem = _bad_connection(args)
    if problem is None and not re.match(NAME_PATTERN, args.robot):
        problem = f"{args.robot!r} is not a robot name (lower-case letters, digits, '_')"
    return problem or _bad_cell_name(args.cell)


def _fail(err: BaseException, prefix: str = "") -> int:
    from urdaemon.client import zenoh_message

    print(f"error: {prefix}{zenoh_message(err)}", file=sys.stderr)
    return EXIT_FAILED


def _fake_robot(args: argparse.Namespace) -> int:
    from urdaemon.fakeur.cli import run_fakes

    return run_fakes(args)


def _check(path: str, *, check_devices: bool = True) -> int:
    from urdaemon.cell import load_cell, summarize
    from urdaemon.daemon import describe_cell, make_backend

    try:
        cell = load_cell(path)
        description = describe_cell(cell)
        for robot in cell.robots:  # what `serve` would refuse, `check` refuses too
            make_backend(robot, description.limits[robot.name], None, cell.cell, check_devices=check_devices)
        busy = _busy_ports(cell, path)  # serve would retry these forever
        if busy:
            raise ConfigError("\n".join(busy), errors=busy)
    except ConfigError as err:
        print(f"{len(err.errors)} error(s):", file=sys.stderr)
        for line in err.errors:
            print(f"  {line}", file=sys.stderr)
        return EXIT_BAD_INPUT
    print(summarize(cell))
    for name, limits in description.limits.items():
        print(f"  {name}: {limits.dof} joints: {', '.join(limits.names)}")
    print("ok")
    return EXIT_OK


def _busy_ports(cell: Cell, source: str) -> list[str]:
    """Callback ports ``serve`` would listen on (robots that command) that something else holds now
    (each bound and released at once). ``serve`` fails at once when its Zenoh port is taken, but
    would retry a taken callback port forever."""
    import socket

    from urdaemon.backends.ur.route import listen_plan
    from urdaemon.cell.config import UrOptions
    from urdaemon.errors import BackendError

    wanted: list[tuple[str, str, int]] = []
    problems = []
    for i, robot in enumerate(cell.robots):
        if not robot.listens or robot.address is None:
            continue
        try:  # where serve's servers would listen: the interface that reaches the robot, by default
            host = listen_plan(robot.address, robot.ur or UrOptions()).address
        except BackendError as err:  # serve would retry this until the network lets it through
            problems.append(f"{source}: robots[{i}] ({robot.name}): {err}")
            continue
        for role, port in robot.ports.as_dict().items():
            wanted.append((f"robots[{i}] ({robot.name}).ports.{role}", host, port))
    for where, host, port in wanted:
        family = socket.AF_INET6 if ":" in host else socket.AF_INET
        try:
            with socket.socket(family, socket.SOCK_STREAM) as sock:
                sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)  # as the servers do
                sock.bind((host, port))
        except OSError as err:
            problems.append(f"{source}: {where}: cannot listen on {host}:{port}: {err.strerror or err}")
    return problems


def _urdf(path: str) -> int:
    from urdaemon.cell import load_cell
    from urdaemon.description import build_cell_urdf

    sys.stdout.write(build_cell_urdf(load_cell(path)))
    return EXIT_OK


def _serve(path: str, listen: list[str] | None, owns_process: bool) -> int:
    from urdaemon.cell import load_cell
    from urdaemon.daemon import Daemon

    cell = load_cell(path)
    daemon = Daemon(cell, listen=tuple(listen) if listen else None)
    previous = None if owns_process else stop_signal_handlers()

    async def run() -> None:
        stop = asyncio.Event()
        stop_on_signals(stop, f"cell {cell.cell!r}")
        await daemon.run(stop)

    try:
        _run_loop(run())
    except (ConfigError, DescriptionError):
        raise  # bad input found as the robots start (a servo arm's missing device): exit 2, as check does
    except UrDaemonError as err:
        return _fail(err)
    except OSError as err:  # e.g. a port in use: say which, no traceback
        print(f"error: {err.strerror or err}", file=sys.stderr)
        return EXIT_FAILED
    except Exception as err:
        import zenoh

        if isinstance(err, zenoh.ZError):  # e.g. the listen endpoint is taken
            return _fail(err, "Zenoh: ")
        raise
    finally:
        end_stop_signals(previous)
    return EXIT_OK


def stop_on_signals(stop: asyncio.Event, what: str) -> None:
    """SIGINT, SIGTERM and SIGHUP set ``stop`` (a clean stop: every goal ends with a result).

    A repeated signal while stopping is logged and otherwise ignored, so it cannot cut the clean stop
    short; the handlers stay after the loop has ended, so a signal during the process's exit is
    ignored too (asyncio's own handlers fall back to the default, which kills the process). Call it
    on the running loop, in the main thread (elsewhere it does nothing).
    """
    import threading

    if threading.current_thread() is not threading.main_thread():
        return
    loop = asyncio.get_running_loop()
    log = logging.getLogger("urdaemon")

    def deliver(signum: int) -> None:
        name = signal.Signals(signum).name
        if stop.is_set():
            log.warning("%s: %s is already stopping cleanly (SIGKILL would skip that)", name, what)
            return
        log.info("%s: stopping %s", name, what)
        stop.set()

    def handler(signum: int, frame: object) -> None:
        # RuntimeError: the loop has ended: the clean stop is done and the process exits
        with contextlib.suppress(RuntimeError):
            loop.call_soon_threadsafe(deliver, signum)

    for sig in STOP_SIGNALS:
        signal.signal(sig, handler)


def stop_signal_handlers() -> dict[signal.Signals, Any]:
    """The stop signals' handlers now, to put back with ``end_stop_signals`` (main thread only)."""
    import threading

    if threading.current_thread() is not threading.main_thread():
        return {}
    return {sig: signal.getsignal(sig) for sig in STOP_SIGNALS}


def end_stop_signals(previous: dict[signal.Signals, Any] | None) -> None:
    """After a clean stop. A command that owns its process (``previous`` None: run as ``urdaemon``)
    ignores the stop signals for the rest of the exit (Python resets its own handlers to the default,
    fatal one while it finalizes; an ignored signal stays ignored). Run in-process (``main`` given
    its arguments: a test, a program), the handlers ``previous`` are put back instead: an ignored
    SIGINT would outlive the command, and every process started afterwards would inherit it
    (Ctrl-C would no longer stop a ``urdaemon move`` started by the same test worker)."""
    import threading

    if threading.current_thread() is not threading.main_thread():
        return
    for sig in STOP_SIGNALS:
        handler = signal.SIG_IGN if previous is None else previous.get(sig)
        if handler is not None:
            signal.signal(sig, handler)


def _run_loop(main: Coroutine[Any, Any, None]) -> None:
    """Run ``main`` on asyncio, or on uvloop when ``URDAEMON_LOOP=uvloop`` and uvloop is installed.

    Opt-in: measured on the 2-core VM it made no clear difference (docs/performance.md). uvloop's
    ``loop.time()`` has 1 ms resolution; nothing in urdaemon measures with it.
    """
    import os

    if os.environ.get("URDAEMON_LOOP", "").lower() == "uvloop":
        try:
            import uvloop
        except ImportError:
            print("warning: URDAEMON_LOOP=uvloop but uvloop is not installed; using asyncio", file=sys.stderr)
        else:
            uvloop.run(main)
            return
    asyncio.run(main)


async def _echo(args: argparse.Namespace) -> int:
    import zenoh

    from urdaemon.client import zenoh_message
    from urdaemon.introspect.echo import echo_command

    problem = _bad_connection(args)
    try:
        zenoh.KeyExpr(args.key)
    except zenoh.ZError as err:
        problem = f"{args.key!r} is not a valid key expression: {zenoh_message(err)}"
    if problem is None and args.field is not None and not all(args.field.split(".")):
        problem = f"--field {args.field!r} is not a field path like position or tcp.pose.0"
    if problem is not None:
        print(f"error: {problem}", file=sys.stderr)
        return EXIT_BAD_INPUT
    return await echo_command(args)


SERVICE_NAME = r"^[a-z_]{1,40}$"


async def _call_service(args: argparse.Namespace) -> int:
    import re

    problem = _bad_target(args)
    if problem is None and not re.match(SERVICE_NAME, args.name):
        problem = f"{args.name!r} is not a service name"
    body: object = None
    if problem is None:
        try:
            body = json.loads(args.body)
        except json.JSONDecodeError as err:
            problem = f"the request is not JSON: {err}"
    if problem is None and not isinstance(body, dict):
        problem = "the request must be a JSON object"
    if problem is not None or not isinstance(body, dict):
        print(f"error: {problem}", file=sys.stderr)
        return EXIT_BAD_INPUT
    request = body
    reply = await _ask_robot(args, lambda robot: robot.call(args.name, request, timeout=args.timeout))
    if isinstance(reply, int):
        return reply
    print(json.dumps(reply))
    return EXIT_OK if reply.get("ok") else EXIT_FAILED


async def _ask_robot(
    args: argparse.Namespace, ask: Callable[[RobotClient], Awaitable[dict[str, Any]]]
) -> dict[str, Any] | int:
    """Connect to ``--connect``, find ``args.robot`` and return ``ask(robot)``'s reply, or the exit
    code after saying what failed (the endpoint, or the robots there)."""
    try:
        async with await _connect(args) as client:
            robot = await client.robot(args.robot, cell=args.cell)
            return await ask(robot)
    except UrDaemonError as err:
        return _fail(err)


async def _dashboard(args: argparse.Namespace) -> int:
    problem = _bad_target(args)
    if problem is not None:
        print(f"error: {problem}", file=sys.stderr)
        return EXIT_BAD_INPUT
    reply = await _ask_robot(args, lambda robot: robot.dashboard(" ".join(args.words)))
    if isinstance(reply, int):
        return reply
    if "reply" in reply:
        print(reply["reply"])
    else:
        print(f"error: {reply.get('reason', 'refused')}", file=sys.stderr)
    return EXIT_OK if reply.get("ok") else EXIT_FAILED


async def _stop(args: argparse.Namespace) -> int:
    """``urdaemon stop [ROBOT]``: the robot's stop, or the cell's (every robot) without one."""
    problem = _bad_target(args) if args.robot is not None else _bad_cell(args)
    if problem is not None:
        print(f"error: {problem}", file=sys.stderr)
        return EXIT_BAD_INPUT
    if args.robot is not None:
        reply = await _ask_robot(args, lambda robot: robot.stop())
    else:
        try:
            async with await _connect(args) as client:
                reply = await client.stop_cell(args.cell)
        except UrDaemonError as err:
            return _fail(err)
    if isinstance(reply, int):
        return reply
    print(json.dumps(reply))
    return EXIT_OK if reply.get("ok") else EXIT_FAILED


def _bad_cell(args: argparse.Namespace) -> str | None:
    """Why the endpoint or cell name of a cell-wide command cannot be used (None when fine)."""
    return _bad_connection(args) or _bad_cell_name(args.cell)


def _bad_cell_name(cell: str | None) -> str | None:
    """Why ``--cell`` cannot be used (None when fine, or not given)."""
    import re

    from urdaemon.cell.config import CELL_NAME_PATTERN

    if cell is not None and not re.match(CELL_NAME_PATTERN, cell):
        return f"--cell {cell!r} is not a cell name"
    return None


async def _cancel(args: argparse.Namespace) -> int:
    problem = _bad_target(args)
    if problem is not None:
        print(f"error: {problem}", file=sys.stderr)
        return EXIT_BAD_INPUT
    reply = await _ask_robot(args, lambda robot: robot.cancel(args.goal))
    if isinstance(reply, int):
        return reply
    print(json.dumps(reply))
    return EXIT_OK if reply.get("canceled") else EXIT_FAILED


GoalSender = Callable[["RobotClient"], Awaitable[Any]]
"""What ``move`` sends: the goal for the robot, as a call of its client."""


def _move_problem(args: argparse.Namespace) -> tuple[GoalSender | None, str | None]:
    """The goal ``move``'s arguments ask for, or why they cannot be used."""
    if not (math.isfinite(args.velocity_scale) and 0 < args.velocity_scale <= 1):
        return None, f"--velocity-scale must be within (0, 1], got {args.velocity_scale}"
    if args.joints is not None:
        if args.linear:
            return None, "--linear moves to --pose values, not --joints"
        joints, problem = _numbers(args.joints, "--joints", None)
        send: GoalSender = partial(_send_move, joints, args)
        return (None, problem) if problem else (send, _bad_target(args))
    poses = []
    for text in args.pose:
        pose, problem = _numbers(text, "--pose", 6)
        if problem is not None:
            return None, problem
        poses.append(pose)
    if not args.linear:
        return _pose_goal(poses, args)
    if args.duration is not None or args.velocity_scale != 1.0:
        return None, "--duration and --velocity-scale are for joint moves; --linear takes --speed (m/s)"
    if args.speed is not None and not (math.isfinite(args.speed) and args.speed > 0):
        return None, f"--speed must be a number of m/s > 0, got {args.speed}"
    return partial(_send_linear, poses, args), _bad_target(args)


def _pose_goal(poses: list[list[float]], args: argparse.Namespace) -> tuple[GoalSender | None, str | None]:
    if len(poses) > 1:
        return None, "several --pose make a path: add --linear (a joint move goes to one pose)"
    if args.speed is not None:
        return None, "--speed (m/s) is for --linear; a pose move takes --duration or --velocity-scale"
    return partial(_send_pose, poses[0], args), _bad_target(args)


def _numbers(text: str, option: str, count: int | None) -> tuple[list[float], str | None]:
    """``text``'s comma-separated finite numbers (``count`` of them when given), or why not."""
    try:
        values = [float(v) for v in text.split(",")]
    except ValueError:
        return [], f"{option} must be comma-separated numbers, got {text!r}"
    if not all(math.isfinite(v) for v in values):
        return [], f"{option} must be finite numbers"
    if count is not None and len(values) != count:
        return [], f"{option} needs {count} numbers (x,y,z in m, rx,ry,rz in rad), got {len(values)}"
    return values, None


async def _send_move(joints: list[float], args: argparse.Namespace, robot: RobotClient) -> Any:
    return await robot.move(joints, duration=args.duration, velocity_scale=args.velocity_scale)


async def _send_pose(pose: list[float], args: argparse.Namespace, robot: RobotClient) -> Any:
    return await robot.move_pose(
        pose, frame=args.frame, duration=args.duration, velocity_scale=args.velocity_scale
    )


async def _send_linear(poses: list[list[float]], args: argparse.Namespace, robot: RobotClient) -> Any:
    return await robot.move_linear(poses, frame=args.frame, speed=args.speed)


async def _move(args: argparse.Namespace) -> int:
    send, problem = _move_problem(args)
    if problem is not None or send is None:
        print(f"error: {problem}", file=sys.stderr)
        return EXIT_BAD_INPUT
    try:
        client = await _connect(args)
    except UrDaemonError as err:
        return _fail(err)
    async with client:
        try:
            robot = await client.robot(args.robot, cell=args.cell)
            # sent as a task of its own, so that Ctrl-C while the accept reply is on its way does not
            # lose the reply: the goal it names is canceled (_cancel_when_answered)
            sending = asyncio.ensure_future(send(robot))
            try:
                goal = await asyncio.shield(sending)
            except asyncio.CancelledError:
                return await _cancel_when_answered(sending)
        except GoalRejected as err:
            print(f"rejected: {err.reason}", file=sys.stderr)
            return EXIT_FAILED
        except UrDaemonError as err:
            return _fail(err)
        print(f"goal {goal.goal_id} accepted, planned {goal.duration:.2f} s", file=sys.stderr)
        bar = _ProgressBar(sys.stderr)
        try:
            return await _follow(goal, bar)
        except asyncio.CancelledError:  # Ctrl-C: asyncio cancels this task; the robot must stop too
            bar.end()
            return await _cancel_on_interrupt(goal)


async def _teleop(args: argparse.Namespace) -> int:
    """``urdaemon teleop ROBOT``: keys to twists in a raw terminal until a quit key (teleop.py)."""
    from urdaemon import teleop_keys

    problem = _bad_target(args)
    if problem is None and not (
        math.isfinite(args.speed) and teleop_keys.MIN_SPEED <= args.speed <= teleop_keys.MAX_SPEED
    ):
        problem = f"--speed must be within {teleop_keys.MIN_SPEED:g}..{teleop_keys.MAX_SPEED:g} m/s"
    if problem is None and not sys.stdin.isatty():
        problem = "teleop reads keys from a terminal, and stdin is not one"
    if problem is not None:
        print(f"error: {problem}", file=sys.stderr)
        return EXIT_BAD_INPUT
    try:
        async with await _connect(args) as client:
            robot = await client.robot(args.robot, cell=args.cell)
            await robot.ensure_lease()  # twists are streams: they need the lease held first
            return await _teleop_in_terminal(robot, teleop_keys.TeleopKeys(args.speed, args.frame))
    except GoalRejected as err:
        print(f"rejected: {err.reason}", file=sys.stderr)
        return EXIT_FAILED
    except UrDaemonError as err:
        return _fail(err)


async def _teleop_in_terminal(robot: RobotClient, keys: TeleopKeys) -> int:
    """The keys' help, then teleop with the terminal raw (put back however it ends)."""
    from urdaemon.teleop import TeleopShell, raw_terminal
    from urdaemon.teleop_keys import HELP

    print(f"teleop {robot.name}: {HELP}", file=sys.stderr)
    fd = sys.stdin.fileno()
    with raw_terminal(fd):
        return await TeleopShell(robot, keys, fd, sys.stdout).run()


async def _lease(args: argparse.Namespace) -> int:
    """``urdaemon lease ROBOT``: who holds its lease; with ``--take-over REASON`` take it (the robot
    stops), say from whom, and release it on exit."""
    problem = _bad_target(args)
    if problem is None and args.take_over is not None and not args.take_over.strip():
        problem = "--take-over needs a reason (it is logged and published)"
    if problem is not None:
        print(f"error: {problem}", file=sys.stderr)
        return EXIT_BAD_INPUT
    try:
        async with await _connect(args) as client:
            robot = await client.robot(args.robot, cell=args.cell)
            if args.take_over is None:
                print(_lease_text(robot.name, await robot.lease_info()))
                return EXIT_OK
            before = await robot.lease_info()
            reply = await robot.take_over(args.take_over)
            previous = reply.get("previous", before)
            print(f"took over {robot.name}'s lease {_taken_from(previous)}")
            await robot.release()
            print(f"released {robot.name}'s lease")
            return EXIT_OK
    except UrDaemonError as err:
        return _fail(err)


def _lease_text(robot: str, lease: dict[str, Any] | None) -> str:
    """One line about a lease: its holder, since when and its fingerprint (what the daemon shows of
    the holder's secret session id), or that it is free."""
    if lease is None:
        return f"{robot}: free"
    shown = f"{lease.get('holder')} since {_since(lease)} (fingerprint {lease.get('fingerprint')})"
    return f"{robot}: held by {shown}"


def _taken_from(lease: object) -> str:
    """Whom a take-over took the lease from (the lease it replaced, None when it was free)."""
    if not isinstance(lease, dict):
        return "(it was free)"
    return f"from {lease.get('holder')} (held since {_since(lease)}, fingerprint {lease.get('fingerprint')})"


def _since(lease: dict[str, Any]) -> str:
    import datetime

    since = lease.get("since")
    if not isinstance(since, int | float) or not math.isfinite(since):
        return "an unknown time"
    return datetime.datetime.fromtimestamp(since, datetime.UTC).isoformat(timespec="seconds")


async def _follow(goal: Any, bar: _ProgressBar) -> int:
    """Show progress (on a terminal only) until the result; print it; the exit code."""
    try:
        async for feedback in goal.feedback():
            bar.show(float(feedback["progress"]))
        result = await goal.result()
    except UrDaemonError as err:
        bar.end()
        return _fail(err)
    succeeded = result.get("status") == "succeeded"
    if succeeded:
        bar.show(1.0)
    bar.end()
    print(json.dumps(result))
    return EXIT_OK if succeeded else EXIT_FAILED


async def _cancel_when_answered(sending: asyncio.Future[Any]) -> int:
    """Ctrl-C while the goal's accept reply is awaited: wait for the reply (at most the request's
    own timeout) and cancel the goal it names, so no accepted goal is left with nobody following it."""
    task = asyncio.current_task()
    if task is not None:
        task.uncancel()
    print("interrupted: waiting for the goal's reply to cancel it", file=sys.stderr)
    try:
        goal = await sending
    except GoalRejected as err:
        print(f"goal not accepted, nothing moves: {err.reason}", file=sys.stderr)
        return EXIT_INTERRUPTED
    except UrDaemonError as err:
        _fail(err, "no reply to the goal, which may still have been accepted (see `urdaemon cancel`): ")
        return EXIT_INTERRUPTED
    return await _cancel_on_interrupt(goal)


async def _cancel_on_interrupt(goal: Any) -> int:
    """Cancel ``goal`` after Ctrl-C and wait (briefly) for its result."""
    task = asyncio.current_task()
    if task is not None:
        task.uncancel()
    print(f"interrupted: canceling goal {goal.goal_id}", file=sys.stderr)
    try:
        reply = await goal.robot.cancel(goal.goal_id)
    except UrDaemonError as err:
        _fail(err, f"goal {goal.goal_id} may still be running: cancel failed: ")
        return EXIT_INTERRUPTED
    if not reply.get("canceled"):
        print(f"goal {goal.goal_id} not canceled: {reply.get('reason', 'no reason')}", file=sys.stderr)
        return EXIT_INTERRUPTED
    try:
        result = await goal.result(timeout=5.0)
    except UrDaemonError as err:
        _fail(err, f"goal {goal.goal_id} canceled, but its result did not come: ")
        return EXIT_INTERRUPTED
    print(f"goal {goal.goal_id} canceled: the robot stops", file=sys.stderr)
    print(json.dumps(result))
    return EXIT_INTERRUPTED


class _ProgressBar:
    """``\r``-rewritten progress, only when the stream is a terminal (never into a log or a pipe)."""

    def __init__(self, stream: Any) -> None:
        self._stream = stream
        self._active = bool(getattr(stream, "isatty", lambda: False)())
        self._shown = False

    def show(self, fraction: float) -> None:
        if self._active:
            self._stream.write(f"\r  {100.0 * fraction:5.1f} %")
            self._stream.flush()
            self._shown = True

    def end(self) -> None:
        if self._shown:
            self._stream.write("\n")
            self._stream.flush()
            self._shown = False


def _calibration(args: argparse.Namespace) -> int:
    from pathlib import Path

    from urdaemon.calibration_tool import DEFAULT_PORT, DEFAULT_TIMEOUT_S, calibration_yaml, read_calibration

    # the defaults are the calibration tool's (imported here, not when the parser is built: the
    # primary codec behind them costs every other command its import time)
    port = DEFAULT_PORT if args.port is None else args.port
    timeout = DEFAULT_TIMEOUT_S if args.timeout is None else args.timeout
    output = Path(args.output)
    if not output.parent.is_dir():
        print(
            f"error: --output {args.output}: directory {str(output.parent)!r} does not exist", file=sys.stderr
        )
        return EXIT_BAD_INPUT
    if output.is_dir():
        print(f"error: --output {args.output} is a directory", file=sys.stderr)
        return EXIT_BAD_INPUT
    try:
        reading = asyncio.run(read_calibration(args.address, port, timeout))
    except UrDaemonError as err:
        print(f"error: {err}", file=sys.stderr)
        return EXIT_FAILED
    try:
        output.write_text(calibration_yaml(reading, f"{args.address}:{port}"), encoding="utf-8")
    except OSError as err:
        print(f"error: cannot write {args.output}: {err.strerror or err}", file=sys.stderr)
        return EXIT_FAILED
    print(f"wrote {args.output} (hash {reading.kinematics.kinematics_hash()})", file=sys.stderr)
    return EXIT_OK
