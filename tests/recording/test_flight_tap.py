"""The flight recorder's tap in the daemon's node: without ``record`` the publishers are Zenoh's own;
with it every message published goes to the tap, Zenoh's put only while a subscriber matches, and a
stream's matching flag is forced on only for what the ring keeps whatever it costs (joint_states)."""

from __future__ import annotations

import asyncio
from collections.abc import Iterator

import pytest
import zenoh

from tests.helpers import free_tcp_port
from urdaemon.cell.zenoh_options import ZenohOptions
from urdaemon.publish.node import ZenohNode
from urdaemon.publish.tap import Matching, Tap, TappedPublisher
from urdaemon.recording.channels import RING_STREAMS


@pytest.mark.parametrize(
    ("key", "always"),
    [
        ("c/alice/joint_states", True),
        ("c/alice/tcp_pose", False),
        ("c/tf", False),
        ("c/alice/status", False),
        ("c/joint_states_x", False),
    ],
)
def test_the_ring_wants_joint_states_whoever_subscribes(key: str, always: bool) -> None:
    assert Tap(RING_STREAMS).always(key) is always


def test_the_tap_hands_over_what_it_kept_once() -> None:
    tap = Tap()
    tap.add("c/a/status", b"1")
    tap.add("c/a/io", b"2")
    assert tap.take() == [("c/a/status", b"1"), ("c/a/io", b"2")]
    assert tap.take() == []


class _Publisher:
    def __init__(self) -> None:
        self.sent: list[bytes] = []

    def put(self, payload: bytes) -> None:
        self.sent.append(payload)


def test_a_tapped_publisher_puts_on_zenoh_only_while_a_subscriber_matches() -> None:
    tap, publisher, wanted = Tap(), _Publisher(), Matching(False)
    tapped = TappedPublisher("c/a/status", publisher, wanted, tap.add)
    tapped.put(b"nobody")
    wanted.active = True
    tapped.put(b"somebody")
    assert publisher.sent == [b"somebody"]
    assert tap.take() == [("c/a/status", b"nobody"), ("c/a/status", b"somebody")]


@pytest.fixture
def options() -> ZenohOptions:
    return ZenohOptions(listen=(f"tcp/127.0.0.1:{free_tcp_port()}",))


@pytest.fixture
def node_factory(options: ZenohOptions) -> Iterator[list[ZenohNode]]:
    made: list[ZenohNode] = []
    yield made
    for node in made:
        node.close()


async def test_without_record_the_publishers_are_zenohs_own(
    options: ZenohOptions, node_factory: list[ZenohNode]
) -> None:
    node = ZenohNode(options, asyncio.get_running_loop())
    node_factory.append(node)
    assert node.tap is None
    publisher = node.publisher("c/a/joint_states", realtime=True)
    assert isinstance(publisher, zenoh.Publisher)
    assert node.matching(publisher).active is False, "no tap: only subscribers count"


async def test_with_a_tap_only_the_ring_streams_are_always_wanted(
    options: ZenohOptions, node_factory: list[ZenohNode]
) -> None:
    tap = Tap(RING_STREAMS)
    node = ZenohNode(options, asyncio.get_running_loop(), tap=tap)
    node_factory.append(node)
    joints = node.publisher("c/a/joint_states", realtime=True)
    pose = node.publisher("c/a/tcp_pose", realtime=True)
    assert isinstance(joints, TappedPublisher)
    assert isinstance(pose, TappedPublisher)
    assert node.matching(joints).active is True, "joint_states: computed for the ring"
    pose_wanted = node.matching(pose)
    assert pose_wanted.active is False, "tcp_pose: only for a subscriber, not for the ring"
    assert pose_wanted is pose.wanted
    joints.put(b"j")
    node.put("c/a/goal/g/result", b"r")
    assert tap.take() == [("c/a/joint_states", b"j"), ("c/a/goal/g/result", b"r")]
