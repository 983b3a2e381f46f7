"""Move both arms of the demo cell at the same time and print their progress and results.

urdaemon serve --config configs/dual_robot_mock.yaml      # in one terminal
python examples/dual_arm.py                               # in another
"""

from __future__ import annotations

import argparse
import asyncio

from urdaemon.client import DEFAULT_ENDPOINT, Client, GoalHandle
from urdaemon.errors import UrDaemonError

HOME = [0.0, -1.5708, 1.5708, -1.5708, -1.5708, 0.0]


async def report(name: str, goal: GoalHandle) -> str:
    """Print a goal's feedback every half second of progress, then its result; return the status."""
    shown = -1.0
    async for feedback in goal.feedback():
        if feedback["progress"] - shown >= 0.25:
            shown = feedback["progress"]
            print(f"{name}: {shown:4.0%}")
    result = await goal.result()
    print(f"{name}: {result['status']} {result['reason']}".rstrip())
    return str(result["status"])


async def main(endpoint: str) -> int:
    """Send alice a three-point trajectory and bob a move, wait for both, then send both home."""
    async with await Client.connect(endpoint) as client:
        alice, bob = await client.robot("alice"), await client.robot("bob")
        alice_goal = await alice.send_trajectory(
            [
                {"positions": [0.4, -1.3, 1.2, -1.5, -1.5, 0.3], "time_from_start": 1.5},
                {"positions": [0.8, -1.1, 0.9, -1.3, -1.4, 0.6], "time_from_start": 3.0},
                {"positions": [0.5, -1.4, 1.3, -1.6, -1.5, 0.2], "time_from_start": 4.5},
            ]
        )
        bob_goal = await bob.move([-0.6, -1.2, 1.1, -1.4, -1.6, 0.5], duration=3.0)
        try:
            statuses = list(await asyncio.gather(report("alice", alice_goal), report("bob", bob_goal)))
        except asyncio.CancelledError:  # Ctrl-C: stop both arms before leaving
            await asyncio.gather(alice.cancel(alice_goal.goal_id), bob.cancel(bob_goal.goal_id))
            raise
        homes = await asyncio.gather(alice.move(HOME), bob.move(HOME))
        statuses += await asyncio.gather(
            *(report(f"{n} home", g) for n, g in zip(("alice", "bob"), homes, strict=True))
        )
        return 0 if all(s == "succeeded" for s in statuses) else 1


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--connect", default=DEFAULT_ENDPOINT)
    try:
        raise SystemExit(asyncio.run(main(parser.parse_args().connect)))
    except UrDaemonError as err:  # e.g. no daemon at --connect, or no robot 'alice': say which
        raise SystemExit(f"error: {err}") from None
