"""``urdaemon fake-robot``: build fake controllers from the command line or a cell file and serve them."""

from __future__ import annotations

import argparse
import asyncio
import sys
from pathlib import Path

from urdaemon.cell import load_cell
from urdaemon.cell.robot_options import Robot
from urdaemon.description.calibration import load_calibration, robot_dh
from urdaemon.description.urmodels import load_ur_model
from urdaemon.errors import ConfigError
from urdaemon.fakeur.contact import Wall, surroundings_of
from urdaemon.fakeur.controller import FakeController
from urdaemon.fakeur.faults import SERVICES, FaultInjector
from urdaemon.fakeur.shared_clock import SharedClock
from urdaemon.scheduling import startup_objects_frozen
from urdaemon.stop_signals import end_stop_signals, stop_on_signals, stop_signal_handlers

__all__ = ["build_fakes", "parse_version", "parse_wall", "run_fakes"]

DAEMON_HOST = "127.0.0.1"
"""Where a fake in URCap mode finds the daemon's script sender when built from a cell file."""


def parse_version(text: str) -> tuple[int, int, int, int]:
    """``5.15.0`` → (5, 15, 0, 0); ConfigError when it is not 2–4 dot-separated numbers."""
    parts = text.split(".")
    if not 2 <= len(parts) <= 4 or not all(p.isdigit() for p in parts):
        raise ConfigError(f"--controller-version {text!r}: expected numbers like 5.15.0")
    numbers = [int(p) for p in parts] + [0] * (4 - len(parts))
    return (numbers[0], numbers[1], numbers[2], numbers[3])


def parse_wall(text: str) -> Wall:
    """``X,Y,Z,NX,NY,NZ[,STIFFNESS]`` (m, a normal toward the free side, N/m) → a wall; ConfigError if not."""
    parts = text.split(",")
    try:
        numbers = [float(p) for p in parts]
        if len(numbers) not in (6, 7):
            raise ValueError("expected 6 or 7 numbers")
        return Wall.of(numbers[:3], numbers[3:6], *numbers[6:])
    except ValueError as err:
        raise ConfigError(f"--wall {text!r}: expected X,Y,Z,NX,NY,NZ[,STIFFNESS] ({err})") from None


def _place_walls(fakes: list[FakeController], args: argparse.Namespace) -> list[FakeController]:
    walls = [parse_wall(text) for text in getattr(args, "wall", None) or []]
    if walls:
        for fake in fakes:
            surroundings_of(fake.arm).walls.extend(walls)
    return fakes


def _programs(args: argparse.Namespace) -> Path | None:
    """The ``--programs`` directory (None when not given); ConfigError if it is not a directory."""
    programs = getattr(args, "programs", None)
    if programs is not None and not Path(programs).is_dir():
        raise ConfigError(f"--programs {programs!r}: not a directory")
    return None if programs is None else Path(programs)


def _faults(args: argparse.Namespace) -> FaultInjector:
    for service in [*args.refuse, *args.split]:
        if service not in (*SERVICES, "*"):
            raise ConfigError(f"unknown service {service!r}; one of {', '.join(SERVICES)} or *")
    delay = {"*": args.delay} if args.delay > 0 else {}
    return FaultInjector(refused=set(args.refuse), split=set(args.split), delay_s=delay)


def build_fakes(args: argparse.Namespace) -> list[FakeController]:
    """The fakes the arguments describe, with the walls it names."""
    return _place_walls(_build_fakes(args), args)


def _daemon_host(robot: Robot) -> str:
    """The URCap's Host IP for a fake built from a cell file: where the daemon's callback servers
    listen for it (backends/ur/route.py): ``reverse_ip``, else ``listen_address``, else the robot's
    own loopback address; ``DAEMON_HOST`` when they listen on every interface."""
    ur = robot.ur
    given = (ur.reverse_ip or ur.listen_address) if ur is not None else None
    if given in ("0.0.0.0", "::"):
        return DAEMON_HOST
    return given or robot.address or DAEMON_HOST


def _build_fakes(args: argparse.Namespace) -> list[FakeController]:
    version = parse_version(args.controller_version)
    if args.config:
        cell = load_cell(args.config)
        fakes = []
        for robot in cell.robots:
            if robot.backend != "ur" or robot.address is None:
                continue
            urcap = None if robot.headless else (_daemon_host(robot), robot.ports.script_sender)
            fakes.append(
                FakeController(
                    robot.model,
                    address=robot.address,
                    controller_version=version,
                    dh=robot_dh(robot),
                    powered=args.powered,
                    urcap=urcap,
                    faults=_faults(args),
                    programs=_programs(args),
                )
            )
        if not fakes:
            raise ConfigError(f"{args.config}: no robot with backend 'ur' and an address")
        return fakes
    model = load_ur_model(args.model)
    dh = load_calibration(args.calibration, model).dh if args.calibration else None
    urcap = None
    if args.urcap:
        host, _, port = args.urcap.rpartition(":")
        if not host or not port.isdigit():
            raise ConfigError(f"--urcap {args.urcap!r}: expected HOST:PORT")
        urcap = (host, int(port))
    return [
        FakeController(
            model,
            address=args.address,
            controller_version=version,
            dh=dh,
            powered=args.powered,
            urcap=urcap,
            faults=_faults(args),
            programs=_programs(args),
        )
    ]


def share_clock(fakes: list[FakeController], phases: str) -> SharedClock | None:
    """One clock for all ``fakes`` (they run at one rate): ``aligned`` ticks them together,
    ``spread`` gives each its own phase within the period, as independent controllers have."""
    if len(fakes) < 2:
        return None
    clock = SharedClock(fakes[0].step_time, slots=len(fakes) if phases == "spread" else 1)
    for slot, fake in enumerate(fakes):
        fake.use_clock(clock, slot)
    return clock


def run_fakes(args: argparse.Namespace) -> int:
    """Serve the fakes until Ctrl-C or SIGTERM; exit code."""
    fakes = build_fakes(args)
    share_clock(fakes, args.phases)

    async def serve() -> None:
        stop = asyncio.Event()
        stop_on_signals(stop, f"{len(fakes)} fake robot(s)")  # SIGINT, SIGTERM, SIGHUP; repeats logged
        if args.late_start > 0:
            try:
                await asyncio.wait_for(stop.wait(), args.late_start)
                return
            except TimeoutError:
                pass
        started: list[FakeController] = []
        try:
            for fake in fakes:
                await fake.start()
                started.append(fake)
            print(f"serving {len(fakes)} fake robot(s)", file=sys.stderr, flush=True)
            with startup_objects_frozen():  # a controller's cycle has no collector pauses either
                await stop.wait()
        finally:
            for fake in started:
                await fake.close()

    # only ``urdaemon fake-robot`` itself owns its process; called otherwise, it gives the handlers back
    previous = None if getattr(args, "owns_process", False) else stop_signal_handlers()
    try:
        asyncio.run(serve())
    except OSError as err:
        print(f"error: cannot listen: {err}", file=sys.stderr)
        return 1
    finally:
        end_stop_signals(previous)  # stopped cleanly: a late signal must not turn the exit into -15
    return 0
