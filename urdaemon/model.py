"""Shared value types: robot/safety modes, lifecycle, joint limits, the per-robot state and command,
and the requests of the robot services (publish/services.py declares which service takes which).

``RobotState`` and ``JointCommand`` are deliberately mutable and reused every cycle: the backend
fills one ``RobotState`` in place at the robot's rate and the controller writes one ``JointCommand``
in place, so the 500 Hz path allocates as little as possible. Everything else is frozen.
"""

from __future__ import annotations

import enum
import hashlib
import math
from dataclasses import dataclass, field

__all__ = [
    "ANALOG_OUTPUT_SPANS",
    "CELL_LEVEL_KEYS",
    "CONFIGURABLE_IO_SHIFT",
    "FINGERPRINT_CHARS",
    "FORCE_MODE_DAMPING",
    "FORCE_MODE_GAIN_SCALING",
    "FORCE_MODE_TYPE",
    "HOLDER_MAX_CHARS",
    "IO_SIZES",
    "STANDARD_IO_SHIFT",
    "TOKEN_BYTES",
    "TOOL_IO_SHIFT",
    "TOOL_VOLTAGES",
    "UR_JOINTS",
    "UR_JOINT_COUNT",
    "CommandMode",
    "CycleStatsRequest",
    "DashboardRequest",
    "ForceModeRequest",
    "JointCommand",
    "JointLimits",
    "Lifecycle",
    "RobotMode",
    "RobotState",
    "SafetyMode",
    "SetIoRequest",
    "SetPayloadRequest",
    "SetTcpRequest",
    "SpeedSliderRequest",
    "ToolVoltageRequest",
    "analog_output_level",
    "analog_output_value",
    "fingerprint",
]

UR_JOINTS: tuple[str, ...] = (
    "shoulder_pan_joint",
    "shoulder_lift_joint",
    "elbow_joint",
    "wrist_1_joint",
    "wrist_2_joint",
    "wrist_3_joint",
)
"""The six joint names of every UR arm, without the robot prefix."""
UR_JOINT_COUNT = len(UR_JOINTS)
"""Joints of every UR arm: the length of every joint vector on UR's wire formats and in the fake."""
CELL_LEVEL_KEYS = frozenset({"tf", "robot_description", "service", "goal", "daemon", "audit"})
"""The chunks after ``<cell>/`` that name a key of the cell, not a robot (``<cell>/tf``,
``<cell>/service/stop``, ``<cell>/goal/trajectory``, ``<cell>/daemon``, ``<cell>/audit``):
no robot may be named so."""


IO_SIZES: dict[str, int] = {"digital": 8, "configurable": 8, "tool": 2, "analog": 2}
"""Outputs (and inputs) of each kind a UR controller has: the state's IO lists have these lengths, and
a ``set_io`` request names one of these kinds (analog outputs take 0..1, the others true or false)."""
STANDARD_IO_SHIFT = 0
"""Where each digital kind starts in a controller's digital IO bit word (RTDE's
``actual_digital_input_bits`` / ``actual_digital_output_bits``, the fake's IO words): the standard
pins are bits 0-7, the configurable ones 8-15, the tool's 16-17 (``IO_SIZES`` pins each)."""
CONFIGURABLE_IO_SHIFT = STANDARD_IO_SHIFT + IO_SIZES["digital"]
TOOL_IO_SHIFT = CONFIGURABLE_IO_SHIFT + IO_SIZES["configurable"]
TOOL_VOLTAGES = (0, 12, 24)
"""The tool voltages a ``set_tool_voltage`` request may ask for (V)."""


class RobotMode(enum.IntEnum):
    """UR robot mode (primary interface int8, RTDE INT32); docs/protocols.md §6.1."""

    NO_CONTROLLER = -1
    DISCONNECTED = 0
    CONFIRM_SAFETY = 1
    BOOTING = 2
    POWER_OFF = 3
    POWER_ON = 4
    IDLE = 5
    BACKDRIVE = 6
    RUNNING = 7
    UPDATING_FIRMWARE = 8


class SafetyMode(enum.IntEnum):
    """UR safety mode (primary uint8, RTDE INT32); docs/protocols.md §6.1."""

    NORMAL = 1
    REDUCED = 2
    PROTECTIVE_STOP = 3
    RECOVERY = 4
    SAFEGUARD_STOP = 5
    SYSTEM_EMERGENCY_STOP = 6
    ROBOT_EMERGENCY_STOP = 7
    VIOLATION = 8
    FAULT = 9
    VALIDATE_JOINT_ID = 10
    UNDEFINED_SAFETY_MODE = 11
    AUTOMATIC_MODE_SAFEGUARD_STOP = 12
    SYSTEM_THREE_POSITION_ENABLING_STOP = 13
    TP_THREE_POSITION_ENABLING_STOP = 14
    IMMI_EMERGENCY_STOP = 15
    IMMI_SAFEGUARD_STOP = 16
    PROFISAFE_WAITING_FOR_PARAMETERS = 17
    PROFISAFE_AUTOMATIC_MODE_SAFEGUARD_STOP = 18
    PROFISAFE_SAFEGUARD_STOP = 19
    PROFISAFE_EMERGENCY_STOP = 20
    SAFETY_API_SAFEGUARD_STOP = 22


