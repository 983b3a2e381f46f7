"""What the doctor concludes from the facts it gathered: one ``Check`` per question, each with a
verdict, what was measured and what to do (docs/doctor.md).

Pure: facts in (plain dicts, as the ``doctor`` service gathers them: the daemon's host's and one
robot's), checks out. No clock, no socket, no file: ``doctor/host.py`` and the backends gather,
this decides, so the tables of tests/doctor/test_checks.py pin every verdict.
"""

from __future__ import annotations

import enum
import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

__all__ = [
    "CLOCK_BASELINE_S",
    "DRIFT_WARN_PPM",
    "LAG_FAIL_FRACTION",
    "LAG_WARN_FRACTION",
    "ROUND_TRIP_WARN_MS",
    "Check",
    "Verdict",
    "host_checks",
    "robot_checks",
    "worst",
]

Facts = Mapping[str, Any]

DOCS = "docs/doctor.md"
ROUND_TRIP_WARN_MS = (10.0, 50.0)
"""Dashboard round trips: a median above the first or a maximum above the second warns (the
dashboard server is PolyScope's Java process: slower than the network, but never by that much)."""
LAG_WARN_FRACTION = 1e-3
"""Missed plus late cycles above this fraction of all cycles warn (``ur``; a tenth of the backend's
``lag_fraction`` fact where it has one)."""
LAG_FAIL_FRACTION = 1e-2
"""... and above this fraction fail: one cycle in a hundred without a fresh command (``ur``; the
backend's ``lag_fraction``, the share its log warns of: backends/timing.py ``LagLimits``)."""
DRIFT_WARN_PPM = 100.0
"""Host and controller clocks drifting apart faster than this warn (quartz clocks stay within tens)."""
CLOCK_BASELINE_S = 10.0
"""The drift is judged only over a baseline at least this long (since the RTDE link came up)."""
E_SERIES_FULL = (5, 10)
"""The e-Series version from which the control script uses every feature (``set_target_payload``
5.10, ``tool_contact`` 5.4: urscript.py)."""
REMOTE_CONTROL_SINCE = (5, 6)
"""The first e-Series version whose dashboard answers ``is in remote control`` (docs/protocols.md)."""
SECURITY_SERVICES_SINCE = (5, 17)
"""From this PolyScope version on, Settings > Security > Services can turn the dashboard server and
the primary interface off."""


class Verdict(enum.StrEnum):
    """How one check came out."""

    OK = "ok"
    WARN = "warn"
    FAIL = "fail"
    UNKNOWN = "unknown"
    """Could not be measured now (the reason is in ``measured``)."""
    NA = "n/a"
    """Does not apply to this robot (e.g. a mock has no controller)."""


_RANK = {Verdict.OK: 0, Verdict.NA: 0, Verdict.UNKNOWN: 1, Verdict.WARN: 2, Verdict.FAIL: 3}


@dataclass(frozen=True, slots=True)
class Check:
    """One question the doctor answers."""

    name: str
    verdict: Verdict
    measured: str
    """What was measured (or why nothing could be)."""
    action: str = ""
    """What to do about it ("" when nothing needs doing)."""

    def as_dict(self) -> dict[str, str]:
        """The check as the ``doctor`` service's reply lists it."""
        return {
            "name": self.name,
            "verdict": self.verdict.value,
            "measured": self.measured,
            "action": self.action,
        }


def worst(checks: Sequence[Check]) -> Verdict:
    """The most serious verdict among ``checks`` (OK for none)."""
    return max((c.verdict for c in checks), key=_RANK.__getitem__, default=Verdict.OK)


# ---- the host --------------------------------------------------------------------------------------


def host_checks(host: Facts) -> list[Check]:
    """The kernel's scheduling and the daemon's real-time priority (``doctor/host.py``'s facts)."""
    return [_kernel(host), _realtime(host)]


def _kernel(host: Facts) -> Check:
    kernel = f"{host.get('release', '?')} {host.get('version', '')}".strip()
    if host.get("preempt_rt"):
        return Check("kernel", Verdict.OK, f"PREEMPT_RT: {kernel}")
    return Check(
        "kernel",
        Verdict.WARN,
        f"no PREEMPT_RT: {kernel}",
        f"PREEMPT_RT absent: cycles may be late under load; install a PREEMPT_RT kernel ({DOCS}#kernel)",
    )


