"""``urdaemon calibration``: read a UR controller's kinematics calibration and write the calibration file.

The controller's primary interface (port 30001) sends a VERSION message right after connecting, then
ROBOT_STATE packages whose KINEMATICS_INFO sub-package carries the calibrated DH parameters and whose
CONFIGURATION_DATA says the robot type. :func:`read_calibration` collects those three with the
daemon's own primary link (``PrimaryLink``, on the shell); :func:`calibration_yaml` turns them into
the file that a robot's ``calibration`` key in the cell file accepts (see
``urdaemon.description.calibration``).
"""

from __future__ import annotations

import asyncio
import contextlib
import math
from dataclasses import dataclass
from typing import Any

import yaml

from urdaemon.backends.ur.primary_link import FIRST_STATE_TIMEOUT_S, PRIMARY_PORT, PrimaryLink
from urdaemon.errors import ProtocolError, UrDaemonError, UrTimeoutError
from urdaemon.protocols import primary as prim
from urdaemon.shell import connect

__all__ = [
    "ControllerCalibration",
    "calibration_document",
    "calibration_yaml",
    "model_for",
    "read_calibration",
]

DEFAULT_PORT = PRIMARY_PORT
DEFAULT_TIMEOUT_S = FIRST_STATE_TIMEOUT_S
CONFIGURATION_GRACE_S = 1.0
"""How long to keep reading for CONFIGURATION_DATA once KINEMATICS_INFO has arrived without it."""

# robot_type (CONFIGURATION_DATA) → model, for controllers of major version ≥ 5 and < 5.
_E_SERIES_MODELS = {1: "ur5e", 2: "ur10e", 3: "ur3e", 4: "ur16e", 7: "ur20", 8: "ur30"}
_CB3_MODELS = {1: "ur5", 2: "ur10", 3: "ur3"}
_ONLY_E_SERIES = {4, 7, 8}
"""Robot types that exist in one series only: their model needs no controller version."""


@dataclass(frozen=True, slots=True)
class ControllerCalibration:
    """What the controller told: its kinematics, and its VERSION and CONFIGURATION_DATA when sent."""

    kinematics: prim.KinematicsInfo
    version: prim.VersionMessage | None
    configuration: prim.ConfigurationData | None


def model_for(robot_type: int | None, major_version: int | None) -> tuple[str | None, str]:
    """The UR model of ``robot_type`` on a controller of ``major_version`` (None if unsure), and why."""
    if robot_type is None:
        return None, "the controller sent no CONFIGURATION_DATA, so the robot type is unknown"
    if robot_type in _ONLY_E_SERIES:
        return _E_SERIES_MODELS[robot_type], f"robot_type {robot_type}"
    if robot_type not in _CB3_MODELS:
        return None, f"robot_type {robot_type} is not a model urdaemon knows"
    if major_version is None:
        return None, (
            f"robot_type {robot_type} is {_CB3_MODELS[robot_type]} or {_E_SERIES_MODELS[robot_type]}, "
            "and the controller sent no VERSION message to tell which"
        )
    table = _E_SERIES_MODELS if major_version >= 5 else _CB3_MODELS
    return table[robot_type], f"robot_type {robot_type} on controller version {major_version}"


def calibration_document(
    kinematics: prim.KinematicsInfo,
    version: prim.VersionMessage | None,
    configuration: prim.ConfigurationData | None,
) -> dict[str, Any]:
    """The calibration file's mapping: ``model`` (when unambiguous), ``hash`` and the absolute ``dh``."""
    model, _ = model_for(
        configuration.robot_type if configuration is not None else None,
        version.major_version if version is not None else None,
    )
    document: dict[str, Any] = {}
    if model is not None:
        document["model"] = model
    document["hash"] = kinematics.kinematics_hash()
    document["dh"] = {
        "theta": [float(v) for v in kinematics.dh_theta],
        "a": [float(v) for v in kinematics.dh_a],
        "d": [float(v) for v in kinematics.dh_d],
        "alpha": [float(v) for v in kinematics.dh_alpha],
    }
    return document