class Lifecycle(enum.StrEnum):
    """The daemon's own per-robot lifecycle state, published in the status."""

    DISCONNECTED = "disconnected"
    CONNECTING = "connecting"
    IDLE = "idle"
    RUNNING = "running"
    PAUSED = "paused"
    PROTECTIVE_STOP = "protective_stop"
    EMERGENCY_STOP = "emergency_stop"
    RECOVERING = "recovering"


class CommandMode(enum.IntEnum):
    """What the backend should do with a ``JointCommand`` this cycle."""

    IDLE = 0
    """Hold still; send nothing that moves the robot (a keepalive on real hardware)."""
    POSITION = 1
    """Go to ``positions`` this cycle (servoj on a UR); ``velocities`` is the feed-forward velocity."""
    VELOCITY = 2
    """Move at ``velocities`` (speedj on a UR); ``positions`` is ignored."""


@dataclass(frozen=True, slots=True)
class JointLimits:
    """Per-joint limits in joint order; positions in rad (or m), rates per second."""

    names: tuple[str, ...]
    min_position: tuple[float, ...]
    max_position: tuple[float, ...]
    max_velocity: tuple[float, ...]
    max_acceleration: tuple[float, ...]
    max_jerk: tuple[float, ...]
    max_effort: tuple[float, ...] = ()

    def __post_init__(self) -> None:
        n = len(self.names)
        for label in ("min_position", "max_position", "max_velocity", "max_acceleration", "max_jerk"):
            values = getattr(self, label)
            if len(values) != n:
                raise ValueError(f"JointLimits.{label} has {len(values)} values for {n} joints")
            if not all(math.isfinite(v) or (label.endswith("position") and math.isinf(v)) for v in values):
                raise ValueError(f"JointLimits.{label} must be finite: {values}")
        for label in ("max_velocity", "max_acceleration", "max_jerk"):
            if any(v <= 0.0 for v in getattr(self, label)):
                raise ValueError(f"JointLimits.{label} must be positive: {getattr(self, label)}")
        for i, (lo, hi) in enumerate(zip(self.min_position, self.max_position, strict=True)):
            if lo >= hi:
                raise ValueError(f"JointLimits for {self.names[i]}: min_position {lo} >= max_position {hi}")

    @property
    def dof(self) -> int:
        """Number of joints."""
        return len(self.names)


