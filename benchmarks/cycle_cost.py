"""CPU cost of one robot cycle in-process (mock step, controller tick, state/TCP encoding), no Zenoh.

    python benchmarks/cycle_cost.py

Prints µs per cycle for a UR10e mock executing a trajectory and idling, and what that means in
CPU-seconds per second at 500 Hz (the target for a whole cycle including Zenoh is 0.04).
"""

from __future__ import annotations

import platform
import statistics
import time

from urdaemon.backends.mock import MockBackend
from urdaemon.cell import load_cell
from urdaemon.control import MotionController, TrajectoryPoint
from urdaemon.daemon import describe_cell
from urdaemon.description import DhKinematics, robot_dh
from urdaemon.model import Lifecycle
from urdaemon.paths import resources_dir
from urdaemon.publish.state_encoder import JointStateEncoder

CYCLES = 5000


def main() -> None:
    """Run the measurements and print a table."""
    cell = load_cell(resources_dir().parent / "configs" / "dual_robot_mock.yaml")
    robot = cell.robot("alice")
    limits = describe_cell(cell).limits["alice"]
    home = [0.0, -1.57, 1.57, -1.57, -1.57, 0.0]
    backend = MockBackend("alice", limits.names, 500.0, initial_positions=home)
    state = backend.state
    state.lifecycle = Lifecycle.RUNNING
    state.program_running = True
    controller = MotionController(limits, period=backend.period)
    kinematics = DhKinematics(robot_dh(robot))
    encoder = JointStateEncoder("alice", limits.names)
    points = [
        TrajectoryPoint(positions=tuple(p + 0.5 for p in home), time_from_start=5.0),
        TrajectoryPoint(positions=tuple(home), time_from_start=10.0),
    ]

    def cycle(now: float) -> None:
        backend.step()
        controller.tick(state, backend.command, now)
        encoder.encode(state)
        encoder.encode_pose(state, "alice_base", "alice_tool0", kinematics.tool_pose(state.positions))
        if controller.has_events:
            controller.drain_events()

    rows = []
    now = 0.0
    for label, with_goal in (("executing a trajectory", True), ("idle", False)):
        if with_goal:
            controller.accept_trajectory("bench", limits.names, points, state, now)
        samples = []
        for _ in range(CYCLES):
            start = time.perf_counter_ns()
            cycle(now)
            samples.append((time.perf_counter_ns() - start) / 1000.0)
            now += backend.period
        samples.sort()
        median = statistics.median(samples)
        rows.append((label, median, samples[int(0.99 * len(samples))], median * 500 / 1e6))
    print(f"machine: {platform.machine()} {platform.processor()}, Python {platform.python_version()}")
    print(f"{'cycle (no Zenoh)':<26} {'median µs':>10} {'p99 µs':>8} {'CPU-s/s at 500 Hz':>18}")
    for label, median, p99, load in rows:
        print(f"{label:<26} {median:>10.1f} {p99:>8.1f} {load:>18.4f}")


if __name__ == "__main__":
    main()
