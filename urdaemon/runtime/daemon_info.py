"""The daemon's description of itself, answered on ``<cell>/daemon`` (what ``urdaemon list`` and
``urdaemon info`` show).

What never changes (host, pid, version, listen endpoints, each robot's model, ports, limits,
configured rates and keys) is gathered once when the daemon starts; what changes (lifecycle, lease,
calibration check, controller version, TCP) is read at the moment of the query from the owners that
keep it (the robot's status message, its backend). Nothing here runs in a robot's cycle: the
queryable is answered on the loop, between cycles, when someone asks.
"""

from __future__ import annotations

import contextlib
import logging
import os
import socket
import time
from collections.abc import Sequence
from typing import Any, Protocol

from urdaemon import __version__
from urdaemon.backends.base import Backend
from urdaemon.cell.config import Cell
from urdaemon.cell.robot_options import Robot
from urdaemon.model import JointLimits
from urdaemon.publish import envelope
from urdaemon.publish.endpoints import ROBOT, ROBOT_ENDPOINTS, Kind
from urdaemon.publish.keys import CellKeys, RobotKeys

__all__ = ["DaemonInfo", "DescribedRobot", "robot_keys", "ur_ports"]

log = logging.getLogger(__name__)


class _Poses(Protocol):
    @property
    def available(self) -> bool:
        """Whether the robot publishes its TCP pose."""


class DescribedRobot(Protocol):
    """What the daemon's self-description reads of each robot (robot.py's ``RobotRuntime`` is one)."""

    @property
    def robot(self) -> Robot:
        """Its options: name, model, ports, calibration, TCP, servo."""

    @property
    def backend(self) -> Backend:
        """Its backend: kind, rate, and what it heard of the controller."""

    @property
    def keys(self) -> RobotKeys:
        """Its keys."""

    @property
    def service_names(self) -> frozenset[str]:
        """The services it answers (once declared)."""

    @property
    def tcp_poses(self) -> _Poses:
        """Its TCP poses: whether it publishes them."""

    def status_message(self) -> dict[str, Any]:
        """Its status message body, now."""


def ur_ports(robot: Robot) -> dict[str, Any] | None:
    """A UR robot's ports: the controller's (primary, RTDE, dashboard) at its address, and the
    daemon's callback ports its control program connects back to; None for other backends."""
    if robot.backend != "ur":
        return None
    from urdaemon.protocols.dashboard import DASHBOARD_PORT
    from urdaemon.protocols.primary import PRIMARY_PORT
    from urdaemon.protocols.rtde import RTDE_PORT

    return {
        "address": robot.address,
        "controller": {"primary": PRIMARY_PORT, "rtde": RTDE_PORT, "dashboard": DASHBOARD_PORT},
        "callbacks": robot.ports.as_dict(),
    }


_LISTED = {
    Kind.PUBLICATION: "published",
    Kind.QUERYABLE: "queryables",
    Kind.SUBSCRIBER: "subscribed",
    Kind.LIVELINESS: "liveliness",
}
"""Where the reply lists a row of each kind (a client's token, ``Kind.TOKEN``, is not the robot's key)."""


def robot_keys(keys: RobotKeys, services: Sequence[str], *, posed: bool, servo: bool) -> dict[str, list[str]]:
    """The keys one robot serves, by what it does on them (docs/keys.md): every row of the endpoint
    table (publish/endpoints.py) it serves, in the table's order, its services by name."""
    skipped = {ROBOT.tcp_pose: not posed, ROBOT.servo_command: not servo}
    listed: dict[str, list[str]] = {name: [] for name in _LISTED.values()}
    for row in ROBOT_ENDPOINTS:
        if row.kind in _LISTED and row.service is None and not skipped.get(row, False):
            listed[_LISTED[row.kind]].append(row.key(keys))
    listed["queryables"] += [ROBOT.service(name).key(keys) for name in sorted(services)]
    return listed


def _limits(limits: JointLimits) -> dict[str, Any]:
    return {
        "names": list(limits.names),
        "min_position": list(limits.min_position),
        "max_position": list(limits.max_position),
        "max_velocity": list(limits.max_velocity),
        "max_acceleration": list(limits.max_acceleration),
    }