@dataclass(slots=True)
class RobotState:
    """The latest measured state of one robot, filled in place by its backend every cycle."""

    joint_names: tuple[str, ...]
    positions: list[float]
    velocities: list[float]
    efforts: list[float]
    controller_time: float = 0.0
    """Controller clock in seconds (RTDE ``timestamp``; the mock's own cycle clock)."""
    host_time_ns: int = 0
    """``time.time_ns()`` when this state arrived on the host."""
    monotonic_ns: int = 0
    """``time.monotonic_ns()`` when this state arrived on the host."""
    cycle: int = 0
    """Cycles received since the backend (re)connected."""
    lifecycle: Lifecycle = Lifecycle.DISCONNECTED
    lifecycle_reason: str = ""
    robot_mode: RobotMode = RobotMode.DISCONNECTED
    safety_mode: SafetyMode = SafetyMode.NORMAL
    speed_slider: float = 1.0
    """The speed slider fraction (0..1)."""
    speed_scaling: float = 1.0
    """The effective scaling of trajectory time (slider × runtime scaling, 0..1)."""
    program_running: bool = False
    digital_out: list[bool] = field(default_factory=lambda: [False] * IO_SIZES["digital"])
    configurable_out: list[bool] = field(default_factory=lambda: [False] * IO_SIZES["configurable"])
    tool_out: list[bool] = field(default_factory=lambda: [False] * IO_SIZES["tool"])
    analog_out: list[float] = field(default_factory=lambda: [0.0] * IO_SIZES["analog"])
    digital_in: list[bool] = field(default_factory=lambda: [False] * IO_SIZES["digital"])
    configurable_in: list[bool] = field(default_factory=lambda: [False] * IO_SIZES["configurable"])
    tool_in: list[bool] = field(default_factory=lambda: [False] * IO_SIZES["tool"])
    analog_in: list[float] = field(default_factory=lambda: [0.0] * IO_SIZES["analog"])
    tool_voltage: int = 0
    payload_mass: float = 0.0
    payload_cog: tuple[float, float, float] = (0.0, 0.0, 0.0)

    @classmethod
    def zeros(cls, joint_names: tuple[str, ...]) -> RobotState:
        """A state at all-zero joint values for the given joints."""
        n = len(joint_names)
        return cls(joint_names=joint_names, positions=[0.0] * n, velocities=[0.0] * n, efforts=[0.0] * n)

    @property
    def ready_for_motion(self) -> bool:
        """True when the robot accepts motion commands (running, normal/reduced safety, program on)."""
        return (
            self.lifecycle is Lifecycle.RUNNING
            and self.program_running
            and self.safety_mode in (SafetyMode.NORMAL, SafetyMode.REDUCED)
        )

    def not_ready_reason(self) -> str:
        """Why ``ready_for_motion`` is false, the robot and safety modes, and what to do (empty when ready).

        The backend's ``lifecycle_reason`` says why and what to do when it knows; otherwise the advice
        follows from the modes. Runs only when a motion is refused or aborted, never per cycle.
        """
        if self.ready_for_motion:
            return ""
        if self.lifecycle is not Lifecycle.RUNNING:
            head = f"robot is {self.lifecycle.value}"
        elif self.safety_mode not in (SafetyMode.NORMAL, SafetyMode.REDUCED):
            head = f"robot safety mode is {self.safety_mode.name}"
        else:
            head = "control program is not running"
        why = self.lifecycle_reason or _advice(self)
        return f"{head} (robot mode {self.robot_mode.name}, safety mode {self.safety_mode.name}): {why}"


_EMERGENCY_STOPS = frozenset(
    {
        SafetyMode.ROBOT_EMERGENCY_STOP,
        SafetyMode.SYSTEM_EMERGENCY_STOP,
        SafetyMode.IMMI_EMERGENCY_STOP,
        SafetyMode.PROFISAFE_EMERGENCY_STOP,
    }
)
_SAFEGUARD_STOPS = frozenset(
    {
        SafetyMode.SAFEGUARD_STOP,
        SafetyMode.AUTOMATIC_MODE_SAFEGUARD_STOP,
        SafetyMode.IMMI_SAFEGUARD_STOP,
        SafetyMode.PROFISAFE_SAFEGUARD_STOP,
        SafetyMode.PROFISAFE_AUTOMATIC_MODE_SAFEGUARD_STOP,
        SafetyMode.SAFETY_API_SAFEGUARD_STOP,
        SafetyMode.SYSTEM_THREE_POSITION_ENABLING_STOP,
        SafetyMode.TP_THREE_POSITION_ENABLING_STOP,
    }
)


def _advice(state: RobotState) -> str:
    """What to do about a robot that is not ready, from its lifecycle and modes alone."""
    lifecycle, safety, mode = state.lifecycle, state.safety_mode, state.robot_mode
    if lifecycle in (Lifecycle.DISCONNECTED, Lifecycle.CONNECTING, Lifecycle.RECOVERING):
        return (
            "the daemon has no link to the robot; it keeps reconnecting (check the robot's network and power)"
        )
    if safety in _EMERGENCY_STOPS:
        return "release the emergency stop, then call the startup service"
    if safety is SafetyMode.PROTECTIVE_STOP:
        return (
            "unlock the protective stop (dashboard service 'unlock protective stop', or the pendant), "
            "then call the resend_program service"
        )
    if safety in _SAFEGUARD_STOPS:
        return (
            "reset the safeguard stop (close the guard or release the enabling device), then resend_program"
        )
    if safety not in (SafetyMode.NORMAL, SafetyMode.REDUCED):
        return f"clear the {safety.name} condition on the pendant, then call the startup service"
    if mode is RobotMode.POWER_OFF:
        return "the robot is powered off: call the startup service (or power it on on the pendant)"
    if mode is RobotMode.IDLE:
        return "the brakes are engaged: call the startup service (or release them on the pendant)"
    if lifecycle is Lifecycle.PAUSED:
        return "the program is paused on the controller: resume it (dashboard 'play' or the pendant)"
    if mode is not RobotMode.RUNNING:
        return f"the robot is in {mode.name} mode: call the startup service once it has finished"
    return "call the resend_program service (or startup) to start the control program"


