"""The cell file schema: frozen pydantic models that reject unknown keys.

Nothing below the daemon sees YAML or dicts: ``load_cell`` turns a file into a ``Cell`` once.
Relative paths in the file are resolved against the file's folder (validation context ``base_dir``).
"""

from __future__ import annotations

import ipaddress
import math
import re
from pathlib import Path
from typing import Annotated, Any, Literal

from pydantic import (
    Field,
    ValidationInfo,
    field_validator,
    model_validator,
)

from urdaemon.cell.schema_types import Finite, Frozen
from urdaemon.cell.servo import ServoOptions
from urdaemon.model import CELL_LEVEL_KEYS, UR_JOINTS
from urdaemon.paths import resource_path
from urdaemon.urscript import (
    DEFAULT_REVERSE_PORT,
    DEFAULT_SERVOJ_GAIN,
    DEFAULT_SERVOJ_LOOKAHEAD_S,
    SERVOJ_GAIN_RANGE,
    SERVOJ_LOOKAHEAD_RANGE_S,
)

__all__ = [
    "ALL_ROBOTS",
    "DEFAULT_ENDPOINT",
    "DEFAULT_PORT_BASE",
    "DEFAULT_PORT_STRIDE",
    "AccessOptions",
    "CartesianOptions",
    "Cell",
    "CustomDescription",
    "Grant",
    "Identity",
    "JointLimitOverride",
    "MockOptions",
    "MotionOptions",
    "Ports",
    "Pose",
    "PublishOptions",
    "RecordOptions",
    "Robot",
    "TlsOptions",
    "UrOptions",
    "ZenohOptions",
    "ur_models",
]

NAME_PATTERN = r"^[a-z][a-z0-9_]{0,30}$"
"""Robot names: a key chunk and a joint/link prefix (``alice`` → ``alice_`` and ``<cell>/alice/``)."""
CELL_NAME_PATTERN = r"^[A-Za-z0-9][A-Za-z0-9_-]{0,62}$"
ENDPOINT_PATTERN = r"^(tcp|udp|tls|quic|ws|unixsock-stream|serial)/\S+$"
DEFAULT_PORT_BASE = DEFAULT_REVERSE_PORT
"""UR's reverse port; the first robot gets 50001..50004 like UR's own driver."""
DEFAULT_ENDPOINT = "tcp/127.0.0.1:7447"
"""Where the daemon listens for Zenoh sessions by default, and where clients look for it."""
DEFAULT_PORT_STRIDE = 10
"""Each further robot's default ports are 10 higher, so defaults never clash."""
_LOOKAHEAD = SERVOJ_LOOKAHEAD_RANGE_S
_GAIN = (int(SERVOJ_GAIN_RANGE[0]), int(SERVOJ_GAIN_RANGE[1]))
"""servoj's limits (urscript.py), the gain as the whole numbers the cell file takes."""
HOST_NAME_PATTERN = r"^(?=.{1,253}$)[A-Za-z0-9]([A-Za-z0-9-]{0,62})(\.[A-Za-z0-9]([A-Za-z0-9-]{0,62}))*\.?$"


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


def endpoint_port(endpoint: str) -> int | None:
    """The TCP port of a Zenoh ``tcp/HOST:PORT`` endpoint (None for other protocols)."""
    match = re.match(r"^tcp/.*:(\d{1,5})(#.*)?$", endpoint)
    return int(match.group(1)) if match else None


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


def _resolve_file(value: str, info: ValidationInfo) -> str:
    base = (info.context or {}).get("base_dir")
    path = Path(value).expanduser()
    if not path.is_absolute() and base is not None:
        path = Path(base) / path
    if not path.is_file():
        raise ValueError(f"file not found: {path}")
    return str(path.resolve())


