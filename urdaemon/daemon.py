"""The daemon: build every robot of a cell once, run them in one TaskGroup, stop cleanly."""

from __future__ import annotations

import asyncio
import contextlib
import gc
import logging
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from urdaemon.backends.base import Backend
from urdaemon.backends.mock import MockBackend
from urdaemon.backends.servo import ServoBackend
from urdaemon.backends.servo.outputs import board_links, device_problems
from urdaemon.cell.config import Cell
from urdaemon.cell.robot_options import Robot
from urdaemon.control import MotionController
from urdaemon.control.cartesian import CartesianLimits
from urdaemon.description import (
    DhKinematics,
    KinematicTree,
    build_cell_urdf,
    joint_limits_for,
    robot_dh,
)
from urdaemon.description.arm import arm_kinematics
from urdaemon.description.calibration import load_calibration
from urdaemon.description.urdf_facts import read_urdf_facts
from urdaemon.description.urmodels import load_ur_model
from urdaemon.errors import ConfigError, UrDaemonError
from urdaemon.model import JointLimits
from urdaemon.protocols.kinematics_hash import kinematics_hash
from urdaemon.publish import envelope
from urdaemon.publish.endpoints import CELL, ROBOT, Endpoint, declare_endpoints
from urdaemon.publish.keys import CellKeys
from urdaemon.publish.node import ZenohNode
from urdaemon.publish.tap import Matching, Tap
from urdaemon.recording.channels import RING_STREAMS
from urdaemon.robot import RobotRuntime
from urdaemon.runtime.audit import AuditLog, AuditOptions, CellAudit, watch_links, zenoh_log_from_env
from urdaemon.runtime.cell_goals import CellGoals
from urdaemon.runtime.daemon_info import DaemonInfo
from urdaemon.runtime.flight_recorder import FlightRecorder, flight_recorder
from urdaemon.runtime.lease_keeper import watch_lease_holders
from urdaemon.runtime.queries import internal_error, reply
from urdaemon.scheduling import RealtimeUnavailable, startup_objects_frozen, use_realtime_priority

__all__ = ["CellDescription", "Daemon", "describe_cell", "tf_message", "twist_limits"]

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class CellDescription:
    """The cell's URDF and what the daemon derives from it once at start-up."""

    urdf: str
    tree: KinematicTree
    limits: dict[str, JointLimits]


def describe_cell(cell: Cell) -> CellDescription:
    """Build the cell URDF and every robot's joint limits; ``ConfigError`` naming each key path of a
    start pose (``mock``/``servo.initial_positions``) the limits refuse, before anything is served."""
    urdf_text = build_cell_urdf(cell)
    urdf = read_urdf_facts(urdf_text)
    limits = {robot.name: joint_limits_for(robot, urdf) for robot in cell.robots}
    problems = [
        line
        for i, robot in enumerate(cell.robots)
        for line in _start_pose_problems(robot, limits[robot.name], f"robots[{i}] ({robot.name})")
    ]
    if problems:
        raise ConfigError("\n".join(problems), errors=problems)
    return CellDescription(urdf=urdf_text, tree=KinematicTree.from_urdf(urdf), limits=limits)


def _start_pose(robot: Robot) -> tuple[str, tuple[float, ...] | dict[str, float] | None]:
    """The cell file's section holding the robot's start pose, and the pose as written (None: none)."""
    if robot.mock is not None:
        return "mock", robot.mock.initial_positions
    if robot.servo is not None:
        return "servo", robot.servo.initial_positions
    return "", None


def _start_pose_problems(robot: Robot, limits: JointLimits, where: str) -> list[str]:
    """What is wrong with the robot's start pose, a line per problem, each naming its key path under
    ``where`` (``robots[0] (alice)``): joints the arm lacks, a wrong count, values outside the limits.
    (Only here are a custom arm's joints and every arm's final limits known: cell/ cannot see them.)"""
    section, given = _start_pose(robot)
    if given is None:
        return []
    key = f"{where}.{section}.initial_positions"
    bounds = dict(zip(limits.names, zip(limits.min_position, limits.max_position, strict=True), strict=True))
    if isinstance(given, dict):
        unknown = sorted(name for name in given if robot.prefix + name not in bounds)
        if unknown:
            return [f"{key}: unknown joint(s) {', '.join(unknown)}; joints: {', '.join(limits.names)}"]
        named = [(f"{key}.{name}", robot.prefix + name, value) for name, value in given.items()]
    elif len(given) != limits.dof:
        return [f"{key}: {len(given)} values for {limits.dof} joints ({', '.join(limits.names)})"]
    else:
        named = [
            (f"{key}[{i}]", name, value)
            for i, (name, value) in enumerate(zip(limits.names, given, strict=True))
        ]
    return [
        f"{path}: {value:g} is outside the limits of {joint} [{bounds[joint][0]:g}, {bounds[joint][1]:g}]"
        for path, joint, value in named
        if not bounds[joint][0] <= value <= bounds[joint][1]
    ]


