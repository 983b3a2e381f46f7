"""End to end: `urdaemon serve` on configs/dual_robot_mock.yaml as a subprocess, driven over Zenoh."""

from __future__ import annotations

import asyncio
import itertools
import json
import math
import os
import signal
import subprocess
import sys
from collections.abc import AsyncIterator
from pathlib import Path
from typing import Any

import pytest

from tests.helpers import drain_in_background, free_tcp_port, wait_for_line
from urdaemon.cell import load_cell
from urdaemon.client import Client, RobotClient, Subscription
from urdaemon.daemon import describe_cell
from urdaemon.errors import GoalRejected
from urdaemon.model import JointLimits

ROOT = Path(__file__).resolve().parents[2]
CONFIG = ROOT / "configs" / "dual_robot_mock.yaml"
HOME = [0.0, -1.5708, 1.5708, -1.5708, -1.5708, 0.0]

pytestmark = pytest.mark.timeout(180)


@pytest.fixture
async def daemon() -> AsyncIterator[str]:
    """A running daemon on a free loopback port; yields its endpoint; stops it with SIGTERM."""
    endpoint = f"tcp/127.0.0.1:{free_tcp_port()}"
    proc = subprocess.Popen(
        [sys.executable, "-m", "urdaemon", "serve", "--config", str(CONFIG), "--listen", endpoint],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
        env={**os.environ, "PYTHONUNBUFFERED": "1"},
    )
    log: list[str] = []
    try:
        log += await wait_for_line(proc, "serving 2 robot(s)", timeout=60.0)
        drain_in_background(proc, log)
        yield endpoint
    finally:
        proc.send_signal(signal.SIGTERM)
        try:
            code = proc.wait(timeout=20)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait(timeout=10)
            pytest.fail("daemon did not stop within 20 s of SIGTERM")
        assert code == 0, f"daemon exited with {code}:\n{''.join(log[-50:])}"
        assert not [line for line in log if "Traceback" in line], "".join(log)


def _limits() -> dict[str, JointLimits]:
    return describe_cell(load_cell(CONFIG)).limits


async def _collect(sub: Subscription, until: asyncio.Event, limit: int = 200_000) -> list[dict[str, Any]]:
    samples: list[dict[str, Any]] = []
    while not until.is_set() and len(samples) < limit:
        try:
            samples.append(await sub.get_json(timeout=0.5))
        except Exception:  # a timeout just re-checks `until`
            continue
    return samples


def _check_stream(samples: list[dict[str, Any]], limits: JointLimits) -> None:
    assert len(samples) > 100, "too few joint states received"
    samples.sort(key=lambda s: s["controller_time"])
    for sample in samples:
        for j, v in enumerate(sample["velocity"]):
            assert abs(v) <= limits.max_velocity[j] * 1.0001, f"{limits.names[j]} velocity {v}"
    for a, b in itertools.pairwise(samples):
        dt = b["controller_time"] - a["controller_time"]
        if dt <= 0:
            continue
        for j in range(limits.dof):
            speed = abs(b["position"][j] - a["position"][j]) / dt
            acc = abs(b["velocity"][j] - a["velocity"][j]) / dt
            assert speed <= limits.max_velocity[j] * 1.01, f"{limits.names[j]} moved at {speed} rad/s"
            assert acc <= limits.max_acceleration[j] * 1.05, f"{limits.names[j]} accelerated at {acc} rad/s²"


async def _final_positions(robot: RobotClient) -> list[float]:
    sub = robot.joint_states(10)
    try:
        sample = await sub.get_json(timeout=5.0)
        return [float(v) for v in sample["position"]]
    finally:
        sub.close()