IDENTITY_PATTERN = r"^[A-Za-z][A-Za-z0-9_-]{0,31}$"
"""Names of access-control identities in the cell file (``operator``, ``line-pc``)."""
ALL_ROBOTS = "*"
"""In a grant's ``read`` or ``command`` list: every robot of the cell, and the cell's own keys."""
SECURE_PROTOCOLS = ("tls/", "quic/")
"""Endpoints whose links are encrypted and carry the peer's certificate."""


_PEM_CERTIFICATE = "-----BEGIN CERTIFICATE-----"
_PEM_KEY = "-----BEGIN (RSA |EC )?PRIVATE KEY-----"
"""What Zenoh reads: PEM certificates, and unencrypted PKCS#8, RSA or EC private keys."""


class TlsOptions(Frozen):
    """TLS for the daemon's Zenoh links (``tls/`` and ``quic/`` endpoints); docs/security.md."""

    root_ca: str
    """The certificate authority (PEM) that signed the daemon's and the clients' certificates."""
    certificate: str
    """The daemon's certificate (PEM): its name or IP address in subjectAltName, as clients dial it."""
    private_key: str
    """The daemon's private key (PEM); keep it readable by the daemon's user only."""
    mutual: bool = True
    """Mutual TLS: a client must show a certificate the root CA signed, or its link is refused; the
    certificate's common name is the client's identity for ``access``. ``false``: encryption only,
    anyone who reaches the port may connect."""

    @field_validator("root_ca", "certificate", "private_key")
    @classmethod
    def _exists(cls, value: str, info: ValidationInfo) -> str:
        try:
            path = _resolve_file(value, info)
        except ValueError as err:
            raise ValueError(f"{err} (docs/security.md shows how to make the certificates)") from None
        try:
            text = Path(path).read_text(encoding="ascii", errors="replace")
        except OSError as err:
            raise ValueError(f"cannot read {path}: {err.strerror or err}") from None
        want = _PEM_KEY if info.field_name == "private_key" else _PEM_CERTIFICATE
        if not re.search(want, text):
            raise ValueError(f"{path} holds no {want.replace('(RSA |EC )?', '')} in PEM form")
        return path


class Identity(Frozen):
    """Who a connection is, for ``access``: each list given must match (common name AND interface)."""

    cert_common_names: tuple[Annotated[str, Field(min_length=1, max_length=64)], ...] | None = None
    """The common name (CN) of the client certificate the link was opened with (needs mutual TLS)."""
    interfaces: tuple[Annotated[str, Field(pattern=r"^[A-Za-z0-9_.:@-]{1,15}$")], ...] | None = None
    """The daemon's network interface the link arrived on (``lo``, ``eth1``)."""

    @model_validator(mode="after")
    def _says_who(self) -> Identity:
        for field in ("cert_common_names", "interfaces"):
            if getattr(self, field) == ():
                raise ValueError(f"{field}: an empty list matches nobody; leave the field out instead")
        if self.cert_common_names is None and self.interfaces is None:
            raise ValueError(
                "an identity needs cert_common_names or interfaces (one without either would match "
                "every connection)"
            )
        return self


RobotRef = Annotated[str, Field(pattern=rf"^(\{ALL_ROBOTS}|[a-z][a-z0-9_]{{0,30}})$")]


class Grant(Frozen):
    """What some identities may do: read robots' state, command robots."""

    identities: tuple[Annotated[str, Field(pattern=IDENTITY_PATTERN)], ...]
    read: tuple[RobotRef, ...] = ()
    """Robots whose state these identities may subscribe to and ask for (joint states, status, io,
    events, goal feedback and results, cycle stats, the cell's description); ``"*"``: every robot,
    the cell's tf and the cell goals' messages."""
    command: tuple[RobotRef, ...] = ()
    """Robots these identities may command (goals, cancel, services, command streams, the command
    lease and its liveliness token), and read as above; ``"*"``: every robot and cell goals."""

    @model_validator(mode="after")
    def _grants_something(self) -> Grant:
        if not self.identities:
            raise ValueError("identities: list at least one identity the grant is for")
        if not self.read and not self.command:
            raise ValueError("a grant needs 'read' or 'command' (robot names, or '*' for all)")
        return self


