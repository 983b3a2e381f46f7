"""The robot services, declared once: ``SERVICES``, one ``ServiceSpec`` per service.

From each entry follow the service's key (``<cell>/<robot>/service/<name>``), how its request is
decoded and checked (``decode``: a request type of model.py, with the reasons clients see), what it
does (``handle``: a backend method or the runtime's), the reply, the client's call and wait, the
CLI's help and the rows of docs/keys.md's table (``markdown_rows``). Every backend answers every
service: one whose backend lacks what ``needs`` names refuses with that backend's reason
(backends/base.py), as the mock does for ``dashboard``.

Runnable as ``python -m urdaemon.publish.services`` to print docs/keys.md's rows.
"""

from __future__ import annotations

from collections.abc import Awaitable, Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Protocol

from urdaemon.cell.robot_options import TCP_MAX_OFFSET_M, check_tcp
from urdaemon.errors import MessageError
from urdaemon.model import (
    FORCE_MODE_DAMPING,
    FORCE_MODE_GAIN_SCALING,
    FORCE_MODE_TYPE,
    IO_SIZES,
    TOOL_VOLTAGES,
    CycleStatsRequest,
    DashboardRequest,
    ForceModeRequest,
    SetIoRequest,
    SetPayloadRequest,
    SetTcpRequest,
    SpeedSliderRequest,
    ToolVoltageRequest,
)
from urdaemon.protocols import dashboard as dash
from urdaemon.protocols.dashboard_refusal import REFUSAL_PREFIXES
from urdaemon.publish import service_requests
from urdaemon.publish.envelope import client_text
from urdaemon.publish.service_requests import MAX_COG_M, MAX_FORCE_MODE, MAX_PAYLOAD_KG

if TYPE_CHECKING:
    from urdaemon.backends.base import Backend

__all__ = [
    "CLIENT_TIMEOUT_S",
    "READ_ONLY_DASHBOARD",
    "SERVICES",
    "STOP",
    "ServiceHost",
    "ServiceSpec",
    "markdown_rows",
    "names",
    "read_only_words",
    "spec",
]

CLIENT_TIMEOUT_S = 5.0
"""How long the client waits for a service's reply unless its entry says otherwise."""

Reply = dict[str, Any] | None
"""What a service adds to its ``{"ok": true}`` reply (None: nothing)."""


class ServiceHost(Protocol):
    """What a service's handler may use: the robot's backend and the runtime's own steps."""

    @property
    def backend(self) -> Backend:
        """The robot's backend."""
        ...

    def publish_io(self) -> None:
        """Publish the IO message now (an output or the payload changed)."""

    async def hand_back_control(self) -> None:
        """Refuse what is being planned, then hand control back to the pendant program."""

    async def end_tool_contact(self) -> None:
        """End tool-contact detection; motion starts anew from where the robot rests."""

    async def set_tcp(self, pose: tuple[float, ...]) -> None:
        """Make ``pose`` the robot's TCP offset: the controller's (refused unless idle), the
        backend's, and tcp_pose's."""

    def check_not_planning_from_rest(self) -> None:
        """Refuse (``GoalRejected``) what would move the robot while a goal is planned from where
        it rests (a linear goal)."""


@dataclass(frozen=True, slots=True)
class ServiceSpec:
    """One service: its name, request, handler, and what users read about it."""

    name: str
    summary: str
    """One line: the CLI's help."""
    request: type | None
    """The request type (model.py); None: the service takes no arguments."""
    decode: Callable[[bytes | None], Any]
    """The request's payload → the request (``MessageError`` naming what is wrong)."""
    handle: Callable[[ServiceHost, Any], Awaitable[Reply]] | None
    """Act on a decoded request; None only for ``stop``, which the runtime answers at once."""
    needs: str | None
    """The Backend method the service calls (a backend without it refuses with its reason)."""
    request_doc: str
    """The request column of docs/keys.md."""
    reply_doc: str
    """The reply column of docs/keys.md."""
    timeout: float = CLIENT_TIMEOUT_S
    """How long the client waits for the reply by default (s)."""
    commanding: bool = True
    """Whether only the command lease's holder may call it (its token as the query's attachment);
    ``stop`` never needs the lease, whatever this says."""
    read_only_refusal: Callable[[Any], str | None] | None = None
    """For a commanding service a read-only robot answers in part: why a read-only robot refuses
    this decoded request (None: it only reads, so it is served). Without it a read-only robot refuses
    a commanding service whole (publish/endpoints.py)."""


