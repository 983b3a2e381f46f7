"""The request decoders: each takes what a client sent and returns typed values or raises
``MessageError`` naming the field and the problem (the envelope is envelope.py's, the checks of the
fields they share fields.py's). Range checks against a robot (limits, joint names, NaN) belong to
the controller, which rejects with its own reasons; here only the shape and types are checked.
"""

from __future__ import annotations

import dataclasses
import json
import math
import re
from collections.abc import Callable, Generator
from dataclasses import dataclass
from typing import Any

from urdaemon.control.trajectory import MAX_GOAL_TIME_S
from urdaemon.errors import MessageError
from urdaemon.model import (
    FORCE_MODE_DAMPING,
    FORCE_MODE_GAIN_SCALING,
    FORCE_MODE_TYPE,
    IO_SIZES,
    TOOL_VOLTAGES,
)
from urdaemon.publish import fields
from urdaemon.publish.envelope import (
    MAX_MESSAGE_BYTES,
    SMALL_MESSAGE_BYTES,
    check_version,
    client_text,
    decode_message,
)
from urdaemon.publish.fields import MAX_POSE_M, POSE_FRAMES, Pose6, ToleranceMessage

__all__ = [
    "CELL_GOAL_POLICIES",
    "CONFIGURATIONS",
    "LINEAR_LIMITS",
    "LINEAR_MESSAGE_BYTES",
    "LINEAR_POSES_PER_LOOK",
    "MAX_COG_M",
    "MAX_FORCE_MODE",
    "MAX_LINEAR_POSES",
    "MAX_PAYLOAD_KG",
    "MOVE_FIELDS",
    "TWIST_FRAMES",
    "WIRE_NAMES",
    "CellGoalDecoder",
    "CellGoalMessage",
    "LinearGoalDecoder",
    "LinearGoalMessage",
    "MoveGoalMessage",
    "StreamMessage",
    "TwistMessage",
    "decode_cancel",
    "decode_cell_cancel",
    "decode_cycle_stats",
    "decode_dashboard",
    "decode_empty",
    "decode_force_mode",
    "decode_freedrive",
    "decode_lease_tokens",
    "decode_linear_goal",
    "decode_move_goal",
    "decode_set_io",
    "decode_set_payload",
    "decode_set_tcp",
    "decode_speed_slider",
    "decode_stream_position",
    "decode_stream_velocity",
    "decode_tool_voltage",
    "decode_twist",
    "request_body",
]

MAX_PAYLOAD_KG = 35.0
"""Largest payload mass accepted: above every UR arm's rated payload (UR30: 30 kg)."""
MAX_COG_M = 1.0
"""Largest distance of the payload's centre of gravity from the tool flange along any axis (m)."""
MAX_FORCE_MODE = {"wrench": 1000.0, "limits": 10.0, "task_frame": 10.0}
"""Bounds of force mode's vectors: wrench (N, Nm), limits (m/s, rad/s or m, rad), task frame (m, rad)."""
WIRE_NAMES = {"force_type": "type"}
"""Request fields whose name in the message differs (``ForceModeRequest.force_type`` is ``type``)."""


def decode_empty(payload: bytes | None, what: str) -> None:
    """Check the request of a service that takes no arguments: nothing, an empty payload, ``{}`` or
    ``{"v": 1}``; anything else is refused, so garbage never acts."""
    if payload is None or len(payload) == 0:
        return
    data = decode_message(payload, what)
    fields.allowed(data, f"{what} takes no arguments, but got", set())


def decode_set_tcp(payload: bytes | None) -> Pose6:
    """Decode a set_tcp request: pose [x, y, z, rx, ry, rz] (m, rad), the TCP in the tool0 frame (its
    ranges are checked by the service: cell/config.py ``check_tcp``)."""
    what = "set_tcp"
    data = decode_message(payload, what)
    fields.allowed(data, what, {"pose"})
    if "pose" not in data:
        raise MessageError(f"{what}.pose: missing")
    return fields.pose(data["pose"], f"{what}.pose")


