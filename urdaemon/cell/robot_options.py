"""One robot of the cell file: its model, backend, ports, pose, TCP, limits and motion options, and the
options of the ``ur``, ``mock`` and custom-description sections (``servo``'s are in servo.py)."""

from __future__ import annotations

import ipaddress
import math
import re
from typing import Annotated, Literal

from pydantic import Field, ValidationInfo, field_validator, model_validator

from urdaemon.cell.schema_types import HOST_NAME_PATTERN, MIN_CYCLE_RATE_HZ, Finite, Frozen, resolve_file
from urdaemon.cell.servo import ServoOptions
from urdaemon.model import UR_JOINTS
from urdaemon.paths import resource_path
from urdaemon.urscript import (
    DEFAULT_KEEPALIVE_CYCLES,
    DEFAULT_SERVOJ_GAIN,
    DEFAULT_SERVOJ_LOOKAHEAD_S,
    KEEPALIVE_CYCLES_RANGE,
    SERVOJ_GAIN_RANGE,
    SERVOJ_LOOKAHEAD_RANGE_S,
)

__all__ = [
    "CARTESIAN_PAIRS",
    "NAME_PATTERN",
    "READ_ONLY_REASON",
    "TCP_MAX_OFFSET_M",
    "TCP_MAX_ROTATION_RAD",
    "CartesianOptions",
    "CustomDescription",
    "JointLimitOverride",
    "MockOptions",
    "MotionOptions",
    "Ports",
    "Pose",
    "Robot",
    "UrAutoRecover",
    "UrOptions",
    "check_host",
    "check_tcp",
    "ur_models",
]

NAME_PATTERN = r"^[a-z][a-z0-9_]{0,30}$"
"""Robot names: a key chunk and a joint/link prefix (``alice`` → ``alice_`` and ``<cell>/alice/``)."""
_LOOKAHEAD = SERVOJ_LOOKAHEAD_RANGE_S
_GAIN = (int(SERVOJ_GAIN_RANGE[0]), int(SERVOJ_GAIN_RANGE[1]))
"""servoj's limits (urscript.py), the gain as the whole numbers the cell file takes."""
READ_ONLY_REASON = "read-only robot (ur.read_only: true): it is watched, not commanded"
"""What a read-only robot (``UrOptions.read_only``) answers to whatever would command it: the
endpoints' refusals (publish/endpoints.py) and the UR backend's own (backends/ur/links.py)."""


def check_host(value: str, what: str) -> str:
    """``value`` if it is an IP address or a host name (no port, no scheme), else ValueError."""
    try:
        ipaddress.ip_address(value)
    except ValueError:
        pass
    else:
        return value
    if re.match(HOST_NAME_PATTERN, value):
        return value
    host, colon, port = value.rpartition(":")
    if colon and port.isdigit():
        raise ValueError(
            f"{value!r}: give the {what} without a port ({host!r}); UR's ports are fixed "
            "(dashboard 29999, primary 30001, RTDE 30004) and the callback ports go in 'ports'"
        )
    raise ValueError(f"{value!r} is not an IP address or host name")


Vec3 = tuple[Finite, Finite, Finite]
TCP_MAX_OFFSET_M = 1.0
"""Largest TCP translation along each flange axis, in metres."""
TCP_MAX_ROTATION_RAD = math.pi
"""Largest TCP rotation (the rotation vector's length), in radians."""


def check_tcp(pose: tuple[float, ...]) -> tuple[float, ...]:
    """A TCP offset ``[x, y, z, rx, ry, rz]`` within range, or ValueError saying what is out of range."""
    if len(pose) != 6:
        raise ValueError(f"a TCP offset has 6 values [x, y, z, rx, ry, rz], not {len(pose)}")
    if not all(math.isfinite(v) for v in pose):
        raise ValueError("a TCP offset's values must be finite")
    for axis, value in zip("xyz", pose[:3], strict=True):
        if abs(value) > TCP_MAX_OFFSET_M:
            raise ValueError(f"TCP {axis} = {value} m is beyond ±{TCP_MAX_OFFSET_M} m")
    angle = math.hypot(*pose[3:])
    if angle > TCP_MAX_ROTATION_RAD:
        raise ValueError(f"TCP rotation {angle:.6g} rad is beyond pi (the rotation vector's length)")
    return pose