def _without_arguments(name: str) -> Callable[[bytes | None], None]:
    """The decoder of a service without arguments: garbage is refused, so it never acts."""

    def decode(payload: bytes | None) -> None:
        service_requests.decode_empty(payload, name)

    return decode


def _ignored(payload: bytes | None) -> None:
    """``stop``'s decoder: a stop is never refused for its payload."""


async def _set_io(host: ServiceHost, request: SetIoRequest) -> Reply:
    await host.backend.set_io(request.kind, request.pin, request.value)
    host.publish_io()
    return None


async def _set_payload(host: ServiceHost, request: SetPayloadRequest) -> Reply:
    await host.backend.set_payload(request.mass, request.cog)
    host.publish_io()
    return None


async def _set_speed_slider(host: ServiceHost, request: SpeedSliderRequest) -> Reply:
    await host.backend.set_speed_slider(request.fraction)
    return None


async def _dashboard(host: ServiceHost, request: DashboardRequest) -> Reply:
    ok, text = await host.backend.dashboard(request.command)
    return {"ok": ok, "reply": text}


READ_ONLY_DASHBOARD: tuple[type, ...] = (
    dash.GetRobotMode,
    dash.GetSafetyMode,
    dash.GetSafetyStatus,
    dash.GetProgramState,
    dash.IsRunning,
    dash.GetLoadedProgram,
    dash.IsProgramSaved,
    dash.IsInRemoteControl,
    dash.GetPolyscopeVersion,
    dash.GetVersion,
    dash.GetRobotModel,
    dash.GetSerialNumber,
    dash.GetOperationalMode,
    dash.GetUserRole,
)
"""The dashboard lines a read-only robot answers: the server's queries (docs/protocols.md §3.2), which
only ask. Every other line (power, brakes, load, play, pause, stop, popups, the log, the operational
mode, user role, quit, shutdown) changes the robot or its controller, and so does a line the server
would not understand."""


def read_only_words() -> list[str]:
    """The dashboard lines a read-only robot answers, as the server reads them."""
    return [kind().line for kind in READ_ONLY_DASHBOARD]


def _dashboard_read_only_refusal(request: DashboardRequest) -> str | None:
    """Why a read-only robot refuses this dashboard line (None: the line only asks)."""
    if isinstance(dash.parse_command(request.command), READ_ONLY_DASHBOARD):
        return None
    return (
        f"read-only robot (ur.read_only: true): dashboard line {client_text(request.command)!r} is "
        f"refused, a read-only robot answers only the lines that ask: {', '.join(read_only_words())}"
    )


async def _set_tool_voltage(host: ServiceHost, request: ToolVoltageRequest) -> Reply:
    await host.backend.set_tool_voltage(request.volts)
    return None


async def _start_force_mode(host: ServiceHost, request: ForceModeRequest) -> Reply:
    from urdaemon.protocols.script_command import StartForceMode

    host.check_not_planning_from_rest()  # force mode moves the robot off where that plan starts
    await host.backend.force_mode(
        StartForceMode(
            task_frame=request.task_frame,
            selection=request.selection,
            wrench=request.wrench,
            force_type=request.force_type,
            limits=request.limits,
            damping=request.damping,
            gain_scaling=request.gain_scaling,
        )
    )
    return None


async def _cycle_stats(host: ServiceHost, request: CycleStatsRequest) -> Reply:
    backend = host.backend
    stats = backend.statistics()
    body = {
        "cycles": stats.cycles,
        "missed_cycles": stats.missed_cycles,
        "late_cycles": stats.late_cycles,
        "turnaround": backend.turnaround.summary(),
    }
    if request.reset:
        backend.turnaround.reset()
    return body


