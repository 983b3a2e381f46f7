"""The cell file schema: frozen pydantic models that reject unknown keys.

Nothing below the daemon sees YAML or dicts: ``load_cell`` turns a file into a ``Cell`` once.
Relative paths in the file are resolved against the file's folder (validation context ``base_dir``).
This module holds the whole cell (its name, the checks across robots, the default ports) and its
``publish`` and ``record`` sections; the ``zenoh`` section is zenoh_options.py's, a robot's
robot_options.py's (its ``servo`` section servo.py's).
"""

from __future__ import annotations

from typing import Annotated, Any

from pydantic import Field, ValidationInfo, field_validator, model_validator

from urdaemon.cell.robot_options import Ports, Robot
from urdaemon.cell.schema_types import Frozen, resolve_path
from urdaemon.cell.zenoh_options import ZenohOptions, endpoint_port
from urdaemon.model import CELL_LEVEL_KEYS
from urdaemon.urscript import DEFAULT_REVERSE_PORT

__all__ = [
    "CELL_NAME_PATTERN",
    "DEFAULT_PORT_BASE",
    "DEFAULT_PORT_STRIDE",
    "AuditFileOptions",
    "Cell",
    "PublishOptions",
    "RecordOptions",
]

CELL_NAME_PATTERN = r"^[A-Za-z0-9][A-Za-z0-9_-]{0,62}$"
DEFAULT_PORT_BASE = DEFAULT_REVERSE_PORT
"""UR's reverse port; the first robot gets 50001..50004 like UR's own driver."""
DEFAULT_PORT_STRIDE = 10
"""Each further robot's default ports are 10 higher, so defaults never clash."""


class PublishOptions(Frozen):
    """Rates of what the daemon publishes."""

    joint_states_decimation: Annotated[int, Field(ge=1, le=1000)] = 1
    """Publish joint states and TCP pose every Nth robot cycle."""
    tf_rate_hz: Annotated[float, Field(ge=1, le=500)] = 50.0
    status_rate_hz: Annotated[float, Field(ge=0.01, le=100)] = 2.0
    """Status is published on every change and at least at this rate (down to once in 100 s)."""
    io_rate_hz: Annotated[float, Field(ge=1, le=500)] = 10.0
    """IO is looked at this often, and published on every change and at least at this rate."""


class RecordOptions(Frozen):
    """The flight recorder (docs/recording.md): the last ``ring_s`` seconds of everything the cell
    publishes, kept by a process of its own and written to ``dir`` on a stop, an aborted goal, a lost
    link, an internal error, or a request on ``<cell>/service/flight_record``."""

    ring_s: Annotated[float, Field(ge=1, le=3600)] = 60.0
    """Seconds kept before a trigger."""
    after_s: Annotated[float, Field(ge=0, le=10)] = 1.0
    """Seconds after the trigger written too (what the stop looked like)."""
    max_mb: Annotated[int, Field(ge=1, le=16384)] = 512
    """Cap of the ring's memory (MB); at 8 robots' 500 Hz the oldest messages go before ``ring_s``
    passed once it is reached."""
    dir: str
    """Where the files go (relative: to the cell file's folder); the daemon makes it at start if missing."""

    @field_validator("dir")
    @classmethod
    def _directory(cls, value: str, info: ValidationInfo) -> str:
        path = resolve_path(value, info)
        if path.exists() and not path.is_dir():
            raise ValueError(f"{path} is not a directory")
        return str(path.resolve())


class AuditFileOptions(Frozen):
    """The audit log's file (docs/operating.md, "The audit log"): one JSON line per commanding request,
    rotated by size. The lines always go to ``<cell>/audit`` too; without this key no file is written."""

    file: str
    """The file (relative: to the cell file's folder); the daemon makes its folder at start if missing."""
    max_bytes: Annotated[int, Field(ge=4096, le=1 << 40)] = 10 * 1024 * 1024
    """Rotated when it would pass this size."""
    backups: Annotated[int, Field(ge=0, le=1000)] = 5
    """Rotated files kept (``FILE.1`` … ``FILE.<backups>``); 0: the file is cut back instead."""

    @field_validator("file")
    @classmethod
    def _file(cls, value: str, info: ValidationInfo) -> str:
        path = resolve_path(value, info)
        if path.is_dir():
            raise ValueError(f"{path} is a directory; name the audit file in it")
        return str(path.resolve())


