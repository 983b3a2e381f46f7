"""How this package calls ruckig: inputs from joint limits, retries on degenerate inputs, every refusal
as a reason, and the true position extrema of a planned trajectory (checked against the limits, which
ruckig's community build ignores)."""

from __future__ import annotations

import math
import re
from collections.abc import Sequence
from typing import Any

from ruckig import InputParameter, Result, RuckigError, Synchronization, Trajectory

from urdaemon.errors import GoalRejected
from urdaemon.model import JointLimits

__all__ = [
    "RETRY_LIMIT_SCALES",
    "RUCKIG_ERRORS",
    "RUCKIG_RESULTS",
    "calculate",
    "check_extrema",
    "new_input",
    "position_extrema",
    "ruckig_failure_reason",
    "ruckig_result_reason",
    "run_robustly",
]

_EXTREMA_EPS = 1e-9


def _fmt(x: float) -> str:
    return f"{x:.6g}"


def new_input(limits: JointLimits, velocity_scale: float = 1.0, acceleration_scale: float = 1.0) -> Any:
    """Ruckig's input for joints with ``limits``, velocity and acceleration limits scaled, the joints
    synchronized in time."""
    inp = InputParameter(limits.dof)
    inp.max_velocity = [v * velocity_scale for v in limits.max_velocity]
    inp.max_acceleration = [a * acceleration_scale for a in limits.max_acceleration]
    inp.max_jerk = list(limits.max_jerk)
    inp.synchronization = Synchronization.Time
    return inp


RETRY_LIMIT_SCALES = (1.0 - 1e-9, 1.0 - 1e-6)
"""ruckig 0.19.4 throws on some exactly-degenerate inputs (e.g. a rest-to-rest move of exactly
2·a³/j², where the profile just touches max acceleration: −1.4 → −1.5 rad at a = 5, j = 50).
Retrying with limits tightened by these factors solves them and stays within the limits."""


RUCKIG_ERRORS = (RuckigError, ValueError)
"""What a ruckig call may throw: its own error, or ValueError when the binding meets a result code it
does not know (e.g. −101, a trajectory longer than ruckig's time range, about 7 600 s)."""


def run_robustly(call: Any, inp: Any) -> Any:
    """Run ``call()`` (ruckig calculate or update on ``inp``); if it throws, retry with tighter limits."""
    try:
        return call()
    except RUCKIG_ERRORS as first:
        limits = (list(inp.max_velocity), list(inp.max_acceleration), list(inp.max_jerk))
        try:
            for scale in RETRY_LIMIT_SCALES:
                inp.max_velocity = [v * scale for v in limits[0]]
                inp.max_acceleration = [a * scale for a in limits[1]]
                inp.max_jerk = [j * scale for j in limits[2]]
                try:
                    return call()
                except RUCKIG_ERRORS:
                    continue
        finally:
            inp.max_velocity, inp.max_acceleration, inp.max_jerk = limits
        raise first


RUCKIG_RESULTS: dict[int, str] = {
    0: "still working (0)",
    1: "finished (1)",
    -1: "an unclassified ruckig error (-1)",
    -100: "its input is invalid (-100)",
    -101: "it would last longer than ruckig's numerical time range, about 7 600 s (-101)",
    -102: "it would leave the position limits (-102)",
    -103: "the joints cannot be phase-synchronized (-103)",
    -104: "a limit of zero makes it impossible (-104)",
    -110: "the minimum-time calculation (step 1) failed: the limits or states are numerically extreme (-110)",
    -111: "synchronizing the joints (step 2) failed: the limits or states are numerically extreme (-111)",
}
"""Every result code ruckig (0.19, and the codes later versions added) can return, as a reason."""

_UNKNOWN_CODE = re.compile(r"(-?\d+) is not a valid")
_MAX_DETAIL = 160


def ruckig_result_reason(code: int) -> str:
    """A clear reason for a ruckig result code, including codes this table does not know."""
    return RUCKIG_RESULTS.get(code, f"ruckig returned the unknown result code {code}")


