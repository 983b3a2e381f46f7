"""The fake's v1-only RTDE option and its dashboard refusals, as a client sees them on the wire."""

from __future__ import annotations

import asyncio
import itertools
from pathlib import Path
from typing import Any

import pytest

from tests.helpers import fake_address
from urdaemon.cli.parser import build_parser
from urdaemon.errors import ConfigError
from urdaemon.fakeur.command import build_fakes
from urdaemon.fakeur.controller import FakeController
from urdaemon.protocols import dashboard as dash
from urdaemon.protocols import rtde
from urdaemon.protocols._buffer import Side

pytestmark = pytest.mark.timeout(30)


async def _exchange(
    reader: asyncio.StreamReader, writer: asyncio.StreamWriter, conn: rtde.RtdeConnection, message: Any
) -> object:
    conn.send(message)
    writer.write(conn.data_to_send())
    async with asyncio.timeout(10.0):
        while True:
            events = conn.receive_data(await reader.read(65536))
            if events:
                return events[0]


async def test_a_v1_only_fake_refuses_v2_and_streams_v1_outputs_at_its_rate() -> None:
    """With ``rtde_versions=(1,)`` the fake refuses REQUEST_PROTOCOL_VERSION(2), accepts 1, answers a
    v1 SETUP_OUTPUTS (no frequency) without a recipe id and streams at the controller rate."""
    async with FakeController("ur10e", address=fake_address(), rtde_versions=(1,)) as fake:
        reader, writer = await asyncio.open_connection(fake.address, fake.ports.rtde)
        conn = rtde.RtdeConnection(Side.DAEMON)
        try:
            refused = await _exchange(reader, writer, conn, rtde.RequestProtocolVersion(2))
            assert isinstance(refused, rtde.ProtocolVersionReply)
            assert not refused.accepted
            accepted = await _exchange(reader, writer, conn, rtde.RequestProtocolVersion(1))
            assert isinstance(accepted, rtde.ProtocolVersionReply)
            assert accepted.accepted
            assert conn.protocol_version == 1
            configured = await _exchange(reader, writer, conn, rtde.SetupOutputs(None, ("timestamp",)))
            assert isinstance(configured, rtde.OutputsConfigured)
            assert configured.recipe_id is None
            assert configured.types == ("DOUBLE",)
            started = await _exchange(reader, writer, conn, rtde.Start())
            assert isinstance(started, rtde.StartReply)
            stamps: list[float] = []
            async with asyncio.timeout(10.0):
                while len(stamps) < 10:
                    for event in conn.receive_data(await reader.read(65536)):
                        if isinstance(event, rtde.DataPackage):
                            stamp = event.values[0]
                            assert isinstance(stamp, float)
                            stamps.append(stamp)
            steps = {round(b - a, 6) for a, b in itertools.pairwise(stamps)}
            assert steps == {0.002}, "every controller cycle: v1 streams at the controller's rate"
        finally:
            writer.close()


async def test_the_fake_dashboard_refuses_a_line_it_does_not_know_as_a_controller_does() -> None:
    """An unknown line is answered ``could not understand: '<line>'``; the connection stays usable."""
    async with FakeController("ur10e", address=fake_address()) as fake:
        reader, writer = await asyncio.open_connection(fake.address, fake.ports.dashboard)
        conn = dash.DashboardConnection(Side.DAEMON)
        try:
            conn.receive_data(await asyncio.wait_for(reader.readline(), 10.0))
            conn.send(dash.Raw("make coffee"))
            conn.send(dash.GetRobotMode())
            writer.write(conn.data_to_send())
            replies: list[object] = []
            async with asyncio.timeout(10.0):
                while len(replies) < 2:
                    replies.extend(conn.receive_data(await reader.readline()))
            assert replies[0] == dash.RawReply(dash.Raw("make coffee"), "could not understand: 'make coffee'")
            assert isinstance(replies[1], dash.RobotModeReply)
        finally:
            writer.close()


def test_fake_robot_programs_option_gives_every_fake_a_programs_directory(tmp_path: Path) -> None:
    """``urdaemon fake-robot --programs DIR`` reaches every fake; a programs path that is not a directory
    is refused before anything listens."""
    parser = build_parser()
    base = ["fake-robot", "--model", "ur10e", "--address", fake_address()]
    [fake] = build_fakes(parser.parse_args([*base, "--programs", str(tmp_path)]))
    assert fake.programs_dir == tmp_path
    assert fake.default_program == f"{tmp_path}/external_control.urp"
    [fake] = build_fakes(parser.parse_args(base))
    assert fake.programs_dir is None
    with pytest.raises(ConfigError, match="not a directory"):
        build_fakes(parser.parse_args([*base, "--programs", str(tmp_path / "missing")]))