@dataclass(slots=True)
class JointCommand:
    """The command the controller leaves for the backend each cycle (reused in place)."""

    mode: CommandMode
    positions: list[float]
    velocities: list[float]

    @classmethod
    def idle(cls, dof: int) -> JointCommand:
        """An IDLE command for ``dof`` joints."""
        return cls(mode=CommandMode.IDLE, positions=[0.0] * dof, velocities=[0.0] * dof)


# ---- the requests of the robot services ------------------------------------------------------------
# Each is what a service's JSON request decodes to (publish/service_requests.py checks shape and
# ranges with the reasons clients see) and what the client sends; the field names are the message's, but for
# ``ForceModeRequest.force_type`` (``type`` on the wire).

FORCE_MODE_TYPE = 2
"""Force mode's default type: the force frame is the task frame (URScript ``force_mode``)."""
FORCE_MODE_DAMPING = 0.025
"""Force mode's default damping (0..1), as URScript's ``force_mode_set_damping`` default."""
FORCE_MODE_GAIN_SCALING = 0.5
"""Force mode's default gain scaling (0..2), as URScript's ``force_mode_set_gain_scaling`` default."""


@dataclass(frozen=True, slots=True)
class SetIoRequest:
    """``set_io``: one output of a kind (``digital``, ``configurable``, ``tool``: bool; ``analog``: 0..1)."""

    kind: str
    pin: int
    value: float | bool


@dataclass(frozen=True, slots=True)
class SetPayloadRequest:
    """``set_payload``: mass (kg) and centre of gravity (m, tool flange frame)."""

    mass: float
    cog: tuple[float, float, float] = (0.0, 0.0, 0.0)


@dataclass(frozen=True, slots=True)
class SetTcpRequest:
    """``set_tcp``: the TCP offset in the tool0 (flange) frame, x, y, z (m) and a rotation vector (rad)."""

    pose: tuple[float, float, float, float, float, float]


@dataclass(frozen=True, slots=True)
class SpeedSliderRequest:
    """``set_speed_slider``: the slider's fraction (0..1)."""

    fraction: float


@dataclass(frozen=True, slots=True)
class DashboardRequest:
    """``dashboard``: one dashboard command line (``power on``)."""

    command: str


@dataclass(frozen=True, slots=True)
class ToolVoltageRequest:
    """``set_tool_voltage``: 0, 12 or 24 V."""

    volts: int


@dataclass(frozen=True, slots=True)
class ForceModeRequest:
    """``start_force_mode``: URScript ``force_mode``'s arguments, damping and gain scaling."""

    task_frame: tuple[float, ...]
    selection: tuple[int, ...]
    wrench: tuple[float, ...]
    limits: tuple[float, ...]
    force_type: int = FORCE_MODE_TYPE
    damping: float = FORCE_MODE_DAMPING
    gain_scaling: float = FORCE_MODE_GAIN_SCALING


@dataclass(frozen=True, slots=True)
class CycleStatsRequest:
    """``cycle_stats``: whether to start a new measuring window after the reply."""

    reset: bool = False


# ---- the command lease, as the daemon (runtime/lease.py) and the client (client/) both see it ----------

HOLDER_MAX_CHARS = 120
"""Longest holder text (it names the client for humans)."""
TOKEN_BYTES = 16
"""A lease token is this many random bytes, as 32 lowercase hex characters."""
FINGERPRINT_CHARS = 16
"""A lease's fingerprint is this many hex characters of sha256 of its session id."""


def fingerprint(session: str) -> str:
    """What the daemon shows of a lease's session id ``session`` (a secret only its holder knows):
    the first 16 hex characters of its SHA-256, enough to tell leases apart, useless to acquire."""
    return hashlib.sha256(session.encode("ascii")).hexdigest()[:FINGERPRINT_CHARS]


ANALOG_OUTPUT_SPANS = {"current": (0.004, 0.020), "voltage": (0.0, 10.0)}
"""A standard analog output's span in each domain: amperes (4-20 mA) and volts (0-10 V). The level
0..1 a program (``set_standard_analog_out``), an RTDE client and ``set_io`` set maps linearly onto it
(UR's script manual: level 0.5 is 5 V or 12 mA); the controller reports the output in the unit."""


def analog_output_value(level: float, voltage: bool) -> float:
    """A standard analog output's level 0..1 in its domain's unit (V when ``voltage``, else A)."""
    low, high = ANALOG_OUTPUT_SPANS["voltage" if voltage else "current"]
    return low + (high - low) * level


def analog_output_level(value: float, voltage: bool) -> float:
    """A standard analog output as the controller reports it (V when ``voltage``, else A) as its
    level 0..1."""
    low, high = ANALOG_OUTPUT_SPANS["voltage" if voltage else "current"]
    return (value - low) / (high - low)
