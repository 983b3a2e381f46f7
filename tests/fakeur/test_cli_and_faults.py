"""`urdaemon fake-robot` from a cell file and with a calibration; the fault injector's byte mangling."""

from __future__ import annotations

import asyncio
import os
import subprocess
import sys
from pathlib import Path

import pytest
import yaml

from tests.helpers import drain_in_background, fake_address, run_cli, wait_for_line
from urdaemon.description.urmodels import load_ur_model
from urdaemon.fakeur.contact import DEFAULT_WALL_STIFFNESS
from urdaemon.fakeur.faults import FaultInjector
from urdaemon.protocols import dashboard as dash
from urdaemon.protocols import primary as prim
from urdaemon.protocols._buffer import Side
from urdaemon.protocols.kinematics_hash import kinematics_hash

pytestmark = pytest.mark.timeout(90)


async def _first(conn: object, address: str, port: int, kind: type) -> object:
    reader, writer = await asyncio.open_connection(address, port)
    try:
        for _ in range(50):
            data = await asyncio.wait_for(reader.read(65536), 5.0)
            assert data
            for event in conn.receive_data(data):  # type: ignore[attr-defined]
                if isinstance(event, kind):
                    return event
        raise AssertionError(f"no {kind.__name__}")
    finally:
        writer.close()


async def _serve(args: list[str], expect: str) -> subprocess.Popen[str]:
    proc = subprocess.Popen(
        [sys.executable, "-m", "urdaemon", "fake-robot", *args],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
        env={**os.environ, "PYTHONUNBUFFERED": "1"},
    )
    await wait_for_line(proc, expect, timeout=30.0)
    drain_in_background(proc, [])
    return proc


async def test_fake_robot_from_a_cell_file_serves_every_ur_robot_at_its_address(tmp_path: Path) -> None:
    alice, bob = fake_address(), fake_address()
    cell = {
        "cell": "fakecell",
        "robots": [
            {"name": "alice", "model": "ur10e", "backend": "ur", "address": alice},
            {"name": "bob", "model": "ur3e", "backend": "ur", "address": bob},
            {"name": "carol", "model": "ur5e", "backend": "mock"},
        ],
    }
    path = tmp_path / "cell.yaml"
    path.write_text(yaml.safe_dump(cell))
    proc = await _serve(["--config", str(path), "--phases", "spread"], "serving 2 fake robot(s)")
    try:
        for address, model in ((alice, "UR10"), (bob, "UR3")):
            # both tick on the process's one shared clock: each streams its own robot state
            state = await _first(prim.PrimaryConnection(Side.DAEMON), address, 30001, prim.RobotState)
            assert isinstance(state, prim.RobotState)
            conn = dash.DashboardConnection(Side.DAEMON)
            reader, writer = await asyncio.open_connection(address, 29999)
            banner = await asyncio.wait_for(reader.readline(), 5.0)
            assert banner.startswith(b"Connected: Universal Robots Dashboard Server")
            conn.receive_data(banner)
            conn.send(dash.GetRobotModel())
            writer.write(conn.data_to_send())
            (reply,) = conn.receive_data(await asyncio.wait_for(reader.readline(), 5.0))
            assert isinstance(reply, dash.RobotModelReply)
            assert reply.model == model
            writer.close()
    finally:
        proc.terminate()
        assert proc.wait(timeout=10) == 0


async def test_fake_robot_with_a_calibration_reports_its_kinematics(tmp_path: Path) -> None:
    model = load_ur_model("ur5e")
    delta = {
        "theta": [0.0, 1e-3, -2e-3, 0.0, 0.0, 0.0],
        "a": [0.0, 2e-4, 0.0, 0.0, 0.0, 0.0],
        "d": [1e-4, 0.0, 0.0, 0.0, 0.0, 0.0],
        "alpha": [0.0] * 6,
    }
    path = tmp_path / "calibration.yaml"
    path.write_text(yaml.safe_dump({"model": "ur5e", "dh_delta": delta}))
    address = fake_address()
    proc = await _serve(
        ["--model", "ur5e", "--address", address, "--calibration", str(path)], "serving 1 fake robot(s)"
    )
    try:
        state = await _first(prim.PrimaryConnection(Side.DAEMON), address, 30001, prim.RobotState)
        assert isinstance(state, prim.RobotState)
        kin = state.get(prim.KinematicsInfo)
        assert kin is not None
        expected = kinematics_hash(
            [t + x for t, x in zip(model.dh.theta, delta["theta"], strict=True)],
            [a + x for a, x in zip(model.dh.a, delta["a"], strict=True)],
            [d + x for d, x in zip(model.dh.d, delta["d"], strict=True)],
            [a + x for a, x in zip(model.dh.alpha, delta["alpha"], strict=True)],
        )
        assert kin.kinematics_hash() == expected != model.kinematics_hash
    finally:
        proc.terminate()
        proc.wait(timeout=10)


