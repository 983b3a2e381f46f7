"""The status names each robot's TCP: its tool link and the TCP offset in that link's frame, sent again
at once when ``set_tcp`` changes it (a viewer draws the TCP from it instead of following ``tcp_pose``).

The cell publishes its status every 100 s only (and once as it starts, within 0.1 s: the test lets 0.2 s
of cycles pass first, counted in joint_states), so a status within the test was sent because something
in it changed: taking the lease sends the first, and one carrying the new offset was sent for it.

Reproduction on the code before this (17fa302): the status had no ``tcp`` (KeyError on the first
message), and a ``set_tcp`` sent no status until the status period ran out.
"""

from __future__ import annotations

from typing import Any

import pytest

from tests.integration.conftest import running_daemon
from urdaemon.client import Subscription

pytestmark = pytest.mark.timeout(120)

CELL = """
cell: tcpd
publish: {status_rate_hz: 0.01}
robots:
  - name: alice
    model: ur5e
    backend: mock
    tcp: [0.0, 0.0, 0.05, 0.0, 0.0, 0.0]
  - name: carol
    model: custom
    backend: mock
    pose: {xyz: [-1.0, 0.0, 0.0]}
    description: {xacro: servo_arm/servo_arm.urdf.xacro, macro: servo_arm, tool_link: wrist_link}
"""
"""alice, a UR robot with the cell file's TCP offset; carol, a custom arm whose tool link is its own."""
WAIT_S = 30.0
MESSAGES = 50
"""At most this many status messages for anything a test waits on."""
SETTLED = 100
"""joint_states messages (0.2 s of alice's 500 Hz cycles at least) before the test starts: by then the
status's timer has sent its first status, the one before its 100 s period."""


async def _status(sub: Subscription, check: Any, what: str) -> dict[str, Any]:
    for _ in range(MESSAGES):
        message: dict[str, Any] = await sub.get_json(WAIT_S)
        if check(message):
            return message
    raise AssertionError(f"{what}: not within {MESSAGES} status messages")


def _leased(message: dict[str, Any]) -> bool:
    return message["lease"] is not None


async def test_the_status_names_the_tcp_and_a_set_tcp_sends_it_at_once() -> None:
    async with running_daemon(CELL) as (daemon, client):
        alice_status = client.subscribe("tcpd/alice/status", 100)
        carol_status = client.subscribe("tcpd/carol/status", 100)
        states = client.subscribe("tcpd/alice/joint_states", SETTLED)
        try:
            for _ in range(SETTLED):
                await states.get(WAIT_S)
        finally:
            client.unsubscribe(states)
        try:
            alice, carol = await client.robot("alice"), await client.robot("carol")
            await alice.ensure_lease()  # the status names the holder: it goes out at once
            await carol.ensure_lease()
            first = await _status(alice_status, _leased, "alice's leased status")
            assert first["tcp"] == {"link": "alice_tool0", "pose": [0.0, 0.0, 0.05, 0.0, 0.0, 0.0]}
            carol_first = await _status(carol_status, _leased, "carol's leased status")
            assert carol_first["tcp"] == {"link": "carol_wrist_link", "pose": [0.0] * 6}
            tcp = [0.01, -0.02, 0.1, 0.1, 0.0, 0.2]
            await alice.set_tcp(tcp)
            changed = await _status(
                alice_status, lambda m: m["tcp"]["pose"] != first["tcp"]["pose"], "new tcp"
            )
            assert changed["tcp"] == {"link": "alice_tool0", "pose": tcp}
            assert daemon.runtimes[0].tcp_poses.child == "alice_tcp"  # tcp_pose follows the same offset
        finally:
            client.unsubscribe(alice_status)
            client.unsubscribe(carol_status)