class AccessOptions(Frozen):
    """Zenoh access control on the daemon's links: only what a grant allows passes (docs/security.md).

    ``stop`` (every robot's and the cell's) and finding the cell's robots are allowed to every
    connection that reaches the daemon, whatever the grants say: a stop is never refused.
    """

    default: Literal["deny"] = "deny"
    """What no grant allows is dropped by the daemon's Zenoh session (the only choice: said here so
    the cell file reads as it works)."""
    identities: dict[Annotated[str, Field(pattern=IDENTITY_PATTERN)], Identity]
    grants: tuple[Grant, ...]

    @model_validator(mode="after")
    def _grants_name_identities(self) -> AccessOptions:
        if not self.identities:
            raise ValueError("identities: name at least one identity")
        for i, grant in enumerate(self.grants):
            unknown = [name for name in grant.identities if name not in self.identities]
            if unknown:
                raise ValueError(
                    f"grants[{i}].identities: unknown identity {', '.join(map(repr, unknown))}; "
                    f"identities: {', '.join(sorted(self.identities))}"
                )
        return self

    def unknown_robots(self, robots: tuple[str, ...] | list[str]) -> str | None:
        """The first grant entry naming a robot not in ``robots``, as an error naming its field."""
        for i, grant in enumerate(self.grants):
            for kind, names in (("read", grant.read), ("command", grant.command)):
                for j, name in enumerate(names):
                    if name != ALL_ROBOTS and name not in robots:
                        return (
                            f"zenoh.access.grants[{i}].{kind}[{j}]: {name!r} is not a robot of this cell "
                            f"({', '.join(robots)}; or '*' for all)"
                        )
        return None


class ZenohOptions(Frozen):
    """How the daemon joins the Zenoh network: a peer that clients dial (the default), or a client of
    a Zenoh router that several cells and their clients share (docs/scale-out.md)."""

    mode: Literal["peer", "client", "router"] = "peer"
    listen: tuple[Annotated[str, Field(pattern=ENDPOINT_PATTERN)], ...] = (DEFAULT_ENDPOINT,)
    """Where the daemon accepts sessions; none in ``client`` mode (its clients come through the router)."""
    connect: tuple[Annotated[str, Field(pattern=ENDPOINT_PATTERN)], ...] = ()
    multicast_scouting: bool = False
    low_latency: bool = False
    """Zenoh's low-latency unicast transport (no batching, no QoS priorities): about half the CPU per
    published sample when the subscriber enables it too (``Client.connect(..., low_latency=True)``);
    peers without it still connect. See docs/performance.md."""
    tls: TlsOptions | None = None
    """Certificates for ``tls/`` endpoints; with it every listen endpoint must be ``tls/`` (or
    ``quic/``), so no client gets in around it."""
    access: AccessOptions | None = None
    """Zenoh access control: which identities may read and command which robots."""

    @model_validator(mode="before")
    @classmethod
    def _client_listens_nowhere(cls, data: Any) -> Any:
        """In ``client`` mode ``listen`` defaults to none: the router is where sessions arrive (a
        client listening on the default 7447 would take the port of a router on the same machine)."""
        if isinstance(data, dict) and data.get("mode") == "client" and "listen" not in data:
            return {**data, "listen": ()}
        return data

    @model_validator(mode="after")
    def _client_needs_connect(self) -> ZenohOptions:
        if self.mode == "client":
            self._client_consistent()
        self._tls_consistent()
        return self

    def _client_consistent(self) -> None:
        """A client daemon dials its router, accepts no session, and sees every client of the router
        arrive on its one link to it, so it cannot tell them apart for ``access``."""
        if not self.connect:
            raise ValueError("mode 'client' needs at least one connect endpoint (the router, tcp/HOST:7447)")
        if self.listen:
            raise ValueError(
                f"listen: {list(self.listen)}: a daemon in mode 'client' accepts no sessions (its clients "
                "reach it through the router in 'connect'); leave 'listen' out, or use mode 'peer'"
            )
        if self.access is not None:
            raise ValueError(
                "access: in mode 'client' every client's messages reach the daemon over its one link to "
                "the router, so grants cannot tell clients apart; put access control on the router "
                "(docs/scale-out.md), or use mode 'peer' with clients dialling the daemon"
            )

    def _tls_consistent(self) -> None:
        # Messages start with their own key path, as in Cell: a model validator has no location.
        for field in ("listen", "connect"):
            for i, endpoint in enumerate(getattr(self, field)):
                secure = endpoint.startswith(SECURE_PROTOCOLS)
                if secure and self.tls is None:
                    raise ValueError(
                        f"{field}[{i}]: {endpoint} needs the 'tls' section "
                        "(root_ca, certificate, private_key)"
                    )
                if field == "listen" and self.tls is not None and not secure:
                    raise ValueError(
                        f"listen[{i}]: {endpoint} is not encrypted; with 'tls' every listen endpoint must "
                        "be tls/ or quic/ (this one would let clients in without a certificate)"
                    )
        if self.tls is not None and not any(
            e.startswith(SECURE_PROTOCOLS) for e in self.listen + self.connect
        ):
            raise ValueError("tls: no listen or connect endpoint uses it (tls/HOST:PORT)")
        if self.access is None:
            return
        for name, identity in self.access.identities.items():
            if identity.cert_common_names is not None and (self.tls is None or not self.tls.mutual):
                raise ValueError(
                    f"access.identities.{name}.cert_common_names: clients show a certificate only with "
                    "mutual TLS ('tls' with mutual: true)"
                )