def test_fake_robot_refuses_bad_arguments() -> None:
    run = run_cli(
        "fake-robot", "--model", "ur10e", "--address", fake_address(), "--controller-version", "five"
    )
    assert run.code == 2
    assert "--controller-version 'five'" in run.stderr


def test_split_pieces_join_to_the_data_and_garble_flips_exactly_one_byte() -> None:
    faults = FaultInjector(split={"rtde"}, garble={"primary": 1}, delay_s={"dashboard": 0.05}, seed=3)
    data = bytes(range(200))
    split = faults.mangle("rtde", data)
    assert len(split.pieces) > 1
    assert b"".join(split.pieces) == data
    garbled = faults.mangle("primary", data).pieces[0]
    assert sum(a != b for a, b in zip(garbled, data, strict=True)) == 1
    assert faults.mangle("primary", data).pieces == (data,), "only the next write was garbled"
    assert faults.mangle("dashboard", data).delay_s == 0.05
    assert faults.mangle("secondary", data) == faults.mangle("secondary", data)
    everything = FaultInjector(refused={"*"})
    assert everything.is_refused("rtde")
    assert everything.is_refused("dashboard")


def test_fake_robot_walls_from_the_command_line_reach_every_arm() -> None:
    """``--wall X,Y,Z,NX,NY,NZ[,K]`` puts a wall around the fake arm (fakeur/contact.py); before the
    option (f5f0e26) a user had nothing the fake arm could touch. A bad wall is refused with the reason."""
    import argparse

    from urdaemon.cli.parser import build_parser
    from urdaemon.errors import ConfigError
    from urdaemon.fakeur.command import build_fakes, parse_wall

    command = ["fake-robot", "--model", "ur10e", "--wall", "0,0,0.1,0,0,1", "--wall", "0.5,0,0,-2,0,0,5000"]
    walls = build_parser().parse_args(command).wall
    args = argparse.Namespace(
        config=None,
        model="ur10e",
        address=fake_address(),
        controller_version="5.15.0",
        calibration=None,
        powered=True,
        urcap=None,
        refuse=[],
        split=[],
        delay=0.0,
        programs=None,
        wall=walls,
    )
    (fake,) = build_fakes(args)
    surroundings = fake.arm.surroundings
    assert surroundings is not None
    assert [(w.point, w.normal, w.stiffness) for w in surroundings.walls] == [
        ((0.0, 0.0, 0.1), (0.0, 0.0, 1.0), DEFAULT_WALL_STIFFNESS),
        ((0.5, 0.0, 0.0), (-1.0, 0.0, 0.0), 5000.0),
    ]
    for bad, reason in (("0,0,1", "6 or 7"), ("0,0,0,0,0,0", "normal"), ("a,0,0,0,0,1", "could not convert")):
        with pytest.raises(ConfigError, match=reason):
            parse_wall(bad)


def test_the_wall_option_help_names_the_fakes_default_stiffness() -> None:
    """``--wall``'s help states the default stiffness as a literal (the CLI does not import the fake);
    this holds it to ``DEFAULT_WALL_STIFFNESS`` so the two cannot drift apart."""
    run = run_cli("fake-robot", "--help")
    assert run.code == 0
    text = " ".join(run.stdout.split())
    assert "--wall X,Y,Z,NX,NY,NZ[,K]" in text
    assert f"its stiffness K in N/m (default {DEFAULT_WALL_STIFFNESS:g})" in text


@pytest.mark.parametrize(
    ("ur_options", "expected"),
    [
        ("", "robot"),  # the daemon listens on the interface that reaches the robot: its own loopback
        ("listen_address: 127.0.0.1", "127.0.0.1"),
        ("listen_address: 0.0.0.0", "127.0.0.1"),
        ("{reverse_ip}", "reverse"),
    ],
)
def test_a_urcap_fake_from_a_cell_file_fetches_where_the_daemon_listens(
    tmp_path: Path, ur_options: str, expected: str
) -> None:
    """A fake built from a cell file with ``headless: false`` plays the URCap, whose Host IP must be
    where the daemon's callback servers listen. Since they listen on the interface that reaches the
    robot (backends/ur/route.py), not 0.0.0.0, the fixed 127.0.0.1 the fake used before fetched from
    an address nothing listened on."""
    import argparse

    from urdaemon.fakeur.command import build_fakes

    robot, reverse = fake_address(), fake_address()
    options = ur_options.replace("{reverse_ip}", f"reverse_ip: {reverse}")
    ur = f"\n    ur: {{{options}}}" if options else ""
    config = tmp_path / "cell.yaml"
    config.write_text(
        "cell: c\nrobots:\n  - name: alice\n    model: ur5e\n    backend: ur\n"
        f"    address: {robot}\n    headless: false{ur}\n"
    )
    args = argparse.Namespace(
        config=str(config),
        controller_version="5.15.0",
        powered=True,
        refuse=[],
        split=[],
        delay=0.0,
        programs=None,
        wall=[],
    )
    (fake,) = build_fakes(args)
    assert fake.urcap is not None
    host = {"robot": robot, "reverse": reverse}.get(expected, expected)
    assert fake.urcap[0] == host