def decode_set_io(payload: bytes | None) -> tuple[str, int, float | bool]:
    """Decode a set_io request: kind, pin, value."""
    what = "set_io"
    data = decode_message(payload, what)
    fields.allowed(data, what, {"kind", "pin", "value"})
    kind, pin, value = data.get("kind"), data.get("pin"), data.get("value")
    if not isinstance(kind, str):
        raise MessageError(f"{what}.kind: expected one of {', '.join(IO_SIZES)}")
    if isinstance(pin, bool) or not isinstance(pin, int):
        raise MessageError(f"{what}.pin: expected an integer")
    if isinstance(value, bool):
        return kind, pin, value
    return kind, pin, fields.number(value, f"{what}.value")


def decode_set_payload(payload: bytes | None) -> tuple[float, tuple[float, float, float]]:
    """Decode a set_payload request: mass (kg), cog [x, y, z] (m)."""
    what = "set_payload"
    data = decode_message(payload, what)
    fields.allowed(data, what, {"mass", "cog"})
    mass = fields.number(data.get("mass"), f"{what}.mass")
    if not math.isfinite(mass) or mass < 0:
        raise MessageError(f"{what}.mass: must be a finite number ≥ 0, got {mass}")
    fields.within(mass, f"{what}.mass (kg)", 0.0, MAX_PAYLOAD_KG)
    cog = fields.numbers(data.get("cog", [0.0, 0.0, 0.0]), f"{what}.cog")
    if len(cog) != 3 or not all(math.isfinite(c) for c in cog):
        raise MessageError(f"{what}.cog: expected three finite numbers")
    for i, c in enumerate(cog):
        fields.within(c, f"{what}.cog[{i}] (m)", -MAX_COG_M, MAX_COG_M)
    return mass, (cog[0], cog[1], cog[2])


def decode_dashboard(payload: bytes | None) -> str:
    """Decode a dashboard request: command (one line, e.g. ``power on``)."""
    what = "dashboard"
    data = decode_message(payload, what)
    fields.allowed(data, what, {"command"})
    command = data.get("command")
    if not isinstance(command, str) or not command.strip():
        raise MessageError(f'{what}.command: expected a dashboard command line, e.g. "power on"')
    if not command.isprintable() or len(command) > 1024:
        raise MessageError(f"{what}.command: must be one line of at most 1024 printable characters")
    return command.strip()


def decode_tool_voltage(payload: bytes | None) -> int:
    """Decode a set_tool_voltage request: volts (0, 12 or 24)."""
    what = "set_tool_voltage"
    data = decode_message(payload, what)
    fields.allowed(data, what, {"volts"})
    volts = data.get("volts")
    if isinstance(volts, bool) or volts not in TOOL_VOLTAGES:
        raise MessageError(
            f"{what}.volts: must be {', '.join(map(str, TOOL_VOLTAGES[:-1]))} or {TOOL_VOLTAGES[-1]}"
        )
    return int(volts)


def decode_force_mode(payload: bytes | None) -> dict[str, Any]:
    """Decode a start_force_mode request into the fields of the script command (docs/protocols.md §4.5)."""
    what = "start_force_mode"
    data = decode_message(payload, what)
    fields.allowed(
        data, what, {"task_frame", "selection", "wrench", "type", "limits", "damping", "gain_scaling"}
    )
    decoded: dict[str, Any] = {}
    for key in ("task_frame", "wrench", "limits"):
        values = fields.numbers(data.get(key), f"{what}.{key}")
        if len(values) != 6 or not all(math.isfinite(v) for v in values):
            raise MessageError(f"{what}.{key}: expected six finite numbers")
        bound = MAX_FORCE_MODE[key]
        low = 0.0 if key == "limits" else -bound
        for i, v in enumerate(values):
            fields.within(v, f"{what}.{key}[{i}]", low, bound)
        decoded[key] = values
    selection = data.get("selection")
    if (
        not isinstance(selection, list)
        or len(selection) != 6
        or any(v not in (0, 1) or isinstance(v, bool) for v in selection)
    ):
        raise MessageError(f"{what}.selection: expected six 0/1 values")
    decoded["selection"] = tuple(int(v) for v in selection)
    force_type = data.get("type", FORCE_MODE_TYPE)
    if isinstance(force_type, bool) or force_type not in (1, 2, 3):
        raise MessageError(f"{what}.type: must be 1, 2 or 3")
    decoded["force_type"] = int(force_type)
    for key, low, high, default in (
        ("damping", 0.0, 1.0, FORCE_MODE_DAMPING),
        ("gain_scaling", 0.0, 2.0, FORCE_MODE_GAIN_SCALING),
    ):
        value = data.get(key, default)
        decoded[key] = fields.within(fields.number(value, f"{what}.{key}"), f"{what}.{key}", low, high)
    return decoded


