"""`urdaemon calibration`: the file it writes from a (fake) controller, and how it fails."""

from __future__ import annotations

import asyncio
import math
import time
from pathlib import Path

import numpy as np
import pytest
import yaml

from tests.description.support import quat_matrix
from tests.helpers import fake_address, run_cli_in_thread
from urdaemon.calibration_tool import (
    ControllerCalibration,
    calibration_document,
    calibration_yaml,
    model_for,
    read_calibration,
)
from urdaemon.cell import parse_cell
from urdaemon.description import DhKinematics, DhParameters, build_cell_urdf, load_calibration, load_ur_model
from urdaemon.description.urdf import load_urdf
from urdaemon.errors import UrDaemonError, UrTimeoutError
from urdaemon.fakeur.controller import FakeController
from urdaemon.model import UR_JOINTS
from urdaemon.protocols import primary as prim
from urdaemon.protocols._buffer import Side

pytestmark = pytest.mark.timeout(90)

UR10E = load_ur_model("ur10e")


def _calibrated(nominal: DhParameters) -> DhParameters:
    """Nominal + small fixed deltas, with huge opposite d2/d3 that d4 compensates (as real arms have)."""
    d2, d3 = 439.2 + 0.123456789012, -446.3 - 0.0987654321098
    delta = DhParameters(
        theta=(2.4e-3, -7.1234567e-3, 5.3e-3, -1.1e-3, 8.9e-4, -3.3e-4),
        a=(2.12e-4, -3.31e-4, 4.87e-4, -1.9e-4, 6.4e-4, 0.0),
        d=(-1.6e-4, d2, d3, -(d2 + d3) + 3.1e-4, 7.2e-5, -8.3e-5),
        # tiny: with a 440 m lever, 1e-5 rad already moves the arm by 4 mm
        alpha=(-6.5e-6, 1.39e-6, -2.94e-6, 1.1e-6, 4.1e-6, 0.0),
    )
    return nominal.plus(delta)


FAKE_DH = _calibrated(UR10E.dh)


async def _run_cli(*args: str, timeout: float = 60.0) -> tuple[int, str]:
    """Run ``urdaemon calibration ARGS`` (in-process, in a thread of its own); its exit code and stderr."""
    run = await run_cli_in_thread("calibration", *args, timeout=timeout)
    return run.code, run.stderr


# --- the document -----------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("robot_type", "major", "model"),
    [
        (1, 5, "ur5e"),
        (1, 3, "ur5"),
        (2, 5, "ur10e"),
        (2, 3, "ur10"),
        (3, 10, "ur3e"),
        (3, 3, "ur3"),
        (4, 5, "ur16e"),
        (7, 5, "ur20"),
        (8, 5, "ur30"),
        (8, None, "ur30"),
        (1, None, None),
        (5, 5, None),
        (None, 5, None),
    ],
)
def test_model_is_given_only_when_unambiguous(
    robot_type: int | None, major: int | None, model: str | None
) -> None:
    found, why = model_for(robot_type, major)
    assert found == model
    assert why


def _version(major: int) -> prim.VersionMessage:
    return prim.VersionMessage("URControl", major, 15, 0, 0, "01-01-2026, 00:00:00")


def _kinematics(dh: DhParameters) -> prim.KinematicsInfo:
    return prim.KinematicsInfo(dh_theta=dh.theta, dh_a=dh.a, dh_d=dh.d, dh_alpha=dh.alpha)


def test_document_has_model_hash_and_absolute_dh() -> None:
    kin = _kinematics(FAKE_DH)
    document = calibration_document(kin, _version(5), prim.ConfigurationData(robot_type=2))
    assert list(document) == ["model", "hash", "dh"]
    assert document["model"] == "ur10e"
    assert document["hash"] == kin.kinematics_hash()
    assert document["dh"] == {k: list(getattr(FAKE_DH, k)) for k in ("theta", "a", "d", "alpha")}


def test_without_version_the_model_is_left_out_and_the_comment_says_why(tmp_path: Path) -> None:
    reading = ControllerCalibration(_kinematics(FAKE_DH), None, prim.ConfigurationData(robot_type=2))
    assert "model" not in calibration_document(reading.kinematics, None, reading.configuration)
    text = calibration_yaml(reading, "10.0.0.2:30001")
    assert "# model: left out" in text
    assert "no VERSION message" in text
    path = tmp_path / "cal.yaml"
    path.write_text(text)
    assert load_calibration(path, UR10E).dh == FAKE_DH


def test_header_comment_cannot_be_broken_by_controller_text() -> None:
    version = prim.VersionMessage("URControl\nmodel: ur3", 5, 1, 2, 3, "")
    reading = ControllerCalibration(_kinematics(FAKE_DH), version, prim.ConfigurationData(robot_type=2))
    data = yaml.safe_load(calibration_yaml(reading, "host\nhash: x:1"))
    assert data["model"] == "ur10e"
    assert data["hash"].startswith("calib_")


# --- against the fake controller ----------------------------------------------------------------------