class Cell(Frozen):
    """A whole work cell: its name, the Zenoh settings and the robots."""

    cell: Annotated[str, Field(pattern=CELL_NAME_PATTERN)]
    """Cell name: the first chunk of every key (``<cell>/<robot>/...``)."""
    zenoh: ZenohOptions = ZenohOptions()
    publish: PublishOptions = PublishOptions()
    realtime_priority: Annotated[int, Field(ge=0, le=99, strict=True)] = 0
    """``SCHED_FIFO`` priority (1–99) of the daemon's event loop thread, which clocks every robot; 0
    keeps normal scheduling. Needs ``CAP_SYS_NICE`` or an ``rtprio`` limit; without it the daemon
    warns and serves at normal priority. See docs/performance.md."""
    command_lease: bool = True
    """Every robot has a command lease (docs/security.md): goals, streams and commanding services are
    taken only from the client holding the robot's lease, and a robot whose holder's session goes away
    stops. ``false``: any client may command any robot (the lease can still be taken, and is not
    checked)."""
    record: RecordOptions | None = None
    """The flight recorder; none without it (docs/recording.md)."""
    audit: AuditFileOptions | None = None
    """The audit log's rotating file; none without it (``<cell>/audit`` is published either way)."""
    robots: tuple[Robot, ...]

    @model_validator(mode="before")
    @classmethod
    def _assign_default_ports(cls, data: Any) -> Any:
        """Give robots without ``ports`` the lowest block of four ports no robot uses explicitly."""
        if not isinstance(data, dict) or not isinstance(data.get("robots"), list | tuple):
            return data
        robots = list(data["robots"])
        taken: set[int] = set()
        for robot in robots:
            ports = robot.get("ports") if isinstance(robot, dict) else None
            if isinstance(ports, dict):
                taken.update(p for p in ports.values() if isinstance(p, int))
        base = DEFAULT_PORT_BASE
        for i, robot in enumerate(robots):
            if isinstance(robot, dict) and robot.get("ports") is None:
                while taken & set(range(base, base + 4)):
                    base += DEFAULT_PORT_STRIDE
                robots[i] = {**robot, "ports": Ports.block(base).as_dict()}
                taken.update(range(base, base + 4))
                base += DEFAULT_PORT_STRIDE
        return {**data, "robots": tuple(robots)}

    @model_validator(mode="after")
    def _unique(self) -> Cell:
        # Messages start with their own key path: a whole-cell validator has no location of its own.
        if not self.robots:
            raise ValueError("robots: must list at least one robot")
        where = {r.name: f"robots[{i}] ({r.name})" for i, r in enumerate(self.robots)}
        seen: set[str] = set()
        for i, robot in enumerate(self.robots):
            if robot.name in seen:
                raise ValueError(f"robots[{i}] ({robot.name}).name: duplicate robot name {robot.name!r}")
            if robot.name in CELL_LEVEL_KEYS:
                raise ValueError(
                    f"robots[{i}] ({robot.name}).name: {robot.name!r} names a key of the cell itself "
                    f"({', '.join(sorted(CELL_LEVEL_KEYS))}); choose another name"
                )
            seen.add(robot.name)
        owner: dict[int, str] = {}
        for robot in self.robots:
            for role, port in robot.ports.as_dict().items():
                if port in owner:
                    raise ValueError(
                        f"{where[robot.name]}.ports.{role}: robot {robot.name!r} {role} port {port} "
                        f"clashes with {owner[port]}"
                    )
                owner[port] = f"robot {robot.name!r} {role} port"
        self._one_robot_per_controller(where)
        self._zenoh_ports_free(owner)
        access = self.zenoh.access
        unknown = access.unknown_robots([r.name for r in self.robots]) if access is not None else None
        if unknown is not None:
            raise ValueError(unknown)
        mounted_on: dict[str, str] = {}
        for robot in self.robots:
            parent = robot.pose.parent
            if parent == "world":
                continue
            carriers = [r for r in self.robots if parent.startswith(r.prefix)]
            if not carriers:
                raise ValueError(
                    f"{where[robot.name]}.pose.parent: {parent!r} is neither 'world' "
                    "nor a link of a robot of this cell"
                )
            mounted_on[robot.name] = max(carriers, key=lambda r: len(r.prefix)).name
        for robot in self.robots:
            chain = [robot.name]
            while chain[-1] in mounted_on:
                chain.append(mounted_on[chain[-1]])
                if chain[-1] == robot.name:
                    raise ValueError(
                        f"{where[robot.name]}.pose.parent: mounting makes a loop: {' → '.join(chain)}"
                    )
                if len(chain) > len(self.robots) + 1:
                    break
        return self

    def _one_robot_per_controller(self, where: dict[str, str]) -> None:
        controllers: dict[str, str] = {}
        for robot in self.robots:
            if robot.backend != "ur" or robot.address is None:
                continue
            other = controllers.get(robot.address.lower())
            if other is not None:
                raise ValueError(
                    f"{where[robot.name]}.address: {robot.address} is also robot {other!r}'s address; "
                    "one controller drives one arm (its dashboard, primary and RTDE ports are fixed)"
                )
            controllers[robot.address.lower()] = robot.name

    def _zenoh_ports_free(self, owner: dict[int, str]) -> None:
        listening = {
            port: text
            for robot in self.robots
            if robot.listens
            for port, text in owner.items()
            if text.startswith(f"robot {robot.name!r} ")
        }
        for i, endpoint in enumerate(self.zenoh.listen):
            port = endpoint_port(endpoint)
            if port is not None and port in listening:
                raise ValueError(
                    f"zenoh.listen[{i}]: {endpoint} uses port {port}, the {listening[port]}; "
                    "the daemon would listen on it twice"
                )

    def robot(self, name: str) -> Robot:
        """The robot called ``name``."""
        for robot in self.robots:
            if robot.name == name:
                return robot
        raise KeyError(name)