async def _doctor(host: ServiceHost, request: None) -> Reply:
    from urdaemon.doctor.report import doctor_report

    return await doctor_report(host.backend)


def _acting(act: Callable[[ServiceHost], Awaitable[None]]) -> Callable[[ServiceHost, None], Awaitable[Reply]]:
    """The handler of a service without arguments: it acts, the reply adds nothing."""

    async def handle(host: ServiceHost, request: None) -> Reply:
        await act(host)
        return None

    return handle


def _payloadless(
    name: str, summary: str, act: Callable[[ServiceHost], Awaitable[None]], **rest: Any
) -> ServiceSpec:
    return ServiceSpec(
        name, summary, None, _without_arguments(name), _acting(act), request_doc="none, or `{}`", **rest
    )


async def _set_tcp(host: ServiceHost, request: SetTcpRequest) -> Reply:
    await host.set_tcp(request.pose)
    return None


def _decode_set_tcp(payload: bytes | None) -> SetTcpRequest:
    """The set_tcp request, its offset within the cell file's ranges (cell/robot_options.py ``check_tcp``)."""
    pose = service_requests.decode_set_tcp(payload)
    try:
        check_tcp(pose)
    except ValueError as err:
        raise MessageError(f"set_tcp.pose: {err}") from err
    return SetTcpRequest(pose)


def _force_mode(payload: bytes | None) -> ForceModeRequest:
    return ForceModeRequest(**service_requests.decode_force_mode(payload))


_AS_ABOVE = "as above"

