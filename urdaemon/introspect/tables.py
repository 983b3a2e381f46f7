"""The text ``urdaemon list`` and ``urdaemon info`` print, from what the daemons answered. Pure: the
answers (``<cell>/daemon``, docs/keys.md) and the measured rates in, lines out."""

from __future__ import annotations

import datetime
import math
from collections.abc import Mapping, Sequence
from typing import Any

from urdaemon.introspect.survey import Survey

__all__ = ["MeasuredRate", "align", "duration_text", "info_lines", "lease_text", "list_lines"]

MeasuredRate = tuple[float | None, int, str]
"""A key's measured rate (None: fewer than two messages), its message count, the time source."""
UNKNOWN = "?"
NO_DAEMON = "no answer on {cell}/daemon (a daemon older than this command, or this session may not read it)"


def align(rows: Sequence[Sequence[str]], indent: str = "  ") -> list[str]:
    """Rows as columns padded to their widest cell (the last column unpadded)."""
    if not rows:
        return []
    widths = [max(len(row[i]) for row in rows) for i in range(len(rows[0]))]
    return [
        (indent + "  ".join(cell.ljust(width) for cell, width in zip(row, widths, strict=True))).rstrip()
        for row in rows
    ]


def duration_text(seconds: float) -> str:
    """``3h02m``, ``5m07s``, ``42s``."""
    if not math.isfinite(seconds) or seconds < 0:
        return UNKNOWN
    whole = int(seconds)
    hours, rest = divmod(whole, 3600)
    minutes, secs = divmod(rest, 60)
    if hours:
        return f"{hours}h{minutes:02d}m"
    return f"{minutes}m{secs:02d}s" if minutes else f"{secs}s"


def lease_text(lease: object) -> str:
    """Who holds a lease (``-``: nobody)."""
    if not isinstance(lease, Mapping):
        return "-"
    return str(lease.get("holder", UNKNOWN))


def _daemon_line(cell: str, daemon: Mapping[str, Any] | None) -> str:
    if daemon is None:
        return f"cell {cell}: " + NO_DAEMON.format(cell=cell)
    up = UNKNOWN
    started, now = daemon.get("started_at_ns"), daemon.get("host_time_ns")
    if isinstance(started, int) and isinstance(now, int):
        up = duration_text((now - started) / 1e9)
    listen = ", ".join(str(e) for e in daemon.get("listen", [])) or "-"
    return (
        f"cell {cell}: urdaemon {daemon.get('version', UNKNOWN)} on {daemon.get('host', UNKNOWN)} "
        f"(pid {daemon.get('pid', UNKNOWN)}), up {up}, listening on {listen}"
    )


def list_lines(found: Survey) -> list[str]:
    """Every cell, its daemon and its robots: backend, model, rate, lifecycle, lease holder."""
    if not found.cells:
        return ["nothing reachable: no daemon answered and no robot is alive"]
    lines: list[str] = []
    for cell in found.cells:
        daemon = found.daemons.get(cell)
        lines.append(_daemon_line(cell, daemon))
        rows = [["ROBOT", "BACKEND", "MODEL", "RATE_HZ", "LIFECYCLE", "LEASE"]]
        alive = {robot for c, robot in found.alive if c == cell}
        for name in sorted(set(found.robots_of(cell)) | alive):
            robot = found.robot(cell, name) or {}
            lifecycle = str(robot.get("lifecycle", UNKNOWN))
            if name not in alive:
                lifecycle += " (no liveliness token)"
            rate = robot.get("rate_hz")
            rows.append(
                [
                    name,
                    str(robot.get("backend", UNKNOWN)),
                    str(robot.get("model", UNKNOWN)),
                    f"{rate:g}" if isinstance(rate, int | float) else UNKNOWN,
                    lifecycle,
                    lease_text(robot.get("lease")) if robot else UNKNOWN,
                ]
            )
        lines += align(rows)
    return lines


def _version_text(version: object) -> str:
    if not isinstance(version, Mapping):
        return "none (not a UR controller, or not connected)"
    number = f"{version.get('major')}.{version.get('minor')}.{version.get('bugfix')}"
    return f"{version.get('project')} {number} (build {version.get('build')}, {version.get('date')})"


def _calibration_text(robot: Mapping[str, Any]) -> str:
    configured = robot.get("calibration") or {}
    source = configured.get("file") or "the model's nominal kinematics"
    check = {True: "matches the robot", False: "MISMATCH with the robot", None: "not checked"}
    shown = check.get(robot.get("calibration_ok"), UNKNOWN)
    expected = configured.get("expected_hash")
    return f"{source}; {shown}" + (f" (expected hash {expected})" if expected else "")