PortNumber = Annotated[int, Field(ge=1, le=65535, strict=True)]


def ur_models() -> tuple[str, ...]:
    """The UR models whose data ships in ``resources/ur``."""
    return tuple(sorted(p.stem for p in resource_path("ur").glob("ur*.yaml")))


class Ports(Frozen):
    """Host ports the robot's control program connects back to."""

    reverse: PortNumber
    script_sender: PortNumber
    trajectory: PortNumber
    script_command: PortNumber

    @classmethod
    def block(cls, base: int) -> Ports:
        """Four consecutive ports starting at ``base``."""
        return cls(reverse=base, script_sender=base + 1, trajectory=base + 2, script_command=base + 3)

    def as_dict(self) -> dict[str, int]:
        """Port role → number."""
        return {
            "reverse": self.reverse,
            "script_sender": self.script_sender,
            "trajectory": self.trajectory,
            "script_command": self.script_command,
        }

    @model_validator(mode="after")
    def _distinct(self) -> Ports:
        seen: dict[int, str] = {}
        for role, port in self.as_dict().items():
            if port in seen:
                raise ValueError(f"{role} port {port} is also the {seen[port]} port")
            seen[port] = role
        return self


class Pose(Frozen):
    """Where the robot's base_link sits relative to its parent link."""

    parent: Annotated[str, Field(pattern=r"^[A-Za-z0-9_]+$")] = "world"
    xyz: Vec3 = (0.0, 0.0, 0.0)
    """Translation in metres."""
    rpy: Vec3 = (0.0, 0.0, 0.0)
    """Roll, pitch, yaw in radians (URDF convention)."""


class JointLimitOverride(Frozen):
    """Tighter (or, knowingly, other) limits for one joint; unset fields keep the model's value."""

    min_position: Finite | None = None
    max_position: Finite | None = None
    max_velocity: Annotated[float, Field(gt=0, allow_inf_nan=False)] | None = None
    max_acceleration: Annotated[float, Field(gt=0, allow_inf_nan=False)] | None = None
    max_jerk: Annotated[float, Field(gt=0, allow_inf_nan=False)] | None = None

    @model_validator(mode="after")
    def _ordered(self) -> JointLimitOverride:
        if (
            self.min_position is not None
            and self.max_position is not None
            and self.min_position >= self.max_position
        ):
            raise ValueError(
                f"min_position {self.min_position} must be below max_position {self.max_position}"
            )
        return self


Positive = Annotated[float, Field(gt=0, allow_inf_nan=False)]
CARTESIAN_PAIRS = (
    ("speed", "max_speed", "m/s"),
    ("acceleration", "max_acceleration", "m/s²"),
    ("jerk", "max_jerk", "m/s³"),
    ("angular_speed", "max_angular_speed", "rad/s"),
    ("angular_acceleration", "max_angular_acceleration", "rad/s²"),
    ("angular_jerk", "max_angular_jerk", "rad/s³"),
)
"""Each Cartesian default, the cap it must stay within, and its unit."""


class CartesianOptions(Frozen):
    """A robot's Cartesian motion limits (TCP point: m/s, m/s², m/s³; TCP frame: rad/s, rad/s², rad/s³).

    ``max_*`` are caps: no linear goal or twist may ask for more. The others are what a linear goal
    uses for a limit it leaves out, and what twist streaming smooths with (acceleration and jerk).
    """

    max_speed: Positive = 1.0
    max_acceleration: Positive = 5.0
    max_jerk: Positive = 50.0
    max_angular_speed: Positive = 3.0
    max_angular_acceleration: Positive = 15.0
    max_angular_jerk: Positive = 150.0
    speed: Positive = 0.25
    acceleration: Positive = 1.2
    jerk: Positive = 10.0
    angular_speed: Positive = 1.0
    angular_acceleration: Positive = 4.0
    angular_jerk: Positive = 40.0

    @model_validator(mode="after")
    def _defaults_within_caps(self) -> CartesianOptions:
        for name, cap, unit in CARTESIAN_PAIRS:
            value, limit = getattr(self, name), getattr(self, cap)
            if value > limit:
                raise ValueError(f"{name} {value:g} {unit} is above {cap} {limit:g} {unit}")
        return self