def decode_speed_slider(payload: bytes | None) -> float:
    """Decode a set_speed_slider request: fraction in [0, 1]."""
    what = "set_speed_slider"
    data = decode_message(payload, what)
    fields.allowed(data, what, {"fraction"})
    return fields.within(
        fields.number(data.get("fraction"), f"{what}.fraction"), f"{what}.fraction", 0.0, 1.0
    )


def decode_cycle_stats(payload: bytes | None) -> bool:
    """Decode a cycle_stats request: whether to reset the counters after reading them (default no)."""
    what = "cycle_stats"
    if payload is None or len(payload) == 0:
        return False
    data = decode_message(payload, what)
    fields.allowed(data, what, {"reset"})
    return fields.boolean(data, "reset", what)


def request_body(request: object | None) -> dict[str, Any]:
    """A service request (a dataclass of model.py, or None: no arguments) as the message's fields."""
    if request is None:
        return {}
    body: dict[str, Any] = {}
    for item in dataclasses.fields(request):  # type: ignore[arg-type]
        value = getattr(request, item.name)
        body[WIRE_NAMES.get(item.name, item.name)] = list(value) if isinstance(value, tuple) else value
    return body


TWIST_FRAMES = ("base", "tool")
"""The frames a twist may be given in; ``base`` by default."""


@dataclass(frozen=True, slots=True)
class TwistMessage:
    """A decoded twist command: the TCP point's velocity (m/s) and angular velocity (rad/s)."""

    linear: tuple[float, float, float]
    angular: tuple[float, float, float]
    frame: str


@dataclass(frozen=True, slots=True)
class StreamMessage:
    """A decoded streaming command."""

    joint_names: tuple[str, ...] | None
    positions: tuple[float, ...] | None
    velocities: tuple[float, ...] | None


def decode_stream_position(payload: bytes | None) -> StreamMessage:
    """Decode a streaming joint position command: positions, velocities?, joint_names?."""
    what = "joint_position command"
    data = decode_message(payload, what)
    fields.allowed(data, what, {"joint_names", "positions", "velocities"})
    if "positions" not in data:
        raise MessageError(f"{what}.positions: missing")
    velocities = data.get("velocities")
    return StreamMessage(
        joint_names=fields.joint_names(data.get("joint_names"), f"{what}.joint_names"),
        positions=fields.numbers(data["positions"], f"{what}.positions"),
        velocities=None if velocities is None else fields.numbers(velocities, f"{what}.velocities"),
    )


def decode_stream_velocity(payload: bytes | None) -> StreamMessage:
    """Decode a streaming joint velocity command: velocities, joint_names?."""
    what = "joint_velocity command"
    data = decode_message(payload, what)
    fields.allowed(data, what, {"joint_names", "velocities"})
    if "velocities" not in data:
        raise MessageError(f"{what}.velocities: missing")
    return StreamMessage(
        joint_names=fields.joint_names(data.get("joint_names"), f"{what}.joint_names"),
        positions=None,
        velocities=fields.numbers(data["velocities"], f"{what}.velocities"),
    )


def decode_twist(payload: bytes | None) -> TwistMessage:
    """Decode a twist command: linear [3] (m/s), angular [3] (rad/s), frame? (base | tool)."""
    what = "twist command"
    data = decode_message(payload, what)
    fields.allowed(data, what, {"linear", "angular", "frame"})
    vectors = []
    for key in ("linear", "angular"):
        if key not in data:
            raise MessageError(f"{what}.{key}: missing")
        values = fields.numbers(data[key], f"{what}.{key}", max_len=3)
        if len(values) != 3 or not all(math.isfinite(v) for v in values):
            raise MessageError(f"{what}.{key}: expected three finite numbers")
        vectors.append((values[0], values[1], values[2]))
    return TwistMessage(vectors[0], vectors[1], fields.choice(data, "frame", what, TWIST_FRAMES))


