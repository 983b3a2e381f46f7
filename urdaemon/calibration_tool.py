"""``urdaemon calibration``: read a UR controller's kinematics calibration and write the calibration file.

The controller's primary interface (port 30001) sends a VERSION message right after connecting, then
ROBOT_STATE packages whose KINEMATICS_INFO sub-package carries the calibrated DH parameters and whose
CONFIGURATION_DATA says the robot type. :func:`read_calibration` collects those three (sans-IO codec
over an asyncio stream); :func:`calibration_yaml` turns them into the file that a robot's
``calibration`` key in the cell file accepts (see ``urdaemon.description.calibration``).
"""

from __future__ import annotations

import asyncio
import contextlib
import math
from dataclasses import dataclass
from typing import Any

import yaml

from urdaemon.errors import ProtocolError, UrDaemonError, UrTimeoutError
from urdaemon.protocols import primary as prim
from urdaemon.protocols._buffer import Side

__all__ = [
    "ControllerCalibration",
    "calibration_document",
    "calibration_yaml",
    "model_for",
    "read_calibration",
]

DEFAULT_PORT = 30001
DEFAULT_TIMEOUT_S = 10.0
CONFIGURATION_GRACE_S = 1.0
"""How long to keep reading for CONFIGURATION_DATA once KINEMATICS_INFO has arrived without it."""
_READ_CHUNK = 65536

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


async def read_calibration(
    address: str, port: int = DEFAULT_PORT, timeout: float = DEFAULT_TIMEOUT_S
) -> ControllerCalibration:
    """Connect to the primary interface and read the calibration; UrDaemonError if not within ``timeout``."""
    if not (math.isfinite(timeout) and timeout > 0):
        raise ValueError(f"timeout must be a number of seconds > 0, got {timeout}")
    loop = asyncio.get_running_loop()
    deadline = loop.time() + timeout
    where = f"{address}:{port}"
    try:
        reader, writer = await asyncio.wait_for(asyncio.open_connection(address, port), timeout)
    except TimeoutError:
        raise UrTimeoutError(f"cannot connect to {where}: no answer within {timeout:g} s") from None
    except (OSError, UnicodeError) as err:  # UnicodeError: a host name IDNA cannot encode
        raise UrDaemonError(f"cannot connect to {where}: {getattr(err, 'strerror', None) or err}") from err
    try:
        return await _read(reader, where, deadline, timeout)
    finally:
        writer.close()
        with contextlib.suppress(OSError, TimeoutError):
            await asyncio.wait_for(writer.wait_closed(), 1.0)


async def _read(
    reader: asyncio.StreamReader, where: str, deadline: float, timeout: float
) -> ControllerCalibration:
    loop = asyncio.get_running_loop()
    conn = prim.PrimaryConnection(Side.DAEMON)
    version: prim.VersionMessage | None = None
    configuration: prim.ConfigurationData | None = None
    kinematics: prim.KinematicsInfo | None = None
    while True:
        if kinematics is not None and configuration is not None:
            return ControllerCalibration(kinematics, version, configuration)
        remaining = deadline - loop.time()
        if remaining <= 0:
            if kinematics is not None:  # the grace for CONFIGURATION_DATA ran out: do without it
                return ControllerCalibration(kinematics, version, configuration)
            raise UrTimeoutError(
                f"{where}: no KINEMATICS_INFO within {timeout:g} s; is this a UR controller?"
            )
        try:
            data = await asyncio.wait_for(reader.read(_READ_CHUNK), remaining)
        except TimeoutError:
            continue  # the deadline check above decides
        except OSError as err:
            raise UrDaemonError(f"{where}: connection lost: {err.strerror or err}") from err
        try:
            events = conn.receive_data(data) if data else conn.receive_eof()
        except ProtocolError as err:
            if kinematics is not None:  # what matters has arrived; the rest is not needed
                return ControllerCalibration(kinematics, version, configuration)
            raise UrDaemonError(f"{where}: bad data on the primary interface: {err}") from err
        for event in events:
            if isinstance(event, prim.VersionMessage):
                version = event
            elif isinstance(event, prim.RobotState):
                configuration = event.get(prim.ConfigurationData) or configuration
                found = event.get(prim.KinematicsInfo)
                if found is not None and kinematics is None:
                    kinematics = found
                    deadline = min(deadline, loop.time() + CONFIGURATION_GRACE_S)
        if not data:
            if kinematics is not None:
                return ControllerCalibration(kinematics, version, configuration)
            raise UrDaemonError(
                f"{where}: the controller closed the connection before sending KINEMATICS_INFO"
            )