class MotionOptions(Frozen):
    """Defaults for goal tolerances and the streaming deadman, and the Cartesian limits."""

    path_tolerance: Annotated[float, Field(gt=0, allow_inf_nan=False)] = 0.2
    """Largest allowed |desired − measured| per joint while a goal runs (rad)."""
    goal_tolerance: Annotated[float, Field(gt=0, allow_inf_nan=False)] = 0.01
    """Largest allowed |goal − measured| per joint at the end (rad)."""
    goal_time_tolerance: Annotated[float, Field(ge=0, allow_inf_nan=False)] = 1.0
    """Seconds allowed after the planned end to come within goal tolerance."""
    stream_timeout: Annotated[float, Field(gt=0, le=10, allow_inf_nan=False)] = 0.2
    """Deadman: a stream with no new command for this long is brought to a smooth stop (s)."""
    feedback_rate_hz: Annotated[float, Field(ge=1, le=500)] = 10.0
    """Goal feedback messages a second while a goal runs."""
    cartesian: CartesianOptions = CartesianOptions()
    """Caps and defaults of Cartesian motion (linear goals, twists)."""


DEFAULT_RECEIVE_TIMEOUT_MS = 1000
"""The default window (ms): a hiccup of the host shorter than this loses no program (0.82 s of
silence was seen on a busy 2-core PC)."""
RECEIVE_TIMEOUT_MS_RANGE = (10, 10_000)
"""Allowed ``receive_timeout_ms``: at least a few cycles, at most 10 s of a robot left alone."""


def _old_ms(value: object) -> str:
    """The old key's seconds in ms, for the error's example (the value as given if not a number)."""
    if isinstance(value, int | float) and not isinstance(value, bool) and math.isfinite(value):
        return str(round(value * 1000))
    return str(DEFAULT_RECEIVE_TIMEOUT_MS)


class UrAutoRecover(Frozen):
    """``ur.auto_recover``: what the backend recovers from by itself, and how often."""

    protective_stop: bool = False
    """After a protective stop: wait the controller's 5 s, unlock it, then resend (headless) or play."""
    max_attempts: Annotated[int, Field(strict=True, ge=1, le=100)] = 3
    """Recoveries allowed within ``within_s``; past them the robot is left as it is, and says so."""
    within_s: Annotated[float, Field(gt=0, le=86_400, allow_inf_nan=False)] = 60.0