def decode_freedrive(payload: bytes | None) -> bool:
    """Decode a freedrive command: active (true keeps freedrive on for one deadman period, false ends it)."""
    what = "freedrive command"
    data = decode_message(payload, what)
    fields.allowed(data, what, {"active"})
    return fields.boolean(data, "active", what, default=True)


def decode_cancel(payload: bytes | None) -> str | None:
    """Decode a cancel request: the goal id, or None (or an empty payload) for the active goal."""
    if payload is None or len(payload) == 0:
        return None
    what = "cancel"
    data = decode_message(payload, what)
    fields.allowed(data, what, {"goal_id"})
    goal_id = data.get("goal_id")
    if goal_id is not None and not isinstance(goal_id, str):
        raise MessageError(f"{what}.goal_id: expected a string")
    if goal_id is not None and (len(goal_id) > 200 or not goal_id.isprintable()):
        raise MessageError(f"{what}.goal_id: {client_text(goal_id)!r} is not a goal id")
    return goal_id


def decode_cell_cancel(payload: bytes | None) -> str:
    """Decode a cell goal's cancel: ``{"goal_id": G}`` (the id is required)."""
    goal_id = decode_cancel(payload)
    if goal_id is None:
        raise MessageError("cell cancel.goal_id: required (the cell goal's id)")
    return goal_id


CONFIGURATIONS = {"shoulder": ("left", "right"), "elbow": ("up", "down"), "wrist": ("up", "down")}
"""A pose goal's ``configuration``: each joint group it may name and the values it may take."""
MOVE_FIELDS = frozenset(
    {
        "joint_names",
        "positions",
        "pose",
        "frame",
        "configuration",
        "duration",
        "velocity_scale",
        "acceleration_scale",
        "tolerances",
        "preempt",
    }
)
"""The fields of a move goal (``pose``, ``frame``, ``configuration``: a pose goal's)."""


@dataclass(frozen=True, slots=True)
class MoveGoalMessage:
    """A decoded point-to-point move goal: to joint ``positions``, or to a TCP ``pose`` (then
    ``positions`` is empty)."""

    joint_names: tuple[str, ...] | None
    positions: tuple[float, ...]
    duration: float | None
    velocity_scale: float
    acceleration_scale: float
    tolerances: ToleranceMessage
    preempt: bool
    pose: Pose6 | None = None
    """The TCP pose to reach (x, y, z m, rotation vector rad), in ``frame``; None: ``positions``."""
    frame: str = "base"
    configuration: tuple[tuple[str, str], ...] = ()
    """The wanted configuration's (joint group, value) pairs (UR models), e.g. ``(("elbow", "up"),)``."""


def decode_move_goal(payload: bytes | None) -> MoveGoalMessage:
    """Decode a move goal: exactly one of positions (joints, joint_names?) or pose (the TCP, frame?,
    configuration?), and duration?, velocity_scale?, acceleration_scale?, tolerances?, preempt?."""
    what = "move goal"
    data = decode_message(payload, what)
    fields.allowed(data, what, set(MOVE_FIELDS))
    has_pose = data.get("pose") is not None
    if has_pose and data.get("positions") is not None:
        raise MessageError(f"{what}: give positions (joints) or pose (the TCP), not both")
    if not has_pose and "positions" not in data:
        raise MessageError(f"{what}.positions: missing")
    if not has_pose:
        for key in ("frame", "configuration"):
            if data.get(key) is not None:
                raise MessageError(f"{what}.{key}: only a pose goal has a {key} (send pose, not positions)")
    elif data.get("joint_names") is not None:
        raise MessageError(f"{what}.joint_names: a pose goal names no joints")
    velocity_scale = fields.optional_number(data, "velocity_scale", what)
    acceleration_scale = fields.optional_number(data, "acceleration_scale", what)
    for key, scale in (("velocity_scale", velocity_scale), ("acceleration_scale", acceleration_scale)):
        if scale is not None:
            fields.within(scale, f"{what}.{key}", 0.0, 1.0, open_low=True)
    duration = fields.optional_number(data, "duration", what)
    if duration is not None:
        fields.within(duration, f"{what}.duration", 0.0, MAX_GOAL_TIME_S, open_low=True)
    return MoveGoalMessage(
        joint_names=fields.joint_names(data.get("joint_names"), f"{what}.joint_names"),
        positions=() if has_pose else fields.numbers(data["positions"], f"{what}.positions"),
        duration=duration,
        velocity_scale=1.0 if velocity_scale is None else velocity_scale,
        acceleration_scale=1.0 if acceleration_scale is None else acceleration_scale,
        tolerances=fields.tolerances(data.get("tolerances"), what),
        preempt=fields.boolean(data, "preempt", what),
        pose=fields.pose(data["pose"], f"{what}.pose") if has_pose else None,
        frame=fields.choice(data, "frame", what, POSE_FRAMES),
        configuration=_configuration(data.get("configuration"), f"{what}.configuration"),
    )


