"""What ``urdaemon replay`` takes from a recording: its cell, URDF, each robot's joint states, and
every message in log-time order (for ``--publish``); and what it checks against the cell it drives.
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

from urdaemon.errors import ConfigError
from urdaemon.recording.mcap_file import Recorded, read_recording
from urdaemon.replay.goal_plan import Sample

if TYPE_CHECKING:
    from urdaemon.cell.config import Cell
    from urdaemon.cell.robot_options import Robot

__all__ = ["RecordedCell", "mismatch", "read_cell", "sample_period"]


@dataclass
class RecordedCell:
    """A recording, read through once: the cell it is of, its URDF, each robot's joint names and
    samples (in log-time order; only when asked for), its topics and how many messages it holds;
    ``messages()`` reads them again, one at a time (for ``--publish``)."""

    path: str
    cell: str
    urdf: str | None
    names: dict[str, tuple[str, ...]] = field(default_factory=dict)
    samples: dict[str, list[Sample]] = field(default_factory=dict)
    goals: dict[str, list[tuple[int, float]]] = field(default_factory=dict)
    """Each robot's goals that succeeded: when the result was recorded (ns), the trajectory time run."""
    topics: set[str] = field(default_factory=set)
    count: int = 0
    """Messages, the URDF's left out."""

    @property
    def robots(self) -> list[str]:
        """The robots that have joint states in the recording."""
        return sorted(self.names)

    def messages(self) -> Iterator[Recorded]:
        """Every message but the URDF's, in log-time order, read from the file as they are taken."""
        with open(self.path, "rb") as stream:
            for record in read_recording(stream):
                if record.kind is not None:
                    yield record


def read_cell(path: str | Path, *, samples: bool = True) -> RecordedCell:
    """Read a recording (keeping each robot's samples unless ``samples`` is False); ``ConfigError``
    naming the file when it is not one, or holds no message of a cell."""
    try:
        with open(path, "rb") as stream:
            found = _collect(str(path), read_recording(stream), samples)
    except OSError as err:
        raise ConfigError(f"{path}: cannot read it: {err.strerror or err}") from err
    except ConfigError as err:
        raise ConfigError(f"{path}: {err}") from err
    except Exception as err:  # the mcap reader's own errors: not an MCAP file, truncated, ...
        raise ConfigError(f"{path}: not a readable recording: {type(err).__name__}: {err}") from err
    if not found.cell:
        raise ConfigError(f"{path}: the recording holds no message of a cell")
    return found


def _collect(path: str, records: Iterable[Recorded], samples: bool) -> RecordedCell:
    found = RecordedCell(path, "", None)
    for record in records:
        if record.kind is None:  # the URDF's channel, which names no cell
            found.urdf = found.urdf or str(record.message.get("urdf", ""))
            continue
        cell = record.topic.split("/")[1]
        if found.cell and cell != found.cell:
            raise ConfigError(f"it holds two cells, {found.cell!r} and {cell!r}")
        found.cell = cell
        found.topics.add(record.topic)
        found.count += 1
        if record.kind.name == "joint_states":
            _add_sample(found, record, samples)
        elif record.kind.name == "goal_result" and samples:
            _add_goal(found, record)
    return found


def _add_sample(found: RecordedCell, record: Recorded, keep: bool) -> None:
    message = record.message
    robot = str(message.get("robot") or record.topic.split("/")[2])
    names = tuple(str(n) for n in message["names"])
    known = found.names.setdefault(robot, names)
    if known != names:
        raise ConfigError(f"robot {robot!r}: its joint names change within the recording ({known} → {names})")
    if not keep:
        return
    velocities = tuple(message.get("velocity") or (0.0,) * len(names))
    found.samples.setdefault(robot, []).append(
        Sample(record.log_time_ns, tuple(message["position"]), tuple(float(v) for v in velocities))
    )


def _add_goal(found: RecordedCell, record: Recorded) -> None:
    message = record.message
    duration = message.get("duration")
    if message.get("status") == "succeeded" and isinstance(duration, int | float) and duration > 0:
        robot = str(message.get("robot") or record.topic.split("/")[2])
        found.goals.setdefault(robot, []).append((record.log_time_ns, float(duration)))


def mismatch(
    recorded: RecordedCell, cell: Cell, served: dict[str, tuple[str, ...]], robots: Sequence[str]
) -> str | None:
    """Why the recording cannot drive ``cell`` (None when it can): another cell name, robots of the
    recording (or asked for with ``--robot``) the cell lacks, or a robot whose joint names differ
    (``served``: each robot's joint names as the daemon publishes them)."""
    if recorded.cell != cell.cell:
        return f"the recording is of cell {recorded.cell!r}, the cell file's is {cell.cell!r}"
    in_cell = [r.name for r in cell.robots]
    missing = [r for r in robots if r not in in_cell]
    if missing:
        return (
            f"robots in the recording but not in cell {cell.cell!r}: {', '.join(missing)} "
            f"(recording: {', '.join(recorded.robots)}; cell: {', '.join(in_cell)})"
        )
    for robot in robots:
        want, have = recorded.names[robot], served.get(robot)
        if have is not None and tuple(have) != want:
            return (
                f"robot {robot!r}: joint names differ: the recording has {', '.join(want)}; "
                f"the cell has {', '.join(have)}"
            )
    return None


def sample_period(robot: Robot, cell: Cell) -> float:
    """Seconds between two of the robot's joint states: its cycle (as the daemon's backend runs it)
    times the cell's ``joint_states_decimation``."""
    from urdaemon.description.urmodels import load_ur_model

    if robot.backend == "servo" and robot.servo is not None:
        rate = float(robot.servo.rate_hz)
    elif robot.backend == "mock" and robot.mock is not None and robot.mock.rate_hz:
        rate = float(robot.mock.rate_hz)
    elif robot.is_ur:
        rate = float(load_ur_model(robot.model).control_rate_hz)
    else:
        rate = 100.0
    return cell.publish.joint_states_decimation / rate