class UrOptions(Frozen):
    """Options of the ``ur`` backend."""

    startup: bool = False
    """At start-up (and after every reconnect): power on, release the brakes and start the program."""
    reverse_ip: str | None = None
    """Address the robot connects back to; default: the daemon's end of its RTDE connection."""
    listen_address: str | None = None
    """Where the four callback servers listen; default: the address of this machine's interface that
    reaches the robot (they accept connections from the robot's address only, on either)."""
    servoj_lookahead: Annotated[float, Field(ge=_LOOKAHEAD[0], le=_LOOKAHEAD[1])] = DEFAULT_SERVOJ_LOOKAHEAD_S
    """servoj lookahead time (s); UR allows 0.03–0.2."""
    servoj_gain: Annotated[int, Field(ge=_GAIN[0], le=_GAIN[1])] = DEFAULT_SERVOJ_GAIN
    receive_timeout_ms: Annotated[
        int, Field(strict=True, ge=RECEIVE_TIMEOUT_MS_RANGE[0], le=RECEIVE_TIMEOUT_MS_RANGE[1])
    ] = DEFAULT_RECEIVE_TIMEOUT_MS
    """The window (ms): the control program ends only when no frame arrives for this long; a frame
    within it is followed without a program restart (docs/operating.md, busy PCs)."""
    keepalive_cycles: Annotated[
        int, Field(strict=True, ge=KEEPALIVE_CYCLES_RANGE[0], le=KEEPALIVE_CYCLES_RANGE[1])
    ] = DEFAULT_KEEPALIVE_CYCLES
    """Controller cycles without a frame during which the program goes on with the last command (a
    servoj stream extrapolated within the joint speed limits, a speedj velocity, a trajectory); past
    them it stops the arm with ``stopj`` and waits for the next frame, until ``receive_timeout_ms``."""
    auto_recover: UrAutoRecover | None = None
    """Recover from a protective stop by itself (opt-in; never from an emergency stop)."""
    calibration_check: Literal["warn", "error"] = "warn"
    """A kinematics hash that differs from the configured calibration: log a warning, or refuse to run."""
    read_only: bool = False
    """Only watch the robot: RTDE outputs (state published as usual), the primary interface and the
    dashboard; no RTDE inputs are claimed, no program is sent, no callback server listens, and goals
    and services that would command the robot are refused. For a robot another program drives."""

    @field_validator("reverse_ip", "listen_address")
    @classmethod
    def _host(cls, value: str | None, info: ValidationInfo) -> str | None:
        return None if value is None else check_host(value, str(info.field_name))

    @model_validator(mode="before")
    @classmethod
    def _old_receive_timeout(cls, data: object) -> object:
        if isinstance(data, dict) and "receive_timeout" in data:
            raise ValueError(
                f"receive_timeout (s) is now receive_timeout_ms (ms, default {DEFAULT_RECEIVE_TIMEOUT_MS}), "
                f"with keepalive_cycles (default {DEFAULT_KEEPALIVE_CYCLES}): write e.g. "
                f"receive_timeout_ms: {_old_ms(data['receive_timeout'])} (docs/cell-file.md)"
            )
        return data

    @model_validator(mode="after")
    def _read_only_does_not_start(self) -> UrOptions:
        if self.read_only and self.startup:
            raise ValueError("read_only: a read-only robot cannot also be started up (startup: true)")
        if self.read_only and self.auto_recover is not None and self.auto_recover.protective_stop:
            raise ValueError("read_only: a read-only robot cannot also recover by itself (auto_recover)")
        return self


class MockOptions(Frozen):
    """Options of the ``mock`` backend."""

    initial_positions: tuple[Finite, ...] | dict[str, Finite] | None = None
    """Start pose: a list in joint order, or joint name (without prefix) → value."""
    speed_scaling: Annotated[float, Field(ge=0, le=1, allow_inf_nan=False)] = 1.0
    """The runtime speed scaling the mock reports (multiplied with the speed slider)."""
    rate_hz: Annotated[float, Field(ge=MIN_CYCLE_RATE_HZ, le=1000)] | None = None
    """Cycle rate, 10..1000 Hz; default: the model's controller rate (500 Hz e-Series, 125 Hz CB3)."""


class CustomDescription(Frozen):
    """A robot described by its own xacro macro, called as ``<xacro:MACRO prefix parent><origin/>``."""

    xacro: str
    """Path of the xacro file that defines the macro (relative to the cell file)."""
    macro: Annotated[str, Field(pattern=r"^[A-Za-z_][A-Za-z0-9_]*$")]
    base_link: str = "base_link"
    tool_link: str = "tool0"
    default_max_acceleration: Annotated[float, Field(gt=0, allow_inf_nan=False)] = 5.0
    default_max_jerk: Annotated[float, Field(gt=0, allow_inf_nan=False)] = 50.0

    @field_validator("xacro")
    @classmethod
    def _exists(cls, value: str, info: ValidationInfo) -> str:
        return resolve_file(value, info)


