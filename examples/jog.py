"""Jog alice's base joint with streamed velocity commands, then let the deadman stop it.

    urdaemon serve --config configs/dual_robot_mock.yaml      # in one terminal
    python examples/jog.py                                    # in another

Streaming commands need the robot's command lease, acquired once before the first (the client
releases it when it closes), and must keep coming faster than the robot's ``motion.stream_timeout``
(0.2 s by default); here one goes out with every tenth joint state (every 20 ms at 500 Hz).
"""

from __future__ import annotations

import argparse
import asyncio

from urdaemon.client import DEFAULT_ENDPOINT, Client


async def main(endpoint: str, seconds: float, speed: float) -> int:
    """Jog, stop sending, and report where the joint came to rest."""
    async with await Client.connect(endpoint) as client:
        alice = await client.robot("alice")
        await alice.ensure_lease()  # stream commands need the lease; they never wait to acquire it
        states = alice.joint_states()
        start = (await states.get_json(timeout=5.0))["position"][0]
        for _ in range(int(seconds * 50)):
            alice.stream_velocities([speed, 0.0, 0.0, 0.0, 0.0, 0.0])
            for _ in range(10):
                await states.get(timeout=5.0)
        print(f"jogged from {start:.3f} rad; no more commands: the deadman stops the joint")
        for _ in range(2000):  # at most 4 s of joint states
            sample = await states.get_json(timeout=5.0)
            if all(v == 0.0 for v in sample["velocity"]):
                print(f"at rest at {sample['position'][0]:.3f} rad")
                return 0
        print("still moving after 4 s")
        return 1


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--connect", default=DEFAULT_ENDPOINT)
    parser.add_argument("--seconds", type=float, default=1.0)
    parser.add_argument("--speed", type=float, default=0.3, help="rad/s")
    args = parser.parse_args()
    raise SystemExit(asyncio.run(main(args.connect, args.seconds, args.speed)))
