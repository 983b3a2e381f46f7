"""``urdaemon foxglove`` judged by an independent client of the protocol: tests/foxglove/client.mjs
(@foxglove/ws-protocol over ``ws``, CDR read by @foxglove/rosmsg2-serialization) connects to the
bridge of a mock cell, checks the channels' schema names, and follows alice's joint states while
this test sends her a move: they must come closer to the target, never go back, and end within
1 mrad of it; tf must come as parent → child transforms and the URDF both as the latched
``/<cell>/robot_description`` message and as the ``/robot_description`` parameter."""

from __future__ import annotations

import asyncio
import contextlib
import json

import pytest

from tests.foxglove.node import CLIENT, node_or_skip
from tests.integration.conftest import TWO_MOCKS, running_daemon
from urdaemon.foxglove_bridge.bridge import running_bridge

TARGET = [0.3, -1.2, 1.2, -1.4, -1.4, 0.2]
TOLERANCE = 1e-3
NODE_TIMEOUT_S = 90.0


async def _line(stream: asyncio.StreamReader, timeout: float) -> str:
    return (await asyncio.wait_for(stream.readline(), timeout)).decode().strip()


@pytest.mark.timeout(180)
async def test_a_foxglove_client_sees_the_move_tf_and_urdf() -> None:
    node = node_or_skip()
    async with running_daemon(TWO_MOCKS) as (_, client), running_bridge(client, port=0) as bridge:
        assert bridge.port != 0
        assert bridge.url.endswith(f":{bridge.port}")
        assert bridge.following == set()  # nobody watches yet: the daemon computes nothing for it
        spec = {
            "url": bridge.url,
            "cell": bridge.cell,
            "robot": "alice",
            "target": TARGET,
            "tolerance": TOLERANCE,
            "timeoutMs": int(NODE_TIMEOUT_S * 1000),
        }
        proc = await asyncio.create_subprocess_exec(
            node, str(CLIENT), json.dumps(spec), stdout=asyncio.subprocess.PIPE, cwd=CLIENT.parent
        )
        assert proc.stdout is not None
        try:
            ready = await _line(proc.stdout, NODE_TIMEOUT_S)
            assert ready.startswith("ready "), ready
            assert "/testcell/alice/joint_states" in bridge.following
            robot = await client.robot("alice")
            goal = await robot.move(TARGET)
            verdict = await _line(proc.stdout, NODE_TIMEOUT_S)
            code = await asyncio.wait_for(proc.wait(), 30)
            result = await goal.result(60.0)
        finally:
            with contextlib.suppress(ProcessLookupError):
                proc.kill()
        assert verdict.startswith("ok "), verdict
        assert code == 0
        assert result["status"] == "succeeded", result
        seen = json.loads(verdict[3:])
        assert seen["advertised"]["/testcell/bob/joint_states"] == "sensor_msgs/msg/JointState"
        assert seen["advertised"]["/testcell/alice/tcp_pose"] == "geometry_msgs/msg/PoseStamped"
        assert "alice_base_link" in seen["parents"]
        assert "world" in seen["parents"]
        assert bridge.logged > seen["samples"]
        assert bridge.failed == 0
        for _ in range(100):  # the client has gone: every Zenoh subscriber goes with it
            if not bridge.following:
                break
            await asyncio.sleep(0.05)
        assert bridge.following == set()
        assert bridge.handoff.dropped == 0