def _configuration(value: Any, field: str) -> tuple[tuple[str, str], ...]:
    """A pose goal's configuration: any of shoulder left|right, elbow up|down, wrist up|down."""
    if value is None:
        return ()
    if not isinstance(value, dict):
        raise MessageError(f"{field}: expected an object with any of shoulder, elbow, wrist")
    fields.allowed(value, field, set(CONFIGURATIONS))
    chosen = []
    for group, values in CONFIGURATIONS.items():
        item = value.get(group)
        if item is None:
            continue
        if item not in values:
            raise MessageError(f"{field}.{group}: expected {' or '.join(values)}, got {fields.shown(item)}")
        chosen.append((group, str(item)))
    return tuple(chosen)


LINEAR_LIMITS = ("speed", "acceleration", "jerk", "angular_speed", "angular_acceleration", "angular_jerk")
"""A linear goal's own Cartesian limits, each optional (m/s, m/s², m/s³, rad/s, rad/s², rad/s³)."""
MAX_LINEAR_POSES = 100
"""Most poses of one linear goal: as many as fit, with every blend radius and field, in the node's
ordinary message size (``LINEAR_MESSAGE_BYTES``); a longer path is sent as several goals."""
LINEAR_MESSAGE_BYTES = SMALL_MESSAGE_BYTES
"""Largest linear goal: the node's ordinary 16 KiB, so its JSON is parsed in one call like every other
non-trajectory message (~0.3 ms at most; 256 KiB held the loop 5-9 ms). 100 poses and 99 blend radii
of full-precision numbers with every field are ~15.6 KB as compact JSON; its poses are checked in
slices (``LinearGoalDecoder``)."""
LINEAR_POSES_PER_LOOK = 16
"""Poses of a linear goal checked between two looks at the clock (~3 µs each)."""


@dataclass(frozen=True, slots=True)
class LinearGoalMessage:
    """A decoded linear goal: straight TCP lines from the current pose through each of ``poses``."""

    poses: tuple[Pose6, ...]
    frame: str
    blend_radii: tuple[float, ...]
    """One per corner (``len(poses) - 1``), m; zeros when left out."""
    limits: tuple[tuple[str, float], ...]
    """The Cartesian limits the goal names (field, value), each > 0; the rest are the cell's defaults."""
    tolerances: ToleranceMessage


def decode_linear_goal(payload: bytes | None) -> LinearGoalMessage:
    """Decode a linear goal at once (the daemon uses ``LinearGoalDecoder``, in slices)."""
    decoder = LinearGoalDecoder(payload)
    while decoder.step(math.inf, lambda: 0.0):
        pass
    return decoder.result()