def ruckig_failure_reason(exc: BaseException) -> str:
    """A clear reason for what a ruckig call threw (its error, or the binding's unknown-code ValueError)."""
    text = str(exc).strip()
    unknown = _UNKNOWN_CODE.search(text)
    if unknown is not None:
        return ruckig_result_reason(int(unknown.group(1)))
    # ruckig appends its whole input to the message; the first line is the reason
    first = text.splitlines()[0].strip() if text else ""
    first = first.removeprefix("[ruckig]").strip()
    if "error in step 1" in first:
        return RUCKIG_RESULTS[-110]
    if "error in step 2" in first:
        return RUCKIG_RESULTS[-111]
    if not first:
        return RUCKIG_RESULTS[-1]
    if len(first) > _MAX_DETAIL:
        first = first[:_MAX_DETAIL] + "…"
    return f"its input is invalid: {first} (-100)"


def calculate(otg: Any, inp: Any, what: str) -> Any:
    """Run the offline solver; ruckig's own refusals become GoalRejected naming ``what``."""
    traj = Trajectory(inp.degrees_of_freedom)
    try:
        result = run_robustly(lambda: otg.calculate(inp, traj), inp)
    except RUCKIG_ERRORS as exc:
        raise GoalRejected(f"{what}: ruckig could not plan it: {ruckig_failure_reason(exc)}") from exc
    if result not in (Result.Working, Result.Finished):
        raise GoalRejected(f"{what}: ruckig could not plan it: {ruckig_result_reason(int(result))}")
    return traj


def _phase_extrema(
    lo: float,
    hi: float,
    t: Sequence[float],
    j: Sequence[float],
    a: Sequence[float],
    v: Sequence[float],
    p: Sequence[float],
) -> tuple[float, float]:
    """Widen [lo, hi] by the positions of piecewise-cubic phases, including where velocity crosses 0."""
    for k, dur in enumerate(t):
        # Entries of unused (zero-length) phases may hold stale values, so they are skipped.
        if dur <= 0.0:
            continue
        p0 = p[k]
        v0 = v[k]
        a0 = a[k]
        jk = j[k]
        p_end = p0 + dur * (v0 + dur * (0.5 * a0 + dur * jk / 6.0))
        lo = min(lo, p0, p_end)
        hi = max(hi, p0, p_end)
        roots: tuple[float, ...]
        if jk != 0.0:
            disc = a0 * a0 - 2.0 * jk * v0
            if disc < 0.0:
                continue
            sq = math.sqrt(disc)
            roots = ((-a0 + sq) / jk, (-a0 - sq) / jk)
        elif a0 != 0.0:
            roots = (-v0 / a0,)
        else:
            continue
        for tau in roots:
            if 0.0 < tau < dur:
                x = p0 + tau * (v0 + tau * (0.5 * a0 + tau * jk / 6.0))
                lo = min(lo, x)
                hi = max(hi, x)
    return lo, hi


def position_extrema(traj: Any) -> list[tuple[float, float]]:
    """Per-joint (min, max) position of a ruckig trajectory, computed from its phase profiles."""
    # ruckig 0.19's own ``position_extrema`` misses an extremum inside a constant-acceleration phase
    # (a stop that reverses), so it is recomputed from every phase's jerk, acceleration and velocity.
    out: list[tuple[float, float]] = []
    for prof in traj.profiles[0]:
        pp = prof.p
        lo = min(pp[0], pp[-1])
        hi = max(pp[0], pp[-1])
        brake = prof.brake
        if brake.duration > 0.0:
            lo, hi = _phase_extrema(lo, hi, brake.t, brake.j, brake.a, brake.v, brake.p)
        lo, hi = _phase_extrema(lo, hi, prof.t, prof.j, prof.a, prof.v, pp)
        out.append((lo, hi))
    return out


def check_extrema(limits: JointLimits, traj: Any, start: Sequence[float], what: str) -> None:
    """Refuse ``traj`` (GoalRejected naming ``what``) if a joint overshoots its position limits."""
    # A start already outside a limit may only move back in, so the bound relaxes to the start value.
    for i, (ext_min, ext_max) in enumerate(position_extrema(traj)):
        lo = min(limits.min_position[i], start[i]) - _EXTREMA_EPS
        hi = max(limits.max_position[i], start[i]) + _EXTREMA_EPS
        if ext_max > hi:
            raise GoalRejected(
                f"{what}: {limits.names[i]} overshoots to {_fmt(ext_max)}, beyond its limit "
                f"{_fmt(limits.max_position[i])}"
            )
        if ext_min < lo:
            raise GoalRejected(
                f"{what}: {limits.names[i]} overshoots to {_fmt(ext_min)}, beyond its limit "
                f"{_fmt(limits.min_position[i])}"
            )
