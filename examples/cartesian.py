"""Move alice's TCP in Cartesian space: a pose goal, a straight-line path, a twist jog, a TCP offset.

    urdaemon serve --config configs/dual_robot_mock.yaml      # in one terminal
    python examples/cartesian.py                              # in another

Poses are x, y, z (m) and a rotation vector rx, ry, rz (rad) of the TCP in alice's base frame, the
frame of her ``tcp_pose`` (``frame="world"`` takes them in the cell's world frame instead). A pose
goal moves the joints (jerk-limited, the inverse kinematics solution nearest where alice is); a
linear goal moves the TCP on straight lines, checked end to end before it starts; twists are a
stream, like joint velocities: they need the lease held and must keep coming, or the robot stops.
"""

from __future__ import annotations

import argparse
import asyncio
import math

from urdaemon.client import DEFAULT_ENDPOINT, Client, RobotClient
from urdaemon.errors import GoalRejected


def rotation_vector(q: list[float]) -> list[float]:
    """A tcp_pose quaternion (x, y, z, w) as a rotation vector."""
    x, y, z, w = q if q[3] >= 0 else [-v for v in q]
    sine = math.sqrt(x * x + y * y + z * z)
    scale = 2.0 * math.atan2(sine, w) / sine if sine > 1e-12 else 0.0
    return [x * scale, y * scale, z * scale]


async def tcp_pose(alice: RobotClient, child: str | None = None) -> list[float]:
    """alice's TCP pose now: [x, y, z, rx, ry, rz] (of frame ``child`` once tcp_pose names it)."""
    sub = alice.client.subscribe(alice.keys.tcp_pose, 10)
    try:
        for _ in range(1000):
            message = await sub.get_json(timeout=5.0)
            if child is None or message["child"] == child:
                break
    finally:
        alice.client.unsubscribe(sub)
    return [*message["position"], *rotation_vector(message["orientation"])]


def shifted(pose: list[float], dx: float = 0.0, dy: float = 0.0, dz: float = 0.0) -> list[float]:
    return [pose[0] + dx, pose[1] + dy, pose[2] + dz, *pose[3:]]


def shown(pose: list[float]) -> str:
    return ", ".join(f"{v:+.4f}" for v in pose)


async def jog_up(alice: RobotClient, seconds: float, speed: float) -> None:
    """Twist the TCP up at ``speed`` m/s for ``seconds``, then let it come to rest."""
    await alice.ensure_lease()  # streams never wait to acquire it
    states = alice.joint_states()
    for _ in range(int(seconds * 50)):  # a twist every 10 joint states (20 ms at 500 Hz)
        alice.twist([0.0, 0.0, speed], [0.0, 0.0, 0.0])
        for _ in range(10):
            await states.get(timeout=5.0)
    print(f"jogged up at {speed} m/s for {seconds} s; no more twists: alice decelerates")
    for _ in range(2000):  # at most 4 s of joint states
        sample = await states.get_json(timeout=5.0)
        if all(v == 0.0 for v in sample["velocity"]):
            break
    alice.client.unsubscribe(states)


async def main(endpoint: str) -> int:
    async with await Client.connect(endpoint) as client:
        alice = await client.robot("alice")
        start = await tcp_pose(alice)
        print(f"alice's TCP: {shown(start)}")
        try:
            goal = await alice.move_pose(shifted(start, dx=0.05, dz=-0.1), duration=2.0)
            print(f"pose move: {(await goal.result())['status']}")
            here = await tcp_pose(alice)
            path = [shifted(here, dy=0.1), shifted(here, dy=0.1, dz=0.05)]
            goal = await alice.move_linear(path, speed=0.1)
            print(f"linear move: {(await goal.result())['status']}")
        except GoalRejected as err:
            print(f"rejected: {err.reason}")
            return 1
        await jog_up(alice, 0.5, 0.05)
        print(f"at rest at {shown(await tcp_pose(alice))}")
        await alice.set_tcp([0.0, 0.0, 0.1, 0.0, 0.0, 0.0])  # a 10 cm tool along the flange's z
        print(f"with a 10 cm tool, the TCP is at {shown(await tcp_pose(alice, 'alice_tcp'))}")
        await alice.set_tcp([0.0] * 6)
    return 0


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--connect", default=DEFAULT_ENDPOINT)
    args = parser.parse_args()
    raise SystemExit(asyncio.run(main(args.connect)))