class LinearGoalDecoder:
    """Decodes a linear goal: poses (1..100), frame?, blend_radii?, speed?, acceleration?, jerk?,
    angular_speed?, angular_acceleration?, angular_jerk?, tolerances?.

    The JSON is parsed at once (at most ``LINEAR_MESSAGE_BYTES``, refused by size before parsing:
    ~0.3 ms); its poses are checked
    ``LINEAR_POSES_PER_LOOK`` at a time by ``step(deadline, clock)`` (True while work is left), so
    the checks of a hundred poses (~0.3 ms) run in slices between robot cycles (runtime/slicing.py).
    """

    def __init__(self, payload: bytes | None) -> None:
        what = self._what = "linear goal"
        data = decode_message(payload, what, max_bytes=LINEAR_MESSAGE_BYTES)
        fields.allowed(data, what, {"poses", "frame", "blend_radii", "tolerances", *LINEAR_LIMITS})
        raw = data.get("poses")
        if not isinstance(raw, list) or not raw:
            raise MessageError(f"{what}.poses: expected a list of one or more poses [x, y, z, rx, ry, rz]")
        if len(raw) > MAX_LINEAR_POSES:
            raise MessageError(f"{what}.poses: {len(raw)} poses; at most {MAX_LINEAR_POSES} are accepted")
        self._data = data
        self._raw: list[Any] = raw
        self._poses: list[Pose6] = []
        self._raw_radii: Any = None
        self._radii: list[float] | None = None
        self._result: LinearGoalMessage | None = None

    def step(self, deadline: float, clock: Callable[[], float]) -> bool:
        """Check poses, then blend radii, until ``clock()`` passes ``deadline`` (at least a few); True
        while work is left. Raises ``MessageError``."""
        while self._result is None:
            if not self._next():
                self._result = self._finish()
            elif clock() > deadline:
                return True
        return False

    def result(self) -> LinearGoalMessage:
        """The decoded goal."""
        if self._result is None:
            raise RuntimeError("the linear goal is not decoded yet")
        return self._result

    def _next(self) -> bool:
        """Check the next few poses or radii; False once all are checked."""
        raw, poses, what = self._raw, self._poses, self._what
        if len(poses) < len(raw):
            for i in range(len(poses), min(len(raw), len(poses) + LINEAR_POSES_PER_LOOK)):
                poses.append(fields.pose(raw[i], f"{what}.poses[{i}]"))
            return True
        field = f"{what}.blend_radii"
        if self._radii is None:
            given = self._data.get("blend_radii")
            self._raw_radii = [0.0] * (len(raw) - 1) if given is None else given
            self._radii = []
            if not isinstance(self._raw_radii, list):
                raise MessageError(f"{field}: expected a list of numbers, got {type(given).__name__}")
            if len(self._raw_radii) != len(raw) - 1:
                raise MessageError(
                    f"{field}: {len(self._raw_radii)} radii for {len(raw)} poses; expected {len(raw) - 1} "
                    "(one per corner)"
                )
        radii, given = self._radii, self._raw_radii
        if len(radii) < len(given):
            for i in range(len(radii), min(len(given), len(radii) + 6 * LINEAR_POSES_PER_LOOK)):
                radius = fields.number(given[i], f"{field}[{i}]")
                radii.append(fields.within(radius, f"{field}[{i}] (m)", 0.0, MAX_POSE_M))
            return True
        return False

    def _finish(self) -> LinearGoalMessage:
        data, what, poses = self._data, self._what, tuple(self._poses)
        limits = []
        for key in LINEAR_LIMITS:
            value = fields.optional_number(data, key, what)
            if value is not None:
                if not (value > 0.0 and math.isfinite(value)):
                    raise MessageError(f"{what}.{key}: must be a finite number > 0, got {value:g}")
                limits.append((key, value))
        return LinearGoalMessage(
            poses=poses,
            frame=fields.choice(data, "frame", what, POSE_FRAMES),
            blend_radii=tuple(self._radii or ()),
            limits=tuple(limits),
            tolerances=fields.tolerances(data.get("tolerances"), what),
        )


CELL_GOAL_POLICIES = ("stop_all", "continue")
"""What a cell goal does when one robot's part ends other than succeeded: stop the others, or not."""
_CELL_GOAL = "cell goal"
_CELL_KEY_BYTES = 256
"""Longest text of a field name or a robot name in a cell goal."""
_CELL_FIELD_BYTES = 1024
"""Longest text of a cell goal's own fields (``v``, ``on_abort``)."""
_SCAN_BYTES = 64 * 1024
"""Bytes searched for the next bracket or quote in one step, when a robot's part is delimited."""
_SCAN_TOKENS = 256
"""Brackets and texts passed in one step."""
_TEXT_BYTES = 16 * 1024
"""Longest JSON text (a quoted string) inside a robot's part."""
_STRUCTURE = re.compile(rb'[][{}"]')
_STRING_REST = re.compile(rb'(?:[^"\\]++|\\.)*+"')
_SPACE = re.compile(rb"[ \t\n\r]{0,4096}")
_DONE = object()


