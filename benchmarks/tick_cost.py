"""CPU cost of the motion controller's ``tick`` alone, per mode: a goal, a position, velocity, twist stream.

    python benchmarks/tick_cost.py [runs]

A UR10e-sized controller ticks 10 000 cycles in each case against a robot that lands on every
commanded position one cycle later; a stream gets a new command every cycle, as a client at the
robot's rate sends it, but only the ``tick`` calls are timed. Prints µs per tick, the minimum over
``runs`` runs (default 7): the least disturbed by other work on the machine. The twist cases run on
a UR10e's kinematics with a TCP offset, the twist in the base or the tool frame.
"""

from __future__ import annotations

import math
import platform
import sys
import time
from collections.abc import Callable

from urdaemon.control import MotionController, TrajectoryPoint
from urdaemon.control.cartesian import CartesianLimits
from urdaemon.description.ik import UrKinematics
from urdaemon.description.urmodels import load_ur_model
from urdaemon.model import UR_JOINTS, CommandMode, JointCommand, JointLimits, Lifecycle, RobotState

CYCLES = 10_000
PERIOD = 0.002
LIMITS = JointLimits(
    names=UR_JOINTS,
    min_position=(-2 * math.pi, -2 * math.pi, -math.pi, -2 * math.pi, -2 * math.pi, -2 * math.pi),
    max_position=(2 * math.pi, 2 * math.pi, math.pi, 2 * math.pi, 2 * math.pi, 2 * math.pi),
    max_velocity=(2.094, 2.094, 3.14159, 3.14159, 3.14159, 3.14159),
    max_acceleration=(5.0,) * 6,
    max_jerk=(50.0,) * 6,
)
HOME = (0.0, -1.57, 1.57, -1.57, -1.57, 0.0)
TCP = (0.0, 0.0, 0.15, 0.0, 0.0, 0.0)
TWIST_LIMITS = CartesianLimits(1.0, 1.2, 10.0, 3.0, 4.0, 40.0)

Command = Callable[[MotionController, RobotState, int, float], None]


def _goal(controller: MotionController, state: RobotState, k: int, now: float) -> None:
    if k == 0:
        points = [
            TrajectoryPoint(positions=tuple(p + 0.5 for p in HOME), time_from_start=CYCLES * PERIOD),
            TrajectoryPoint(positions=HOME, time_from_start=2.0 * CYCLES * PERIOD),
        ]
        controller.accept_trajectory("bench", UR_JOINTS, points, state, now)


def _position_stream(controller: MotionController, state: RobotState, k: int, now: float) -> None:
    offset = 0.3 * math.sin(2.0 * math.pi * 0.2 * now)
    controller.stream_positions(UR_JOINTS, [p + offset for p in HOME], None, state, now)


def _velocity_stream(controller: MotionController, state: RobotState, k: int, now: float) -> None:
    speed = 0.3 * math.cos(2.0 * math.pi * 0.2 * now)
    controller.stream_velocities(UR_JOINTS, [speed] * 6, state, now)


def _into_a_limit(controller: MotionController, state: RobotState, k: int, now: float) -> None:
    controller.stream_velocities(UR_JOINTS, [0.0, 0.0, 1.0, 0.0, 0.0, 0.0], state, now)


def _twist(frame: str) -> Command:
    def command(controller: MotionController, state: RobotState, k: int, now: float) -> None:
        speed = 0.05 * math.cos(2.0 * math.pi * 0.2 * now)
        controller.stream_twist((speed, 0.5 * speed, 0.0, 0.0, 0.0, speed), frame, state, now)

    return command


def run_once(command: Command, mode: str) -> float:
    """µs per tick over CYCLES ticks of a fresh controller driven by ``command``, in ``mode`` throughout."""
    controller = MotionController(LIMITS, period=PERIOD)
    controller.set_arm(UrKinematics(load_ur_model("ur10e")), TWIST_LIMITS)
    controller.set_tcp(TCP)
    state = RobotState.zeros(UR_JOINTS)
    state.lifecycle = Lifecycle.RUNNING
    state.program_running = True
    state.positions[:] = HOME
    out = JointCommand.idle(LIMITS.dof)
    tick = controller.tick
    clock = time.perf_counter_ns
    spent = 0
    now = 0.0
    for k in range(CYCLES):
        command(controller, state, k, now)
        start = clock()
        tick(state, out, now)
        spent += clock() - start
        if out.mode is CommandMode.POSITION:
            state.positions[:] = out.positions
            state.velocities[:] = out.velocities
        if controller.has_events:
            controller.drain_events()
        if controller.mode != mode:
            raise AssertionError(f"cycle {k}: the controller is {controller.mode}, not {mode}: wrong case")
        now += PERIOD
    return spent / CYCLES / 1000.0


def main() -> None:
    """Run each case ``runs`` times and print the minimum µs per tick."""
    runs = int(sys.argv[1]) if len(sys.argv) > 1 else 7
    cases: list[tuple[str, Command, str]] = [
        ("goal", _goal, "goal"),
        ("position stream", _position_stream, "stream_position"),
        ("velocity stream", _velocity_stream, "stream_velocity"),
        ("velocity stream at a limit", _into_a_limit, "stream_velocity"),
        ("twist stream, base frame", _twist("base"), "stream_twist"),
        ("twist stream, tool frame", _twist("tool"), "stream_twist"),
    ]
    print(f"machine: {platform.machine()} {platform.processor()}, Python {platform.python_version()}")
    print(f"{'tick while':<28} {'min µs':>8} {'median µs':>10}  ({runs} runs of {CYCLES} ticks)")
    for label, command, mode in cases:
        samples = sorted(run_once(command, mode) for _ in range(runs))
        print(f"{label:<28} {samples[0]:>8.2f} {samples[len(samples) // 2]:>10.2f}")


if __name__ == "__main__":
    main()