class DaemonInfo:
    """Answers ``<cell>/daemon``: the facts gathered at start-up, and the live ones at query time."""

    def __init__(
        self,
        cell: Cell,
        runtimes: Sequence[DescribedRobot],
        limits: dict[str, JointLimits],
        listen: Sequence[str],
    ) -> None:
        self._keys = CellKeys(cell.cell)
        self._runtimes = tuple(runtimes)
        publish = cell.publish
        self._fixed: dict[str, Any] = {
            "cell": cell.cell,
            "host": socket.gethostname(),
            "pid": os.getpid(),
            "version": __version__,
            "started_at_ns": time.time_ns(),
            "listen": list(listen),
            "rates_hz": {
                "tf": publish.tf_rate_hz,
                "status": publish.status_rate_hz,
                "io": publish.io_rate_hz,
            },
            "keys": {
                "published": [self._keys.tf, self._keys.goal_messages],
                "queryables": [
                    self._keys.robot_description,
                    self._keys.stop,
                    self._keys.goal_trajectory,
                    self._keys.goal_cancel,
                    self._keys.goal_results,
                    self._keys.daemon,
                ],
            },
        }
        self._robots = [self._robot_facts(rt, limits[rt.robot.name], cell) for rt in self._runtimes]

    @staticmethod
    def _robot_facts(runtime: DescribedRobot, limits: JointLimits, cell: Cell) -> dict[str, Any]:
        robot, backend = runtime.robot, runtime.backend
        state_hz = backend.rate_hz / cell.publish.joint_states_decimation
        posed = runtime.tcp_poses.available
        rates: dict[str, float] = {"joint_states": state_hz}
        if posed:
            rates["tcp_pose"] = state_hz
        rates |= {"status": cell.publish.status_rate_hz, "io": cell.publish.io_rate_hz}
        publishes_pulses = robot.servo is not None and robot.servo.publishes
        if publishes_pulses:
            rates["servo_command"] = backend.rate_hz
        return {
            "name": robot.name,
            "backend": backend.kind,
            "model": robot.model,
            "rate_hz": backend.rate_hz,
            "publish_rates_hz": rates,
            "keys": robot_keys(
                runtime.keys, sorted(runtime.service_names), posed=posed, servo=publishes_pulses
            ),
            "ports": ur_ports(robot),
            "calibration": {
                "file": robot.calibration,
                "expected_hash": getattr(backend, "expected_hash", None),
            },
            "tcp_configured": list(robot.tcp),
            "joint_limits": _limits(limits),
        }

    def message(self) -> dict[str, Any]:
        """The reply: the fixed facts, each robot's with its live ones, and when it was answered."""
        robots = []
        for runtime, fixed in zip(self._runtimes, self._robots, strict=True):
            status = runtime.status_message()
            live = {
                "lifecycle": status["lifecycle"],
                "reason": status["reason"],
                "lease": status["lease"],
                "calibration_ok": status["calibration_ok"],
                "tcp": status["tcp"],
                # the ur backend's RobotMessages (backends/ur/robot_messages.py) heard it; others have none
                "controller_version": getattr(
                    getattr(runtime.backend, "messages", None), "controller_version", None
                ),
            }
            robots.append({**fixed, **live})
        return {**self._fixed, "host_time_ns": time.time_ns(), "robots": robots}

    def on_query(self, query: Any) -> None:
        """Answer a query on (or a wildcard over) ``<cell>/daemon``; its payload is never read."""
        try:
            asked = str(query.key_expr)
            if asked == self._keys.daemon or _intersects(asked, self._keys.daemon):
                query.reply(self._keys.daemon, envelope.encode(self.message()))
        except Exception as err:  # the querier may have gone; this must never take the cell down
            log.debug("answering %s failed: %s", self._keys.daemon, err)
        finally:
            with contextlib.suppress(Exception):
                query.drop()


def _intersects(asked: str, key: str) -> bool:
    import zenoh

    return bool(zenoh.KeyExpr(asked).intersects(zenoh.KeyExpr(key)))