SERVICES: tuple[ServiceSpec, ...] = (
    ServiceSpec(
        "set_io",
        "set one output (digital, configurable, tool, analog)",
        SetIoRequest,
        lambda payload: SetIoRequest(*service_requests.decode_set_io(payload)),
        _set_io,
        needs="set_io",
        request_doc=(
            f"`kind` ({', '.join(f'`{kind}`' for kind in IO_SIZES)}), `pin`, "
            "`value` (bool; for analog the level 0..1 of the output's 0-10 V: the daemon selects the "
            "voltage domain)"
        ),
        reply_doc='`{"ok": true}` or `{"ok": false, "reason": …}`',
    ),
    ServiceSpec(
        "set_payload",
        "set the payload's mass and centre of gravity",
        SetPayloadRequest,
        lambda payload: SetPayloadRequest(*service_requests.decode_set_payload(payload)),
        _set_payload,
        needs="set_payload",
        request_doc=f"`mass` (kg, 0..{MAX_PAYLOAD_KG:g}), `cog` [x, y, z] (m, each within ±{MAX_COG_M:g})",
        reply_doc=_AS_ABOVE,
    ),
    ServiceSpec(
        "set_speed_slider",
        "set the speed slider (0..1)",
        SpeedSliderRequest,
        lambda payload: SpeedSliderRequest(service_requests.decode_speed_slider(payload)),
        _set_speed_slider,
        needs="set_speed_slider",
        request_doc="`fraction` (0..1)",
        reply_doc=_AS_ABOVE,
    ),
    ServiceSpec(
        "dashboard",
        "send one dashboard command line and return the robot's reply",
        DashboardRequest,
        lambda payload: DashboardRequest(service_requests.decode_dashboard(payload)),
        _dashboard,
        needs="dashboard",
        request_doc=(
            "`command` (one dashboard line, e.g. `power on`, `robotmode`, `unlock protective stop`)"
        ),
        reply_doc=(
            '`{"ok": bool, "reply": the robot\'s answer}` (UR only); `ok` is false when the controller '
            "refused the line (its answer starts "
            + ", ".join(f"`{prefix}`" for prefix in REFUSAL_PREFIXES[:-1])
            + f" or `{REFUSAL_PREFIXES[-1]}`). A read-only robot answers only the lines that ask ("
            + ", ".join(f"`{word}`" for word in read_only_words())
            + ") and refuses every other, naming the line"
        ),
        timeout=30.0,
        read_only_refusal=_dashboard_read_only_refusal,
    ),
    _payloadless(
        "startup",
        "power on, release the brakes, start the control program",
        lambda host: host.backend.startup(),
        needs="startup",
        reply_doc="power on, release the brakes, start the control program (UR; a no-op on the mock)",
        timeout=60.0,
    ),
    _payloadless(
        "resend_program",
        "send the control program again (headless) or play it (URCap)",
        lambda host: host.backend.resend_program(),
        needs="resend_program",
        reply_doc=(
            "send the control program again (headless) or `play` it (URCap), e.g. after a protective "
            "stop was unlocked"
        ),
    ),
    _payloadless(
        "hand_back_control",
        "end the control program so the pendant program continues",
        lambda host: host.hand_back_control(),
        needs="hand_back_control",
        reply_doc=(
            "end the control program's loop; in URCap mode the pendant program continues; the daemon "
            "does not send the program again until `resend_program` or `startup`"
        ),
    ),
    ServiceSpec(
        "set_tcp",
        "set the TCP offset (tool0 -> TCP) used by tcp_pose and every Cartesian command",
        SetTcpRequest,
        _decode_set_tcp,
        _set_tcp,
        needs="set_tcp",
        request_doc=(
            f"`pose` [x, y, z, rx, ry, rz]: the TCP in the tool0 (flange) frame (m, each within "
            f"±{TCP_MAX_OFFSET_M:g}; a rotation vector of at most pi rad)"
        ),
        reply_doc=(
            "refused unless the robot is idle (`set_tcp: the robot is moving`); applies to `tcp_pose` "
            "(child `<robot>_tcp`, or `<robot>_tool0` for a zero offset), every later pose, linear goal "
            "and twist, and on `ur` the controller's TCP (sent again whenever the control program "
            "reconnects); starts as the cell file's `tcp`"
        ),
    ),
    _payloadless(
        "zero_ft_sensor",
        "zero the force/torque sensor",
        lambda host: host.backend.zero_ft_sensor(),
        needs="zero_ft_sensor",
        reply_doc="zero the force/torque sensor",
    ),
    ServiceSpec(
        "set_tool_voltage",
        "set the tool voltage (0, 12 or 24 V)",
        ToolVoltageRequest,
        lambda payload: ToolVoltageRequest(service_requests.decode_tool_voltage(payload)),
        _set_tool_voltage,
        needs="set_tool_voltage",
        request_doc=f"`volts` ({', '.join(map(str, TOOL_VOLTAGES))})",
        reply_doc="",
    ),
    ServiceSpec(
        "start_force_mode",
        "start force mode (URScript force_mode semantics)",
        ForceModeRequest,
        _force_mode,
        _start_force_mode,
        needs="force_mode",
        request_doc=(
            f"`task_frame` [6] (m, rad; each within ±{MAX_FORCE_MODE['task_frame']:g}), "
            f"`selection` [6 × 0/1], `wrench` [6] (N, Nm; each within ±{MAX_FORCE_MODE['wrench']:g}), "
            "`limits` [6] (each "
            f"0..{MAX_FORCE_MODE['limits']:g}), `type`? (1–3, default {FORCE_MODE_TYPE}), `damping`? "
            f"(0..1, {FORCE_MODE_DAMPING:g}), `gain_scaling`? (0..2, {FORCE_MODE_GAIN_SCALING:g})"
        ),
        reply_doc=(
            "URScript `force_mode` semantics (UR); refused as busy while a linear goal is planned from "
            "where the robot rests"
        ),
    ),
    _payloadless(
        "end_force_mode",
        "end force mode",
        lambda host: host.backend.force_mode(None),
        needs="force_mode",
        reply_doc="",
    ),
    _payloadless(
        "start_tool_contact",
        "arm tool-contact detection (the outcome is a tool_contact event)",
        lambda host: host.backend.tool_contact(True),
        needs="tool_contact",
        reply_doc=(
            "arm tool-contact detection; the outcome is a `tool_contact` event (`text`: `contact` or "
            "`canceled`); on a contact the robot stops and goes back to where the tool touched; as it "
            "reports the contact the goal or stream that was running ends (a goal `aborted`, reason "
            "starting `tool contact`), and goals, streams and freedrive are refused (`busy: tool "
            "contact ...`) until `end_tool_contact`"
        ),
    ),
    _payloadless(
        "end_tool_contact",
        "end tool-contact detection",
        lambda host: host.end_tool_contact(),
        needs="tool_contact",
        reply_doc="",
    ),
    ServiceSpec(
        "cycle_stats",
        "cycle counters since the start and the turnaround since the last reset",
        CycleStatsRequest,
        lambda payload: CycleStatsRequest(service_requests.decode_cycle_stats(payload)),
        _cycle_stats,
        needs=None,
        commanding=False,  # reads counters only: anyone may ask
        request_doc="`reset`? (false), or an empty payload",
        reply_doc=(
            '`{"ok": true, "cycles", "missed_cycles", "late_cycles", "turnaround": {"count", "p50_us", '
            '"p99_us", "p999_us", "max_us"}}`: the turnaround is, per cycle, from the RTDE package\'s '
            "bytes reaching the daemon to the reverse-interface frame leaving it (UR; 1 µs bins, exact "
            "maximum; `count` 0 on mock and servo), since the last reset; `reset: true` starts a new "
            "turnaround window after this reply (the three cycle counts run from the backend's start and "
            "are never reset: subtract two replies). On `ur`, `missed_cycles` are packages that never "
            "arrived (gaps in the controller's clock) and `late_cycles` packages that came late: the "
            "first after a gap, and those that queued behind a newer one in the same read (the daemon's "
            "loop was held up), which run the controller only — only the newest package of a read sends a"
            " command and publishes; on `mock` and `servo`, ticks of the daemon's own clock that were "
            "missed or ran late"
        ),
    ),
    ServiceSpec(
        "doctor",
        "check what decides whether the robot runs well: each check's verdict and what to do",
        None,
        _without_arguments("doctor"),
        _doctor,
        needs=None,
        commanding=False,  # measures only, changes nothing: anyone may ask
        request_doc="none, or `{}`",
        reply_doc=(
            '`{"ok": true, "robot", "verdict", "checks": [{"name", "verdict", "measured", "action"}], '
            '"host": {…}, "facts": {…}}`: each check\'s verdict is `ok`, `warn`, `fail`, `unknown` or '
            "`n/a`, `verdict` the worst of them; the host's kernel and real-time priority, and per "
            "robot (UR) the dashboard and primary links, the dashboard round trip, the controller's "
            "version, remote control, the callback ports, the RTDE arrival jitter and clock offset, then "
            "the cycles and turnaround ([doctor.md](doctor.md)); within about 3 s, dashboard queries only"
        ),
        timeout=15.0,
    ),
)
"""Every service but ``stop``, in docs/keys.md's order; each runs through the runtime's one service
path (one reply, refused while it still runs or once the daemon shuts down)."""

STOP = ServiceSpec(
    "stop",
    "stop whatever moves the robot (never refused)",
    None,
    _ignored,
    None,
    needs=None,
    commanding=False,  # never refused, from anyone
    request_doc="anything (ignored)",
    reply_doc=(
        "smooth stop of whatever moves the robot; a running goal ends `aborted`. Unconditional: a stop "
        "is never refused for its payload"
    ),
)
"""``stop``: answered at once by the runtime, whatever its payload, however busy the robot is."""

_BY_NAME = {entry.name: entry for entry in (*SERVICES, STOP)}


def spec(name: str) -> ServiceSpec:
    """The entry of service ``name`` (KeyError for no such service)."""
    return _BY_NAME[name]


def names() -> tuple[str, ...]:
    """Every service's name, ``stop`` last."""
    return tuple(_BY_NAME)


def markdown_rows() -> list[str]:
    """docs/keys.md's table rows of the services, in order, ``stop`` last."""
    return [
        f"| `<cell>/<robot>/service/{entry.name}` | {entry.request_doc} |"
        + (f" {entry.reply_doc} |" if entry.reply_doc else " |")
        for entry in (*SERVICES, STOP)
    ]


if __name__ == "__main__":
    print("\n".join(markdown_rows()))