class Robot(Frozen):
    """One robot of the cell."""

    name: Annotated[str, Field(pattern=NAME_PATTERN)]
    model: str
    """A UR model whose data ships (ur3 … ur30), or ``custom`` with a ``description``."""
    backend: Literal["mock", "servo", "ur"]
    address: str | None = None
    """The robot controller's address (required by the ``ur`` backend)."""
    ports: Ports
    """Host ports; when left out, the cell assigns a block of four no other robot uses."""
    headless: bool = True
    calibration: str | None = None
    """Kinematics calibration file (relative to the cell file)."""
    joint_limits: dict[str, JointLimitOverride] = Field(default_factory=dict)
    """Joint name without prefix → limit overrides."""
    pose: Pose = Pose()
    tcp: tuple[Finite, Finite, Finite, Finite, Finite, Finite] = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
    """TCP offset in the tool0 (flange) frame: x, y, z (m) and a rotation vector (rad)."""
    description: CustomDescription | None = None
    motion: MotionOptions = MotionOptions()
    mock: MockOptions | None = None
    servo: ServoOptions | None = None
    ur: UrOptions | None = None

    @property
    def prefix(self) -> str:
        """Joint and link name prefix."""
        return f"{self.name}_"

    @property
    def is_ur(self) -> bool:
        """True for UR models (not a custom description)."""
        return self.model != "custom"

    @field_validator("calibration")
    @classmethod
    def _calibration_exists(cls, value: str | None, info: ValidationInfo) -> str | None:
        return None if value is None else resolve_file(value, info)

    @field_validator("tcp")
    @classmethod
    def _tcp(cls, value: tuple[float, ...]) -> tuple[float, ...]:
        return check_tcp(value)

    @field_validator("address")
    @classmethod
    def _address(cls, value: str | None) -> str | None:
        return None if value is None else check_host(value, "address")

    @property
    def listens(self) -> bool:
        """True when the daemon listens on this robot's callback ports (a ``ur`` robot that commands)."""
        return self.backend == "ur" and not (self.ur is not None and self.ur.read_only)

    @field_validator("model")
    @classmethod
    def _known_model(cls, value: str) -> str:
        known = ur_models()
        if value != "custom" and value not in known:
            raise ValueError(f"unknown model {value!r}; known: {', '.join(known)}, or 'custom'")
        return value

    @model_validator(mode="after")
    def _consistent(self) -> Robot:
        if self.model == "custom":
            if self.description is None:
                raise ValueError("model 'custom' needs a 'description' (xacro file and macro)")
            if self.calibration is not None:
                raise ValueError("'calibration' applies to UR models only")
        elif self.description is not None:
            raise ValueError(f"'description' is for model 'custom'; {self.model} is described by urdaemon")
        if self.is_ur:
            unknown = sorted(set(self.joint_limits) - set(UR_JOINTS))
            if unknown:
                raise ValueError(
                    f"joint_limits: unknown joint(s) {', '.join(unknown)}; UR joints: {', '.join(UR_JOINTS)}"
                )
        if self.backend == "servo" and self.servo is None:
            raise ValueError("backend 'servo' needs a 'servo' section")
        if self.backend != "servo" and self.servo is not None:
            raise ValueError(f"'servo' section given but backend is {self.backend!r}")
        if self.backend != "mock" and self.mock is not None:
            raise ValueError(f"'mock' section given but backend is {self.backend!r}")
        if self.backend != "ur" and self.ur is not None:
            raise ValueError(f"'ur' section given but backend is {self.backend!r}")
        if self.backend == "ur":
            if self.address is None:
                raise ValueError("backend 'ur' needs the robot's 'address'")
            if not self.is_ur:
                raise ValueError("backend 'ur' needs a UR model")
        if self.mock is not None and isinstance(self.mock.initial_positions, dict) and self.is_ur:
            unknown = sorted(set(self.mock.initial_positions) - set(UR_JOINTS))
            if unknown:
                raise ValueError(f"mock.initial_positions: unknown joint(s) {', '.join(unknown)}")
        if (
            self.mock is not None
            and isinstance(self.mock.initial_positions, tuple)
            and self.is_ur
            and len(self.mock.initial_positions) != len(UR_JOINTS)
        ):
            raise ValueError(
                f"mock.initial_positions has {len(self.mock.initial_positions)} values for 6 joints"
            )
        return self