def _ports_text(ports: object) -> str:
    if not isinstance(ports, Mapping):
        return "none (not a UR robot)"
    controller = ", ".join(f"{k} {v}" for k, v in (ports.get("controller") or {}).items())
    callbacks = ", ".join(f"{k} {v}" for k, v in (ports.get("callbacks") or {}).items())
    return f"controller {ports.get('address')}: {controller}; callbacks (this host): {callbacks}"


def _lease_line(lease: object) -> str:
    if not isinstance(lease, Mapping):
        return "free"
    since = lease.get("since")
    when = UNKNOWN
    if isinstance(since, int | float) and math.isfinite(since):
        when = datetime.datetime.fromtimestamp(since, datetime.UTC).isoformat(timespec="seconds")
    return f"held by {lease.get('holder')} since {when} (fingerprint {lease.get('fingerprint')})"


def _number(value: object, digits: int = 4) -> str:
    return f"{value:.{digits}f}" if isinstance(value, int | float) else "inf"


def _limit_rows(limits: Mapping[str, Any]) -> list[list[str]]:
    rows = [["JOINT", "MIN_RAD", "MAX_RAD", "MAX_VEL", "MAX_ACC"]]
    columns = ("min_position", "max_position", "max_velocity", "max_acceleration")
    for i, name in enumerate(limits.get("names", [])):
        rows.append([str(name), *(_number((limits.get(c) or [None] * (i + 1))[i]) for c in columns)])
    return rows


def _rate_text(measured: MeasuredRate | None) -> str:
    if measured is None:
        return "0 message(s)"
    rate, count, source = measured
    shown = f"{rate:.1f} Hz" if rate is not None else "-"
    return f"{shown} ({count} message(s), {source})"


def _key_rows(
    robot: Mapping[str, Any], measured: Mapping[str, MeasuredRate], window_s: float
) -> list[list[str]]:
    configured = robot.get("publish_rates_hz") or {}
    rows = [["PUBLISHED", "CONFIGURED", f"MEASURED OVER {window_s:g} S"]]
    for key in robot.get("keys", {}).get("published", []):
        chunk = str(key).rsplit("/", 1)[-1]
        rate = configured.get(chunk)
        shown = f"{rate:g} Hz" if isinstance(rate, int | float) else "when it happens"
        if chunk == "status":
            shown = f"on change, >= {rate:g} Hz" if isinstance(rate, int | float) else shown
        elif chunk == "io":  # looked at io_rate_hz times a second, sent on change and at least each second
            shown = f"on change (looked at {rate:g} Hz), >= 1 Hz" if isinstance(rate, int | float) else shown
        rows.append([str(key), shown, _rate_text(measured.get(str(key)))])
    return rows


def info_lines(
    cell: str,
    robot: Mapping[str, Any],
    daemon: Mapping[str, Any],
    measured: Mapping[str, MeasuredRate],
    window_s: float,
) -> list[str]:
    """Everything ``urdaemon info`` shows of one robot."""
    tcp = robot.get("tcp") or {}
    facts = [
        ["daemon:", _daemon_line(cell, daemon).split(": ", 1)[1]],
        ["model:", str(robot.get("model", UNKNOWN))],
        ["backend:", f"{robot.get('backend', UNKNOWN)} at {robot.get('rate_hz', UNKNOWN)} Hz"],
        ["lifecycle:", f"{robot.get('lifecycle', UNKNOWN)} ({robot.get('reason') or 'ready'})"],
        ["controller:", _version_text(robot.get("controller_version"))],
        ["calibration:", _calibration_text(robot)],
        ["ports:", _ports_text(robot.get("ports"))],
        ["tcp:", f"{tcp.get('pose')} in {tcp.get('link')} (cell file: {robot.get('tcp_configured')})"],
        ["lease:", _lease_line(robot.get("lease"))],
    ]
    lines = [f"robot {robot.get('name')} in cell {cell}", *align(facts)]
    lines += ["joint limits:", *align(_limit_rows(robot.get("joint_limits") or {}))]
    lines += ["keys:", *align(_key_rows(robot, measured, window_s))]
    keys = robot.get("keys") or {}
    base = f"{cell}/{robot.get('name')}/"
    for kind in ("queryables", "subscribed", "liveliness"):
        names = [str(k).removeprefix(base) for k in keys.get(kind, [])]
        lines.append(f"  {kind} (under {base}): " + ", ".join(names))
    return lines