@dataclass(frozen=True, slots=True)
class CellGoalMessage:
    """A cell goal as sent: each robot's trajectory goal body (undecoded), and the abort policy."""

    robots: dict[str, memoryview]
    on_abort: str


class CellGoalDecoder:
    """Splits a cell goal ``{"robots": {"alice": {...}, ...}, "on_abort": ...}`` into each robot's
    trajectory goal body, a piece at a time (``advance()`` until False, then ``result()``): a part
    is delimited by counting its brackets, never decoded here (each robot's own decoder does that,
    in slices too), so no step costs more than searching ``_SCAN_BYTES`` or passing
    ``_SCAN_TOKENS`` brackets. Every error is a ``MessageError``."""

    def __init__(self, payload: bytes | None, *, max_bytes: int = MAX_MESSAGE_BYTES) -> None:
        if payload is None or len(payload) == 0:
            raise MessageError(f"{_CELL_GOAL}: empty message; expected a JSON object")
        if len(payload) > max_bytes:
            raise MessageError(
                f"{_CELL_GOAL}: message of {len(payload)} bytes exceeds the limit of {max_bytes} bytes"
            )
        self._data = bytes(payload)
        self._decoder = json.JSONDecoder()
        self._steps = self._run()
        self._result: CellGoalMessage | None = None

    def advance(self) -> bool:
        """One bounded step; True while work is left (``slicing.until_deadline`` runs it in slices)."""
        return next(self._steps, _DONE) is not _DONE

    def result(self) -> CellGoalMessage:
        """The split goal."""
        if self._result is None:
            raise RuntimeError("the cell goal is not split yet")
        return self._result

    def _run(self) -> Generator[None, None, None]:
        pos = self._expect(self._space(0), b"{", "a JSON object")
        own: dict[str, Any] = {}
        robots: dict[str, memoryview] | None = None
        if self._data.startswith(b"}", self._space(pos)):
            pos = self._space(pos) + 1
        else:
            while True:
                key, pos = self._value(pos, _CELL_KEY_BYTES, "a field name")
                if not isinstance(key, str):
                    raise MessageError(f"{_CELL_GOAL}: expected a field name at byte {pos}")
                pos = self._expect(pos, b":", "':' after a field name")
                if key == "robots":
                    robots, pos = yield from self._robots(pos)
                else:
                    own[key], pos = self._value(pos, _CELL_FIELD_BYTES, key)
                if self._data.startswith(b",", self._space(pos)):
                    pos = self._space(pos) + 1
                    continue
                pos = self._expect(pos, b"}", "',' or '}' after a field")
                break
        if self._space(pos) != len(self._data):
            raise MessageError(f"{_CELL_GOAL}: not valid JSON: extra data at byte {self._space(pos)}")
        self._result = _cell_goal(own, robots)

    def _robots(self, pos: int) -> Generator[None, None, tuple[dict[str, memoryview], int]]:
        pos = self._expect(pos, b"{", f"{_CELL_GOAL}.robots: an object naming each robot's trajectory")
        robots: dict[str, memoryview] = {}
        if self._data.startswith(b"}", self._space(pos)):
            return robots, self._space(pos) + 1
        while True:
            name, pos = self._value(pos, _CELL_KEY_BYTES, "a robot name")
            if not isinstance(name, str):
                raise MessageError(f"{_CELL_GOAL}.robots: expected a robot name at byte {pos}")
            what = f"{_CELL_GOAL}.robots.{client_text(name)}"
            if name in robots:
                raise MessageError(f"{what}: the robot is named twice")
            pos = self._expect(pos, b":", "':' after a robot name")
            start = self._space(pos)
            if not self._data.startswith(b"{", start):
                raise MessageError(f"{what}: expected a trajectory goal (a JSON object)")
            end = yield from self._object_end(start, what)
            robots[name] = memoryview(self._data)[start:end]
            if self._data.startswith(b",", self._space(end)):
                pos = self._space(end) + 1
                continue
            return robots, self._expect(end, b"}", "',' or '}' after a robot's trajectory")

    def _object_end(self, pos: int, what: str) -> Generator[None, None, int]:
        """Where the object at ``pos`` ends: its brackets counted, quoted texts passed over."""
        data, depth, passed = self._data, 0, 0
        while True:
            found = _STRUCTURE.search(data, pos, pos + _SCAN_BYTES)
            if found is None:
                if pos + _SCAN_BYTES >= len(data):
                    raise MessageError(f"{what}: not valid JSON: the object does not end")
                pos += _SCAN_BYTES
                yield None
                continue
            char, pos = data[found.start()], found.end()
            if char == 0x22:  # a quoted text: passed over whole, brackets in it do not count
                text = _STRING_REST.match(data, pos, pos + _TEXT_BYTES)
                if text is None:
                    raise MessageError(
                        f"{what}: a text at byte {pos} is unterminated or over {_TEXT_BYTES} bytes"
                    )
                pos = text.end()
            elif char in b"{[":
                depth += 1
            else:
                depth -= 1
                if depth == 0:
                    return pos
            passed += 1
            if passed % _SCAN_TOKENS == 0:
                yield None

    def _value(self, pos: int, limit: int, what: str) -> tuple[Any, int]:
        """One JSON value of at most ``limit`` bytes at ``pos`` (after whitespace), and the byte after it."""
        pos = self._space(pos)
        window = self._data[pos : pos + limit]
        try:
            text = window.decode()
        except UnicodeDecodeError as err:
            if err.end < len(window) or pos + limit >= len(self._data):  # not a character cut short
                raise MessageError(f"{_CELL_GOAL}: not valid JSON: not UTF-8 text ({err.reason})") from err
            text = window[: err.start].decode()
        try:
            value, end = self._decoder.raw_decode(text)
        except (ValueError, RecursionError) as err:
            raise MessageError(
                f"{_CELL_GOAL}: not valid JSON: {what} at byte {pos} is malformed or over {limit} bytes"
            ) from err
        return value, pos + len(text[:end].encode())

    def _space(self, pos: int) -> int:
        found = _SPACE.match(self._data, pos)
        return pos if found is None else found.end()

    def _expect(self, pos: int, char: bytes, what: str) -> int:
        pos = self._space(pos)
        if not self._data.startswith(char, pos):
            raise MessageError(f"{_CELL_GOAL}: not valid JSON: expected {what} at byte {pos}")
        return pos + 1