def _initial_positions(robot: Robot, limits: JointLimits) -> list[float] | None:
    """The robot's start pose in joint order (joints left out of a mapping at 0), or None; checked."""
    problems = _start_pose_problems(robot, limits, f"robot {robot.name!r}")
    if problems:
        raise ConfigError("\n".join(problems), errors=problems)
    _, given = _start_pose(robot)
    if given is None:
        return None
    if isinstance(given, dict):
        by_name = {robot.prefix + k: v for k, v in given.items()}
        return [float(by_name.get(name, 0.0)) for name in limits.names]
    return [float(v) for v in given]


def make_backend(
    robot: Robot, limits: JointLimits, node: ZenohNode | None, cell: str, *, check_devices: bool = True
) -> Backend:
    """The backend a robot's config asks for; ``check_devices``: refuse a servo arm whose device files
    are missing or may not be opened (``check --skip-devices`` leaves that to the machine it runs on)."""
    initial = _initial_positions(robot, limits)
    if robot.backend == "mock":
        options = robot.mock
        rate = options.rate_hz if options and options.rate_hz else None
        if rate is None:
            rate = float(load_ur_model(robot.model).control_rate_hz) if robot.is_ur else 100.0
        return MockBackend(
            robot.name,
            limits.names,
            rate,
            initial_positions=initial,
            speed_scaling=options.speed_scaling if options else 1.0,
        )
    if robot.backend == "servo":
        servo = robot.servo
        assert servo is not None
        if check_devices:
            problems = device_problems(servo, f"robot {robot.name!r}: servo")
            if problems:
                raise ConfigError("\n".join(problems), errors=problems)
        keys = CellKeys(cell).robot(robot.name)
        publisher = ROBOT.servo_command.declare(node, keys) if node is not None and servo.publishes else None
        try:
            backend = ServoBackend(
                robot.name,
                limits.names,
                robot.prefix,
                servo,
                initial_positions=initial,
                publish=(lambda payload: publisher.put(payload)) if publisher is not None else None,
                links=board_links(servo),
            )
        except ConfigError as err:
            raise ConfigError(f"robot {robot.name!r}: {err}") from err
        problems = [
            f"robot {robot.name!r}: {p}"
            for p in backend.mapping.uncovered(limits.min_position, limits.max_position)
        ]
        if problems:
            raise ConfigError("\n".join(problems), errors=problems)
        return backend
    if robot.backend == "ur":
        from urdaemon.backends.ur.backend import UrBackend

        return UrBackend(robot, limits.names, expected_hash=_expected_hash(robot))
    raise ConfigError(f"robot {robot.name!r}: backend {robot.backend!r} is not available in this version")


def _expected_hash(robot: Robot) -> str:
    """The kinematics hash the robot should report: its calibration file's, else its model's nominal one."""
    model = load_ur_model(robot.model)
    if robot.calibration is not None:
        calibration = load_calibration(robot.calibration, model)
        if calibration.hash is not None:
            return calibration.hash
        dh = calibration.dh
        return kinematics_hash(dh.theta, dh.a, dh.d, dh.alpha)
    return model.kinematics_hash


def twist_limits(robot: Robot) -> CartesianLimits:
    """What twist streaming smooths and caps with: the cell's caps of speed, its defaults of
    acceleration and jerk (cell file ``motion.cartesian``)."""
    options = robot.motion.cartesian
    return CartesianLimits(
        speed=options.max_speed,
        acceleration=options.acceleration,
        jerk=options.jerk,
        angular_speed=options.max_angular_speed,
        angular_acceleration=options.angular_acceleration,
        angular_jerk=options.angular_jerk,
    )