def calibration_yaml(reading: ControllerCalibration, source: str) -> str:
    """The calibration file text for ``reading`` from ``source`` (e.g. ``10.0.0.2:30001``), with a header."""
    document = calibration_document(reading.kinematics, reading.version, reading.configuration)
    model, why = model_for(
        reading.configuration.robot_type if reading.configuration is not None else None,
        reading.version.major_version if reading.version is not None else None,
    )
    lines = [
        "# UR kinematics calibration, read by `urdaemon calibration` from the controller's",
        f"# KINEMATICS_INFO at {_printable(source)}.",
        f"# controller: {_version_text(reading.version)}",
    ]
    if model is not None:
        lines.append(f"# model: {model} ({why})")
    else:
        lines.append(f"# model: left out ({why}); set the robot's model in the cell file yourself")
    lines.append(
        "# dh: absolute standard DH (rad, m) as the controller reports it; hash: its kinematics hash"
    )
    body = yaml.safe_dump(document, sort_keys=False, default_flow_style=None, width=4096)
    return "\n".join(lines) + "\n" + body


def _version_text(version: prim.VersionMessage | None) -> str:
    if version is None:
        return "unknown (no VERSION message)"
    name = _printable(version.project_name) or "?"
    return (
        f"{name} {version.major_version}.{version.minor_version}.{version.bugfix_version}"
        f" build {version.build_number}"
    )


def _printable(text: str) -> str:
    """``text`` with anything that could break a YAML comment line replaced by '?'."""
    return "".join(c if c.isprintable() else "?" for c in text)


class _CalibrationReader(PrimaryLink):
    """The daemon's primary link, woken on every message, that also checks the stream at its end."""

    def __init__(self) -> None:
        super().__init__(lambda message: None)
        self.changed = asyncio.Event()
        self.lost: Exception | None = None
        """The socket error that ended the connection, if one did."""

    def _on_event(self, event: Any) -> None:
        super()._on_event(event)
        self.changed.set()

    def eof_received(self) -> bool | None:
        try:
            self.conn.receive_eof()  # a package cut off by the close is bad data
        except ProtocolError as err:
            self.fail(err)
        return None

    def connection_lost(self, exc: Exception | None) -> None:
        self.lost = exc
        super().connection_lost(exc)

    def end(self, reason: Exception) -> None:
        super().end(reason)
        self.changed.set()

    def reading(self) -> ControllerCalibration | None:
        """What it has read, once KINEMATICS_INFO is among it."""
        if self.kinematics is None:
            return None
        return ControllerCalibration(self.kinematics, self.version, self.configuration)


async def read_calibration(
    address: str, port: int = DEFAULT_PORT, timeout: float = DEFAULT_TIMEOUT_S
) -> ControllerCalibration:
    """Connect to the primary interface and read the calibration; UrDaemonError if not within ``timeout``."""
    if not (math.isfinite(timeout) and timeout > 0):
        raise ValueError(f"timeout must be a number of seconds > 0, got {timeout}")
    loop = asyncio.get_running_loop()
    deadline = loop.time() + timeout
    where = f"{address}:{port}"
    link = await connect(_CalibrationReader, address, port, timeout=timeout, name="calibration")
    try:
        return await _read(link, where, deadline, timeout)
    finally:
        link.close()
        with contextlib.suppress(TimeoutError):
            await asyncio.wait_for(asyncio.shield(link.closed), 1.0)


async def _read(
    link: _CalibrationReader, where: str, deadline: float, timeout: float
) -> ControllerCalibration:
    loop = asyncio.get_running_loop()
    graced = False
    while True:
        reading = link.reading()
        if reading is not None and (reading.configuration is not None or link.closed.done()):
            return reading  # once the connection ended, what matters has arrived: do without the rest
        if link.closed.done():
            raise _ended(link, where)
        remaining = deadline - loop.time()
        if remaining <= 0:
            if reading is not None:  # the grace for CONFIGURATION_DATA ran out: do without it
                return reading
            raise UrTimeoutError(
                f"{where}: no KINEMATICS_INFO within {timeout:g} s; is this a UR controller?"
            )
        link.changed.clear()
        with contextlib.suppress(TimeoutError):
            await asyncio.wait_for(link.changed.wait(), remaining)
        if link.kinematics is not None and not graced:
            graced = True
            deadline = min(deadline, loop.time() + CONFIGURATION_GRACE_S)


def _ended(link: _CalibrationReader, where: str) -> UrDaemonError:
    """Why the connection ended before KINEMATICS_INFO arrived."""
    reason = link.closed.result()
    if isinstance(reason, ProtocolError):
        return UrDaemonError(f"{where}: bad data on the primary interface: {reason}")
    if link.lost is not None:
        err = link.lost
        return UrDaemonError(f"{where}: connection lost: {getattr(err, 'strerror', None) or err}")
    return UrDaemonError(f"{where}: the controller closed the connection before sending KINEMATICS_INFO")