def _cell_goal(own: dict[str, Any], robots: dict[str, memoryview] | None) -> CellGoalMessage:
    check_version(own, _CELL_GOAL)
    fields.allowed(own, _CELL_GOAL, {"on_abort"})
    if not robots:
        raise MessageError(f"{_CELL_GOAL}.robots: expected an object naming at least one robot's trajectory")
    on_abort = own.get("on_abort", CELL_GOAL_POLICIES[0])
    if on_abort not in CELL_GOAL_POLICIES:
        raise MessageError(
            f"{_CELL_GOAL}.on_abort: expected one of {', '.join(CELL_GOAL_POLICIES)}, "
            f"got {fields.shown(on_abort)}"
        )
    return CellGoalMessage(robots, on_abort)


def decode_lease_tokens(attachment: bytes | None, limit: int = SMALL_MESSAGE_BYTES) -> dict[str, bytes]:
    """A cell request's attachment: each robot's lease token, ``{"alice": T, ...}`` (empty: none)."""
    if attachment is None or len(attachment) == 0:
        return {}
    if len(attachment) > limit:
        raise MessageError(f"lease tokens: attachment of {len(attachment)} bytes exceeds {limit} bytes")
    try:
        data = json.loads(attachment)
    except (ValueError, RecursionError) as err:
        raise MessageError("lease tokens: the attachment is not a JSON object of robot tokens") from err
    if not isinstance(data, dict) or not all(isinstance(v, str) for v in data.values()):
        raise MessageError('lease tokens: the attachment must be a JSON object {"<robot>": "<token>", ...}')
    # a token that is not ASCII is no holder's token: kept (as one that matches none), so the robot
    # it names is still checked and refused naming its lease
    return {name: token.encode() if token.isascii() else b"" for name, token in data.items()}
