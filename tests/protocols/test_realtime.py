"""The real-time interface codec (port 30003): the layout per controller version, both directions."""

from __future__ import annotations

import struct

import pytest
from hypothesis import given
from hypothesis import strategies as st

from urdaemon.errors import LocalProtocolError, RemoteProtocolError
from urdaemon.protocols import primary as prim
from urdaemon.protocols import realtime as rt
from urdaemon.protocols._buffer import Side


@pytest.mark.parametrize(
    ("version", "size"),
    [((3, 4), 1060), ((3, 15), 1108), ((5, 4), 1116), ((5, 9), 1116), ((5, 10), 1196), ((5, 15), 1196)],
)
def test_message_size_follows_the_controller_version(version: tuple[int, int], size: int) -> None:
    assert rt.message_size(version) == size
    robot = rt.RealtimeConnection(Side.ROBOT, version)
    robot.send(rt.RealtimeState())
    data = robot.data_to_send()
    assert len(data) == size
    assert struct.unpack_from(">i", data)[0] == size


def test_fields_sit_at_the_offsets_of_the_client_interface_table() -> None:
    """Offsets as UR's real-time table gives them (and public clients of it read them)."""
    state = rt.RealtimeState(
        time=12.5,
        q_actual=(1.0, 2.0, 3.0, 4.0, 5.0, 6.0),
        robot_mode=7.0,
        safety_mode=1.0,
        speed_scaling=0.5,
        program_state=2.0,
        elbow_velocity=(0.1, 0.2, 0.3),
        safety_status=1.0,
        payload_mass=2.5,
    )
    robot = rt.RealtimeConnection(Side.ROBOT, (5, 15))
    robot.send(state)
    data = robot.data_to_send()

    def at(offset: int, n: int = 1) -> tuple[float, ...]:
        return struct.unpack_from(f">{n}d", data, offset)

    assert at(4) == (12.5,)
    assert at(252, 6) == (1.0, 2.0, 3.0, 4.0, 5.0, 6.0)
    assert at(756) == (7.0,)
    assert at(812) == (1.0,)
    assert at(940) == (0.5,)
    assert at(1052) == (2.0,)
    assert at(1084, 3) == (0.1, 0.2, 0.3)
    assert at(1108) == (1.0,)
    assert at(1116) == (2.5,)


@given(
    version=st.sampled_from([(3, 4), (3, 15), (5, 4), (5, 15)]),
    q=st.tuples(*[st.floats(allow_nan=False)] * 6),
    chunk=st.integers(1, 3000),
)
def test_a_stream_decodes_in_any_chunking_to_what_was_sent(
    version: tuple[int, int], q: tuple[float, ...], chunk: int
) -> None:
    robot = rt.RealtimeConnection(Side.ROBOT, version)
    sent = [rt.RealtimeState(time=float(i), q_actual=q, digital_outputs=float(i)) for i in range(3)]
    for state in sent:
        robot.send(state)
    data = robot.data_to_send()
    client = rt.RealtimeConnection(Side.DAEMON)
    events = []
    for start in range(0, len(data), chunk):
        events += client.receive_data(data[start : start + chunk])
    assert events == sent


def test_a_client_reads_only_the_fields_an_older_controller_sends() -> None:
    robot = rt.RealtimeConnection(Side.ROBOT, (3, 4))
    robot.send(rt.RealtimeState(time=1.0, elbow_position=(1.0, 1.0, 1.0), program_state=1.0))
    (state,) = rt.RealtimeConnection(Side.DAEMON).receive_data(robot.data_to_send())
    assert isinstance(state, rt.RealtimeState)
    assert state.program_state == 1.0
    assert state.elbow_position == (0.0, 0.0, 0.0)  # not in a 3.4 message


def test_a_bad_message_size_is_a_remote_protocol_error() -> None:
    client = rt.RealtimeConnection(Side.DAEMON)
    with pytest.raises(RemoteProtocolError):
        client.receive_data(struct.pack(">i", 1_000_000))
    with pytest.raises(RemoteProtocolError):
        client.receive_data(b"\x00")  # failed for good


def test_scripts_arrive_on_the_robot_side_as_on_the_primary_interface() -> None:
    daemon = rt.RealtimeConnection(Side.DAEMON)
    daemon.send(prim.Script("def p():\n  textmsg(1)\nend"))
    daemon.send(prim.Script("set_digital_out(2, True)"))
    robot = rt.RealtimeConnection(Side.ROBOT, (5, 15))
    events = robot.receive_data(daemon.data_to_send())
    assert events == [
        prim.ProgramReceived("def", "p", "def p():\n  textmsg(1)\nend\n"),
        prim.CommandReceived("set_digital_out(2, True)"),
    ]


def test_each_side_sends_only_its_own_messages() -> None:
    with pytest.raises(LocalProtocolError):
        rt.RealtimeConnection(Side.ROBOT).send(prim.Script("x"))
    with pytest.raises(LocalProtocolError):
        rt.RealtimeConnection(Side.DAEMON).send(rt.RealtimeState())