async def test_dual_robot_cell_end_to_end(daemon: str) -> None:
    limits = _limits()
    async with await Client.connect(daemon) as client:
        alice = await client.robot("alice")
        bob = await client.robot("bob")
        assert alice.keys.cell == "demo_cell"
        alice_states, bob_states = alice.joint_states(200_000), bob.joint_states(200_000)
        # both streams flow before we command anything
        first = await alice_states.get_json(timeout=10.0)
        assert first["names"][0] == "alice_shoulder_pan_joint"
        await bob_states.get_json(timeout=10.0)

        done = asyncio.Event()
        alice_task = asyncio.create_task(_collect(alice_states, done))
        bob_task = asyncio.create_task(_collect(bob_states, done))

        alice_goal_points = [
            {"positions": [0.4, -1.3, 1.2, -1.5, -1.5, 0.3], "time_from_start": 1.0},
            {"positions": [0.8, -1.1, 0.9, -1.3, -1.4, 0.6], "time_from_start": 2.0},
            {"positions": [0.5, -1.4, 1.3, -1.6, -1.5, 0.2], "time_from_start": 3.0},
        ]
        bob_target = [-0.6, -1.2, 1.1, -1.4, -1.6, 0.5]
        alice_goal, bob_goal = await asyncio.gather(
            alice.send_trajectory(alice_goal_points), bob.move(bob_target, duration=2.0)
        )
        assert alice_goal.duration == pytest.approx(3.0, abs=0.01)
        assert bob_goal.duration == pytest.approx(2.0, abs=0.01)

        feedback = [f async for f in alice_goal.feedback()]
        assert feedback, "no feedback while alice's trajectory ran"
        assert all(f["goal_id"] == alice_goal.goal_id for f in feedback)
        assert max(f["progress"] for f in feedback) > 0.5
        results = await asyncio.gather(alice_goal.result(timeout=30), bob_goal.result(timeout=30))
        for result in results:
            assert result["status"] == "succeeded", result
        done.set()
        alice_samples, bob_samples = await asyncio.gather(alice_task, bob_task)
        _check_stream(alice_samples, limits["alice"])
        _check_stream(bob_samples, limits["bob"])

        alice_target: list[float] = alice_goal_points[-1]["positions"]  # type: ignore[assignment]
        for robot, target in ((alice, alice_target), (bob, bob_target)):
            final = await _final_positions(robot)
            assert all(abs(a - b) <= 0.01 for a, b in zip(final, target, strict=True)), (robot.name, final)

        await _bad_goals_are_rejected(alice, limits["alice"])

        # the daemon still serves after all that: a move home succeeds
        home = await alice.move(HOME)
        assert (await home.result(timeout=30))["status"] == "succeeded"


async def _expect_rejected(coro: Any, *words: str) -> None:
    with pytest.raises(GoalRejected) as info:
        await coro
    reason = info.value.reason.lower()
    for word in words:
        assert word.lower() in reason, f"reason {info.value.reason!r} lacks {word!r}"


async def _bad_goals_are_rejected(alice: RobotClient, limits: JointLimits) -> None:
    names = list(limits.names)
    here = await _final_positions(alice)
    point = {"positions": here, "time_from_start": 1.0}
    await _expect_rejected(
        alice.send_trajectory([point], joint_names=[*names[:5], "alice_nonexistent_joint"]),
        "alice_nonexistent_joint",
    )
    await _expect_rejected(
        alice.send_trajectory([{"positions": here[:5], "time_from_start": 1.0}], joint_names=names[:5]),
        names[5],
    )
    nan_point = {"positions": [math.nan, *here[1:]], "time_from_start": 1.0}
    await _expect_rejected(alice.send_trajectory([nan_point]), "finite")
    outside = list(here)
    outside[2] = limits.max_position[2] + 0.5
    await _expect_rejected(alice.send_trajectory([{"positions": outside, "time_from_start": 2.0}]), names[2])
    await _expect_rejected(
        alice.send_trajectory(
            [{"positions": here, "time_from_start": 2.0}, {"positions": here, "time_from_start": 1.0}]
        ),
        "strictly increase",
    )
    # busy: a long goal runs, a second one without preempt is refused, with preempt it takes over
    far = list(here)
    far[0] += 0.5
    long_goal = await alice.move(far, duration=5.0)
    await _expect_rejected(alice.move(here, duration=2.0), "busy")
    new_goal = await alice.move(here, duration=2.0, preempt=True)
    assert (await long_goal.result(timeout=10))["status"] == "preempted"
    assert (await new_goal.result(timeout=30))["status"] == "succeeded"
    # malformed messages get a reason naming the problem, not silence (sent raw, with the lease's
    # token as a client attaches it: without it the lease would refuse them first)
    token = (await alice.ensure_lease()).encode()
    reply = await alice.client.request(alice.keys.goal_trajectory, {"points": "nope"}, attachment=token)
    assert reply["accepted"] is False
    assert "points" in reply["reason"]
    raw = await alice.client.query(alice.keys.goal_move, None, attachment=token)
    assert raw
    assert json.loads(raw[0])["accepted"] is False