class PublishOptions(Frozen):
    """Rates of what the daemon publishes."""

    joint_states_decimation: Annotated[int, Field(ge=1, le=1000)] = 1
    """Publish joint states and TCP pose every Nth robot cycle."""
    tf_rate_hz: Annotated[float, Field(gt=0, le=500)] = 50.0
    status_rate_hz: Annotated[float, Field(gt=0, le=100)] = 2.0
    """Status is published on every change and at least at this rate."""
    io_rate_hz: Annotated[float, Field(gt=0, le=500)] = 10.0
    """IO is published on every change and at least at this rate."""


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
        base = (info.context or {}).get("base_dir")
        path = Path(value).expanduser()
        if not path.is_absolute() and base is not None:
            path = Path(base) / path
        if path.exists() and not path.is_dir():
            raise ValueError(f"{path} is not a directory")
        return str(path.resolve())


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
    feedback_rate_hz: Annotated[float, Field(gt=0, le=500)] = 10.0
    cartesian: CartesianOptions = CartesianOptions()
    """Caps and defaults of Cartesian motion (linear goals, twists)."""


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
    receive_timeout: Annotated[float, Field(ge=0.004, le=1.0)] = 0.1
    """The robot halts the program when no command arrives for this long (s)."""
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

    @model_validator(mode="after")
    def _read_only_does_not_start(self) -> UrOptions:
        if self.read_only and self.startup:
            raise ValueError("read_only: a read-only robot cannot also be started up (startup: true)")
        return self


class MockOptions(Frozen):
    """Options of the ``mock`` backend."""

    initial_positions: tuple[Finite, ...] | dict[str, Finite] | None = None
    """Start pose: a list in joint order, or joint name (without prefix) → value."""
    speed_scaling: Annotated[float, Field(ge=0, le=1, allow_inf_nan=False)] = 1.0
    """The runtime speed scaling the mock reports (multiplied with the speed slider)."""
    rate_hz: Annotated[float, Field(gt=0, le=1000)] | None = None
    """Cycle rate; default: the model's controller rate (500 Hz e-Series, 125 Hz CB3)."""


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
        return _resolve_file(value, info)


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
        return None if value is None else _resolve_file(value, info)

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
        return {**data, "robots": robots}

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
