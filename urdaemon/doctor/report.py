"""The ``doctor`` service's answer for one robot: the host's facts, the robot's (its controller's from
the backend, its cycles), and the checks ``checks.py`` makes of them.

Runs on the event loop as a service handler: it awaits the backend's dashboard replies, is bounded in
time (backends/ur/diagnosis.py ``BUDGET_S``), and changes nothing (the cycle counters are read, never
reset).
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from urdaemon.doctor.checks import host_checks, robot_checks, worst
from urdaemon.doctor.host import host_facts

if TYPE_CHECKING:
    from urdaemon.backends.base import Backend

__all__ = ["doctor_report"]


async def doctor_report(backend: Backend) -> dict[str, Any]:
    """Gather and judge (the reply adds these to ``{"ok": true}``)."""
    host = host_facts()
    controller = await backend.doctor_facts()
    stats = backend.statistics()
    robot: dict[str, Any] = {
        "backend": backend.kind,
        "rate_hz": backend.rate_hz,
        "cycles": stats.cycles,
        "missed_cycles": stats.missed_cycles,
        "late_cycles": stats.late_cycles,
        "lag_fraction": backend.lag_log.limits.fraction,
        "lag_warnings": backend.lag_log.warnings,
        "turnaround": backend.turnaround.summary(),
        "controller": controller,
    }
    if controller is None:
        robot["why"] = f"{backend.kind} backend: no controller"
    checks = [*host_checks(host), *robot_checks(robot)]
    return {
        "robot": backend.name,
        "verdict": worst(checks).value,
        "checks": [check.as_dict() for check in checks],
        "host": host,
        "facts": robot,
    }