class Daemon:
    """Serves one cell over Zenoh until ``stop`` is set."""

    def __init__(
        self, cell: Cell, *, listen: tuple[str, ...] | None = None, audit: AuditOptions | None = None
    ) -> None:
        self.cell = cell
        self.audit = AuditLog(cell.cell, audit if audit is not None else _audit_options(cell))
        """Every commanding request and session, to ``<cell>/audit`` and the file that ``audit`` (or
        else the cell file's ``audit`` key) names."""
        self.keys = CellKeys(cell.cell)
        self._listen = listen
        self.description = describe_cell(cell)
        self.runtimes: list[RobotRuntime] = []
        self.node: ZenohNode | None = None
        self.flight_recorder: FlightRecorder | None = None
        """The cell file's ``record``: the flight recorder's process, supervised (None without it)."""

    @property
    def listen_endpoints(self) -> tuple[str, ...]:
        """Where the daemon accepts Zenoh sessions (the override, else the cell file's)."""
        return self._listen if self._listen is not None else self.cell.zenoh.listen

    async def run(self, stop: asyncio.Event) -> None:
        """Serve until ``stop`` is set; then end every goal and close the Zenoh session."""
        loop = asyncio.get_running_loop()
        zenoh_log_from_env()  # RUST_LOG: Zenoh's own log, its access-control denials included
        tap = Tap(RING_STREAMS) if self.cell.record is not None else None  # the flight recorder's feed
        self.node = node = ZenohNode(self.cell.zenoh, loop, listen=self._listen, cell=self.cell.cell, tap=tap)
        restore_priority: Callable[[], None] | None = None
        links: Any = None
        try:
            if self.cell.realtime_priority:  # after Zenoh started its threads: they stay as they are
                try:
                    restore_priority = use_realtime_priority(self.cell.realtime_priority)
                    log.info("event loop thread: SCHED_FIFO priority %d", self.cell.realtime_priority)
                except RealtimeUnavailable as err:
                    log.warning("serving at normal priority: %s", err)
            self._build(node)
            watch_lease_holders(node, self.cell, self.runtimes)  # leases: checked or not; end with the holder
            cell_goals = CellGoals(node, self.keys, self.runtimes)  # trajectories started together
            info = DaemonInfo(self.cell, self.runtimes, self.description.limits, self.listen_endpoints)
            self.flight_recorder = recorder = flight_recorder(self.cell, node, self.description.urdf)
            served: dict[Endpoint, Any] = {
                CELL.tf: None,
                CELL.robot_description: self._on_description,
                CELL.daemon: info.on_query,  # also answers ``*/daemon``: every cell
                CELL.any_robot: self._on_any_robot,
                CELL.stop: self._on_cell_stop,  # never refused: any payload
                CELL.audit: None,
                **cell_goals.endpoints(),
                **(recorder.endpoints() if recorder is not None else {}),
            }
            declared = declare_endpoints(node, self.keys, served, audit=CellAudit(self.audit))
            tf_pub = declared[CELL.tf]  # the cell's rows of the table
            self.audit.start(declared[CELL.audit].put)  # its writer thread: off the loop
            links = watch_links(node.session, self.audit)
            with startup_objects_frozen() as frozen:  # no 40-70 ms collector pauses in the cycle
                log.info("cell %r serving %d robot(s)", self.cell.cell, len(self.runtimes))
                log.debug("%d objects of startup kept out of garbage collection", frozen)
                async with asyncio.TaskGroup() as group:
                    tasks = [group.create_task(rt.run()) for rt in self.runtimes]
                    tasks.append(group.create_task(self._publish_tf(tf_pub, node.matching(tf_pub))))
                    tasks.append(group.create_task(cell_goals.run()))
                    if recorder is not None:  # its own process: a robot's cycle only feeds the tap
                        tasks.append(group.create_task(recorder.run()))
                    await stop.wait()
                    for task in tasks:
                        task.cancel()
        finally:
            for runtime in self.runtimes:
                try:
                    await runtime.backend.close()
                except Exception:  # one backend failing to close must not keep the others open
                    log.exception("closing %s failed", runtime.robot.name)
            with contextlib.suppress(Exception):
                if links is not None:
                    links.undeclare()
            self.audit.close()  # what is queued is written and published before the session goes
            node.close()
            if restore_priority is not None:  # the thread may go on running someone else's loop
                restore_priority()
            log.info("cell %r stopped", self.cell.cell)

    def release(self) -> None:
        """Let go of every ruckig object the robots' controllers hold, once ``run`` returned and its
        event loop ended (a handler still queued on the loop could find them gone). Whatever holds the
        daemon when the interpreter exits (a Zenoh callback whose last reference is dropped on a Zenoh
        thread that never runs Python again) then keeps none alive, and nanobind reports no leak."""
        for runtime in self.runtimes:
            runtime.controller.release()
        gc.collect()  # and no ruckig object waits in a reference cycle for the interpreter's last one

    def _build(self, node: ZenohNode) -> None:
        for robot in self.cell.robots:
            limits = self.description.limits[robot.name]
            backend = make_backend(robot, limits, node, self.cell.cell)
            motion = robot.motion
            controller = MotionController(
                limits,
                period=backend.period,
                path_tolerance=motion.path_tolerance,
                goal_tolerance=motion.goal_tolerance,
                goal_time_tolerance=motion.goal_time_tolerance,
                stream_timeout=motion.stream_timeout,
                feedback_period=1.0 / motion.feedback_rate_hz,
            )
            bounds = (limits.min_position, limits.max_position)
            arm = arm_kinematics(robot, self.description.tree, limits.names, bounds)
            controller.set_arm(arm, twist_limits(robot))
            controller.set_tcp(robot.tcp)  # the cell file's; set_tcp changes it
            kinematics = DhKinematics(robot_dh(robot)) if robot.is_ur else None
            runtime = RobotRuntime(
                self.cell.cell,
                robot,
                backend,
                controller,
                node,
                self.cell.publish,
                kinematics=kinematics,
                arm=arm,
                audit=self.audit,
            )
            runtime.declare()
            self.runtimes.append(runtime)

    def _on_description(self, query: Any) -> None:
        try:
            query.reply(self.keys.robot_description, self.description.urdf.encode())
        finally:
            query.drop()

    def _on_cell_stop(self, query: Any) -> None:
        """Stop every robot of the cell at once (each as its own ``stop`` would); answered once, naming
        each robot's outcome."""
        robots: dict[str, Any] = {}
        for runtime in self.runtimes:
            try:
                robots[runtime.robot.name] = runtime.services.stop("cell stop requested")
            except Exception as err:  # one robot failing must not keep the others moving
                log.exception("cell stop: %s failed", runtime.robot.name)
                robots[runtime.robot.name] = {"ok": False, "reason": internal_error(err)}
        reply(query, {"ok": all(r.get("ok") for r in robots.values()), "robots": robots})

    def _on_any_robot(self, query: Any) -> None:
        """Answer a query on a robot this cell does not serve, or on a service a robot does not
        have, naming what there is; every other query is someone else's to answer (or nobody's)."""
        try:
            parsed = self.keys.parse(str(query.key_expr))
            if parsed is None:
                return
            name, rest = parsed
            robots = {runtime.robot.name: runtime for runtime in self.runtimes}
            runtime = robots.get(name)
            service = CellKeys.service_name(rest)
            if runtime is None:
                reason = (
                    f"no robot {envelope.client_text(name)!r} in cell {self.cell.cell!r}; "
                    f"its robots: {', '.join(sorted(robots))}"
                )
            elif service is not None and service not in runtime.service_names:
                reason = (
                    f"robot {name!r} has no service {envelope.client_text(service)!r}; "
                    f"its services: {', '.join(sorted(runtime.service_names))}"
                )
            else:
                return
            query.reply(query.key_expr, envelope.encode({"ok": False, "accepted": False, "reason": reason}))
        except Exception as err:  # the querier may have gone; this must never take the cell down
            log.debug("answering %s failed: %s", envelope.client_text(str(query.key_expr), 80), err)
        finally:
            with contextlib.suppress(Exception):
                query.drop()

    async def _publish_tf(self, publisher: Any, wanted: Matching) -> None:
        period = 1.0 / self.cell.publish.tf_rate_hz
        tree = self.description.tree
        last_error = ""
        while True:
            await asyncio.sleep(period)
            if not wanted.active:  # the whole cell's forward kinematics, for nobody: skip it
                continue
            positions: dict[str, float] = {}
            times: dict[str, dict[str, Any]] = {}  # each robot's: the state its links are computed from
            try:
                for runtime in self.runtimes:
                    state = runtime.state
                    positions.update(zip(state.joint_names, state.positions, strict=True))
                    times[runtime.robot.name] = envelope.state_time(state, time.time_ns())
                links = {name: list(pose) for name, pose in tree.link_poses(positions)}
                publisher.put(envelope.encode(tf_message(links, times)))
            except Exception as err:  # tf must never take the robots down with it; say so once per cause
                text = f"{type(err).__name__}: {err}"
                if text != last_error:
                    log.error("tf not published: %s", text, exc_info=not isinstance(err, UrDaemonError))
                    last_error = text


def tf_message(links: dict[str, list[float]], times: dict[str, dict[str, Any]]) -> dict[str, Any]:
    """The ``tf`` message: the world poses of ``links``, computed from each robot's newest joint state,
    whose time fields (``envelope.state_time``) are ``times``, by robot. Its ``host_time_ns`` is the oldest
    of them (every link is at least that new); it has no ``controller_time`` of its own, as each robot
    has its own clock: ``robot_times`` gives each robot's."""
    oldest = min((t["host_time_ns"] for t in times.values()), default=None)
    stamp = time.time_ns() if oldest is None else oldest
    return {"frame": "world", "host_time_ns": stamp, "robot_times": times, "links": links}


def _audit_options(cell: Cell) -> AuditOptions | None:
    """The cell file's ``audit`` key as the audit log's options (None: no file)."""
    if cell.audit is None:
        return None
    return AuditOptions(Path(cell.audit.file), max_bytes=cell.audit.max_bytes, backups=cell.audit.backups)