def _realtime(host: Facts) -> Check:
    asked = int(host.get("realtime_priority") or 0)
    policy, priority = host.get("loop_policy", "?"), host.get("loop_priority", 0)
    running = f"event loop thread {policy}" + (f" priority {priority}" if policy == "SCHED_FIFO" else "")
    permitted = _fifo_permitted(host)
    if asked and policy == "SCHED_FIFO":
        return Check("realtime_priority", Verdict.OK, f"realtime_priority {asked}: {running}")
    if asked:
        why = host.get("realtime_error") or "not in effect"
        return Check(
            "realtime_priority",
            Verdict.FAIL,
            f"realtime_priority {asked} asked, {running}: {why}",
            f"give the daemon's user an rtprio limit of at least {asked} or CAP_SYS_NICE, then restart "
            f"it ({DOCS}#realtime_priority)",
        )
    if permitted:
        return Check(
            "realtime_priority",
            Verdict.WARN,
            f"realtime_priority not set (0), though SCHED_FIFO is permitted ({_permission(host)}); {running}",
            "set realtime_priority (e.g. 80) in the cell file so the loop is not preempted "
            f"({DOCS}#realtime_priority)",
        )
    return Check(
        "realtime_priority",
        Verdict.WARN,
        f"realtime_priority not set (0) and SCHED_FIFO not permitted ({_permission(host)}); {running}",
        "allow SCHED_FIFO (an rtprio limit, LimitRTPRIO= in a systemd unit, or CAP_SYS_NICE), then set "
        f"realtime_priority (e.g. 80) in the cell file ({DOCS}#realtime_priority)",
    )


def _fifo_permitted(host: Facts) -> bool:
    limit = host.get("rtprio_limit")
    return bool(host.get("root") or host.get("cap_sys_nice") or (isinstance(limit, int) and limit != 0))


def _permission(host: Facts) -> str:
    limit = host.get("rtprio_limit")
    shown = "unlimited" if limit == -1 else str(limit)
    return f"rtprio limit {shown}, CAP_SYS_NICE {'yes' if host.get('cap_sys_nice') else 'no'}"


# ---- one robot -------------------------------------------------------------------------------------


def robot_checks(robot: Facts) -> list[Check]:
    """Every check of one robot: its controller's (``ur``) or why there is none, then its cycles."""
    controller = robot.get("controller")
    checks: list[Check]
    if controller is None:
        why = robot.get("why") or f"{robot.get('backend', '?')} backend: no controller"
        checks = [Check("controller", Verdict.NA, why)]
    else:
        checks = [check(controller) for check in _CONTROLLER_CHECKS]
    return [*checks, _cycles(robot), _turnaround(robot)]


def _dashboard(c: Facts) -> Check:
    board = c.get("dashboard") or {}
    if board.get("connected"):
        return Check("dashboard", Verdict.OK, f"connected to {c.get('address')}:29999")
    return Check(
        "dashboard",
        Verdict.FAIL,
        f"cannot talk to the dashboard server: {board.get('error') or 'not connected'}",
        "the dashboard server may be disabled: on PolyScope >= 5.17 enable it in Settings > Security > "
        f"Services; else check the robot's address and network ({DOCS}#dashboard)",
    )


def _primary(c: Facts) -> Check:
    links = c.get("links") or {}
    if links.get("primary"):
        return Check("primary", Verdict.OK, "primary interface (30001) connected")
    return Check(
        "primary",
        Verdict.FAIL,
        "primary interface (30001) not connected" + (f": {links['error']}" if links.get("error") else ""),
        "the primary interface may be disabled: on PolyScope >= 5.17 enable it in Settings > Security > "
        f"Services; the daemon reconnects on its own ({DOCS}#primary)",
    )