async def test_calibration_of_a_fake_ur10e_builds_a_urdf_with_its_kinematics(tmp_path: Path) -> None:
    output = tmp_path / "alice_calibration.yaml"
    address = fake_address()
    async with FakeController("ur10e", address=address, dh=FAKE_DH):
        code, stderr = await _run_cli("--address", address, "--output", str(output), "--timeout", "20")
    assert code == 0, stderr
    text = output.read_text()
    assert text.startswith("#")
    assert f"{address}:30001" in text
    assert "URControl 5.15.0" in text
    calibration = load_calibration(output, UR10E)
    assert calibration.dh == FAKE_DH  # every float to the last bit
    assert calibration.hash == _kinematics(FAKE_DH).kinematics_hash()
    assert calibration.hash != UR10E.kinematics_hash
    assert yaml.safe_load(text)["model"] == "ur10e"

    cell_text = (
        "cell: calcell\n"
        "robots:\n"
        "  - name: alice\n"
        "    model: ur10e\n"
        "    backend: mock\n"
        f"    calibration: {output.name}\n"
    )
    urdf = load_urdf(build_cell_urdf(parse_cell(cell_text, base_dir=tmp_path)))
    kinematics = DhKinematics(FAKE_DH)
    rng = np.random.default_rng(7)
    names = [f"alice_{joint}" for joint in UR_JOINTS]
    for _ in range(20):
        q = rng.uniform(-2 * math.pi, 2 * math.pi, 6).tolist()
        urdf.update_cfg(dict(zip(names, q, strict=True)))
        actual = urdf.get_transform("alice_tool0", "alice_base")
        x, y, z, qx, qy, qz, qw = kinematics.tool_pose(q)
        np.testing.assert_allclose(actual[:3, 3], [x, y, z], rtol=0, atol=1e-9)
        np.testing.assert_allclose(actual[:3, :3], quat_matrix(qx, qy, qz, qw), rtol=0, atol=1e-9)


async def test_read_calibration_reports_version_and_configuration() -> None:
    address = fake_address()
    async with FakeController("ur10e", address=address, controller_version=(5, 21, 3, 7), dh=FAKE_DH):
        reading = await read_calibration(address, 30001, 10.0)
    assert reading.version is not None
    assert (reading.version.major_version, reading.version.minor_version) == (5, 21)
    assert reading.configuration is not None
    assert reading.configuration.robot_type == 2
    assert reading.kinematics.dh_d == FAKE_DH.d


async def test_no_robot_at_the_address_exits_1(tmp_path: Path) -> None:
    address = fake_address()  # nothing listens there
    output = tmp_path / "cal.yaml"
    code, stderr = await _run_cli("--address", address, "--output", str(output), "--timeout", "3")
    assert code == 1
    assert f"cannot connect to {address}:30001" in stderr
    assert not output.exists()


async def test_a_silent_server_times_out_with_exit_1(tmp_path: Path) -> None:
    """A server that sends only VERSION and then nothing: exit 1 after --timeout, no file written."""
    connected = asyncio.Event()

    async def serve(reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        conn = prim.PrimaryConnection(Side.ROBOT)
        conn.send(_version(5))
        writer.write(conn.data_to_send())
        connected.set()
        await reader.read()  # until the client goes
        writer.close()

    address = fake_address()
    server = await asyncio.start_server(serve, address, 0)
    port = server.sockets[0].getsockname()[1]
    output = tmp_path / "cal.yaml"
    async with server:
        start = time.monotonic()
        code, stderr = await _run_cli(
            "--address", address, "--port", str(port), "--output", str(output), "--timeout", "1.5"
        )
        elapsed = time.monotonic() - start
    assert connected.is_set()
    assert code == 1, stderr
    assert "no KINEMATICS_INFO within 1.5 s" in stderr
    assert elapsed >= 1.5  # a lower bound: a busy machine only makes it longer
    assert not output.exists()


async def test_read_calibration_raises_on_a_server_that_closes() -> None:
    async def serve(reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        writer.close()

    address = fake_address()
    server = await asyncio.start_server(serve, address, 0)
    async with server:
        port = server.sockets[0].getsockname()[1]
        with pytest.raises(UrDaemonError, match="closed the connection before sending KINEMATICS_INFO"):
            await read_calibration(address, port, 5.0)


async def test_read_calibration_times_out_on_a_server_that_never_writes() -> None:
    async def serve(reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        await reader.read()
        writer.close()

    address = fake_address()
    server = await asyncio.start_server(serve, address, 0)
    async with server:
        port = server.sockets[0].getsockname()[1]
        with pytest.raises(UrTimeoutError, match=r"no KINEMATICS_INFO within 0\.3 s"):
            await read_calibration(address, port, 0.3)


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--output", "{tmp}/missing/cal.yaml"], "does not exist"),
        (["--output", "{tmp}"], "is a directory"),
        (["--output", "{tmp}/cal.yaml", "--timeout", "0"], "--timeout"),
        (["--output", "{tmp}/cal.yaml", "--timeout", "nan"], "--timeout"),
        (["--output", "{tmp}/cal.yaml", "--port", "70000"], "--port"),
        (["--output", "{tmp}/cal.yaml", "--port", "x"], "--port"),
    ],
)
async def test_bad_arguments_exit_2(tmp_path: Path, args: list[str], message: str) -> None:
    argv = [arg.replace("{tmp}", str(tmp_path)) for arg in args]
    code, stderr = await _run_cli("--address", fake_address(), *argv)
    assert code == 2, stderr
    assert message in stderr


async def test_missing_output_argument_exits_2() -> None:
    code, stderr = await _run_cli("--address", fake_address())
    assert code == 2
    assert "--output" in stderr