def _round_trip(c: Facts) -> Check:
    trips = [float(t) for t in (c.get("dashboard") or {}).get("round_trips_ms") or ()]
    if not trips:
        return Check("round_trip", Verdict.UNKNOWN, "no dashboard round trip measured (no dashboard)")
    ordered = sorted(trips)
    median = ordered[len(ordered) // 2]
    mean = sum(trips) / len(trips)
    std = math.sqrt(sum((t - mean) ** 2 for t in trips) / len(trips))
    measured = (
        f"dashboard robotmode x{len(trips)}: min {ordered[0]:.2f} / median {median:.2f} / max "
        f"{ordered[-1]:.2f} ms, std {std:.2f} ms"
    )
    slow_median, slow_max = ROUND_TRIP_WARN_MS
    if median > slow_median or ordered[-1] > slow_max:
        return Check(
            "round_trip",
            Verdict.WARN,
            measured,
            "slow or uneven replies: put the robot on a direct, wired link (no Wi-Fi, no busy switch) "
            f"and keep other clients off its dashboard ({DOCS}#round_trip)",
        )
    return Check("round_trip", Verdict.OK, measured)


def _version(c: Facts) -> Check:
    version = _tuple(c.get("polyscope_version")) or _tuple(c.get("rtde_version"))
    if not version:
        return Check("controller_version", Verdict.UNKNOWN, "the controller did not say its version")
    text = ".".join(map(str, version))
    rtde = _tuple(c.get("rtde_version"))
    if rtde and rtde[:2] != version[:2]:
        return Check(
            "controller_version",
            Verdict.WARN,
            f"the dashboard says {text}, RTDE says {'.'.join(map(str, rtde))}",
            "two different controllers answer at this address? check the robot's address "
            f"({DOCS}#controller_version)",
        )
    if version[0] == 5 and version[:2] < E_SERIES_FULL:
        return Check(
            "controller_version",
            Verdict.WARN,
            f"PolyScope {text}: the control script leaves out what needs >= 5.10 (set_target_payload; "
            "tool contact needs 5.4)",
            f"update PolyScope to 5.10 or later for every feature ({DOCS}#controller_version)",
        )
    series = "CB3" if version[0] < 5 else "e-Series" if version[0] == 5 else "PolyScope X"
    return Check("controller_version", Verdict.OK, f"PolyScope {text} ({series})")


def _remote(c: Facts) -> Check:
    remote = c.get("remote_control")
    version = _tuple(c.get("polyscope_version")) or _tuple(c.get("rtde_version"))
    if remote is True:
        return Check("remote_control", Verdict.OK, "remote control on")
    if remote is None:
        if version and version[0] < 5:
            return Check("remote_control", Verdict.NA, "CB3 has no remote control mode")
        if version and version[0] == 5 and version[:2] < REMOTE_CONTROL_SINCE:
            shown = ".".join(map(str, version))
            return Check("remote_control", Verdict.UNKNOWN, f"PolyScope {shown} cannot tell (5.6+)")
        said = c.get("remote_control_text")
        answer = f": {said}" if said else ""
        return Check("remote_control", Verdict.UNKNOWN, f"not asked or not answered{answer}")
    action = (
        "remote control is off: set the robot to Remote Control on the pendant (the pendant's top right "
        f"corner: Local/Remote; enable it in Settings > System > Remote Control) ({DOCS}#remote_control)"
    )
    if c.get("headless", True) and not c.get("read_only"):
        refused = "remote control off: the robot refuses the daemon's program"
        return Check("remote_control", Verdict.FAIL, refused, action)
    return Check(
        "remote_control", Verdict.WARN, "remote control off: the dashboard cannot power on or play", action
    )


def _callbacks(c: Facts) -> Check:
    back = c.get("callbacks") or {}
    if c.get("read_only"):
        return Check("callback_ports", Verdict.NA, "read-only robot: no control program, no callback ports")
    ports = back.get("ports") or {}
    listed = ", ".join(f"{name} {entry.get('port')}" for name, entry in ports.items())
    where = back.get("listening_on")
    dials = back.get("dials") or "?"
    closed = [name for name, entry in ports.items() if not entry.get("listening")]
    if where is None or closed:
        return Check(
            "callback_ports",
            Verdict.FAIL,
            f"not listening ({', '.join(closed) or listed}); the program dials {dials}",
            f"see the daemon's log for why the ports could not be opened ({DOCS}#callback_ports)",
        )
    measured = f"listening on {where} ({listed}); the program dials {dials}"
    reverse = ports.get("reverse") or {}
    if reverse.get("connected"):
        peer = reverse.get("peer") or "the robot"
        return Check("callback_ports", Verdict.OK, f"{measured}; reached from {peer} (reverse link up)")
    return Check(
        "callback_ports",
        Verdict.WARN,
        f"{measured}; the robot has not reached them (no reverse link)",
        "start the control program (urdaemon service ROBOT startup, or play External Control); if it "
        f"runs, open those ports toward {dials} in this machine's firewall ({DOCS}#callback_ports)",
    )


def _rtde_jitter(c: Facts) -> Check:
    clock = c.get("clock") or {}
    if clock.get("offset_s") is None:
        seen = int(clock.get("samples") or 0)
        return Check("rtde_jitter", Verdict.UNKNOWN, f"{seen} RTDE packages seen (RTDE link down?)")
    jitter = float(clock.get("jitter_ms", 0.0))
    period = float(clock.get("period_ms", 0.0))
    measured = (
        f"RTDE arrival jitter {jitter:.3f} ms peak to peak over {clock['samples']} packages "
        f"(period {period:g} ms)"
    )
    if period and jitter > period:
        return Check(
            "rtde_jitter",
            Verdict.WARN,
            measured,
            "packages arrive bunched: a wired direct link to the robot, realtime_priority, and a quieter "
            f"host keep them a period apart ({DOCS}#rtde_jitter)",
        )
    return Check("rtde_jitter", Verdict.OK, measured)


def _clock(c: Facts) -> Check:
    clock = c.get("clock") or {}
    offset = clock.get("offset_s")
    if offset is None:
        return Check("clock_offset", Verdict.UNKNOWN, "no RTDE packages seen (RTDE link down?)")
    baseline = float(clock.get("baseline_s") or 0.0)
    shown = f"host - controller = {offset:.6f} s"
    drift = clock.get("drift_ppm")
    if drift is None or baseline < CLOCK_BASELINE_S:
        return Check(
            "clock_offset",
            Verdict.OK,
            f"{shown}; drift not judged yet (RTDE up {baseline:.1f} s, needs {CLOCK_BASELINE_S:g} s)",
        )
    bound = float(clock.get("drift_bound_ppm") or 0.0)
    measured = f"{shown}; drift {drift:+.1f} ppm (+-{bound:.1f}) over {baseline:.0f} s"
    if abs(drift) - bound > DRIFT_WARN_PPM:
        return Check(
            "clock_offset",
            Verdict.WARN,
            measured,
            "the clocks run apart: synchronize the host (chrony/PTP) and the controller (Settings > "
            f"System > Time: NTP) to one source ({DOCS}#clock_offset)",
        )
    return Check("clock_offset", Verdict.OK, measured)


_CONTROLLER_CHECKS: tuple[Callable[[Facts], Check], ...] = (
    _dashboard,
    _primary,
    _round_trip,
    _version,
    _remote,
    _callbacks,
    _rtde_jitter,
    _clock,
)


def _cycles(robot: Facts) -> Check:
    cycles = int(robot.get("cycles") or 0)
    missed, late = int(robot.get("missed_cycles") or 0), int(robot.get("late_cycles") or 0)
    if cycles == 0:
        return Check("cycles", Verdict.UNKNOWN, "no cycle ran yet (is the robot connected?)")
    fail = float(robot.get("lag_fraction") or LAG_FAIL_FRACTION)
    lagged = (missed + late) / (cycles + missed)
    measured = f"{missed} missed, {late} late of {cycles} cycles since the daemon started ({lagged:.3%})"
    if robot.get("lag_warnings"):
        measured += f"; {robot['lag_warnings']} warning(s) logged"
    if lagged <= fail * (LAG_WARN_FRACTION / LAG_FAIL_FRACTION):
        return Check("cycles", Verdict.OK, measured)
    return Check(
        "cycles",
        Verdict.FAIL if lagged > fail else Verdict.WARN,
        measured,
        "the machine or the event loop is too busy for this rate: set realtime_priority, use a "
        f"PREEMPT_RT kernel, keep other load off the host ({DOCS}#cycles)",
    )


def _turnaround(robot: Facts) -> Check:
    turn = robot.get("turnaround") or {}
    if not turn.get("count"):
        if robot.get("controller") is None:
            why = robot.get("why") or "no controller"
            return Check("turnaround", Verdict.NA, f"{why}: the command is applied in the daemon's own step")
        return Check("turnaround", Verdict.UNKNOWN, "no command sent yet (is the control program running?)")
    period_us = 1e6 / float(robot.get("rate_hz") or 500.0)
    p99, top = float(turn.get("p99_us", 0.0)), float(turn.get("max_us", 0.0))
    measured = (
        f"package in -> command out: p50 {turn.get('p50_us', 0):g} / p99 {p99:g} / max {top:g} us "
        f"over {turn['count']} cycles"
    )
    if p99 > period_us:
        verdict = Verdict.FAIL
    elif p99 > period_us / 4 or top > period_us:
        verdict = Verdict.WARN
    else:
        return Check("turnaround", Verdict.OK, measured)
    return Check(
        "turnaround",
        verdict,
        measured,
        f"commands leave late (period {period_us:g} us): set realtime_priority and keep the host's other "
        f"load off the daemon's core ({DOCS}#turnaround)",
    )


def _tuple(value: Any) -> tuple[int, ...]:
    if not isinstance(value, list | tuple):
        return ()
    return tuple(int(v) for v in value if isinstance(v, int))
