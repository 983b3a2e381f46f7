"""MotionController twist streams: a TCP velocity in the base or tool frame, smoothed, damped near
singularities, braked before joint limits, stopped by the deadman.

Pure: the controller drives the simulated robot of sim.py (it lands on each command one cycle later) on
a fake clock; where the TCP goes is checked by the forward kinematics of a UR10e. Every twist stream
was new in issue 17: on the old controller each test fails at ``set_arm`` (AttributeError).
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Sequence

import pytest

from urdaemon.control.cartesian import CartesianLimits
from urdaemon.description.dls import singularity
from urdaemon.description.frames import frame_of_pose
from urdaemon.description.ik import UrKinematics
from urdaemon.description.urmodels import load_ur_model
from urdaemon.errors import GoalRejected
from urdaemon.model import UR_JOINTS, CommandMode, JointLimits

from .sim import PERIOD, UR10E_LIMITS, SimRobot, check_command_limits

KIN = UrKinematics(load_ur_model("ur10e"))
TWIST = CartesianLimits(
    speed=1.0, acceleration=1.2, jerk=10.0, angular_speed=3.0, angular_acceleration=4.0, angular_jerk=40.0
)
"""The cell file's defaults: caps for the speeds, default accelerations and jerks for the smoothing."""
Q0 = [0.0, -1.4, 1.6, -1.8, -1.57, 0.0]
"""A pose far from every singularity and limit."""


def _robot(q0: Sequence[float] = Q0, limits: JointLimits = UR10E_LIMITS, **kwargs: float) -> SimRobot:
    robot = SimRobot.create(limits, list(q0), **kwargs)
    robot.controller.set_arm(KIN, TWIST)
    return robot


def _twist(robot: SimRobot, twist: Sequence[float], cycles: int, frame: str = "base") -> None:
    """Send ``twist`` every cycle for ``cycles`` cycles."""
    for _ in range(cycles):
        robot.controller.stream_twist(twist, frame, robot.state, robot.now)
        robot.step()


def _tcp(robot: SimRobot, k: int) -> tuple[float, ...]:
    """The TCP pose commanded at cycle ``k``."""
    return tuple(KIN.forward(robot.commands[k][1], robot.controller.tcp))


def _speeds(robot: SimRobot, first: int = 1) -> list[float]:
    """The TCP point's speed (m/s) between successive commanded poses from cycle ``first`` on."""
    points = [_tcp(robot, k)[:3] for k in range(first - 1, len(robot.commands))]
    return [math.dist(a, b) / PERIOD for a, b in itertools.pairwise(points)]


def _check_jerk(robot: SimRobot, limits: JointLimits = UR10E_LIMITS) -> None:
    """Every joint's jerk (second difference of the commanded velocities) within its limit, every cycle."""
    vel = [c[2] for c in robot.commands]
    for k in range(2, len(vel)):
        for i in range(limits.dof):
            jerk = (vel[k][i] - 2.0 * vel[k - 1][i] + vel[k - 2][i]) / (PERIOD * PERIOD)
            assert abs(jerk) <= limits.max_jerk[i] * 1.0001, f"cycle {k}: {limits.names[i]} jerk {jerk}"


def _unit(v: Sequence[float]) -> list[float]:
    n = math.sqrt(sum(x * x for x in v))
    return [x / n for x in v]


def _braking_starts(robot: SimRobot) -> float:
    """Step the robot (no more messages) until the deadman brakes: the time of the first tick whose
    command ramps down (mode stopping, a deadman stop counted; the fastest joint's commanded speed
    lower 50 cycles later)."""
    before = robot.controller.statistics().deadman_stops
    for _ in range(2000):
        tick = robot.now
        robot.step()
        if robot.controller.mode != "stream_twist":
            break
    else:
        raise AssertionError("the deadman never braked")
    assert robot.controller.mode == "stopping"
    assert robot.controller.statistics().deadman_stops == before + 1
    first = len(robot.commands) - 1
    for _ in range(50):
        robot.step()
    speeds = [max(abs(v) for v in c[2]) for c in robot.commands[first - 1 :]]
    assert speeds[-1] < 0.9 * speeds[0], "slower 0.1 s into the ramp"
    return tick


def test_a_base_twist_moves_the_tcp_along_it_and_the_deadman_stops_it() -> None:
    robot = _robot(stream_timeout=0.2)
    start = tuple(KIN.forward(Q0))
    _twist(robot, [0.0, 0.0, 0.1, 0.0, 0.0, 0.0], 600)
    assert robot.controller.mode == "stream_twist"
    end = tuple(KIN.forward(robot.state.positions))
    moved = [b - a for a, b in zip(start[:3], end[:3], strict=True)]
    assert moved[2] > 0.08, "went up, near 0.1 m/s for most of 1.2 s"
    assert math.hypot(moved[0], moved[1]) < 0.01 * moved[2], "straight up"
    assert max(abs(b - a) for a, b in zip(start[3:], end[3:], strict=True)) < 0.01, "orientation kept"
    assert _speeds(robot)[-1] == pytest.approx(0.1, rel=0.01)
    # The messages stop: after the stream timeout the deadman stops it with a jerk-limited ramp.
    last = robot.now - PERIOD
    braking = _braking_starts(robot)
    assert 0.2 - PERIOD < braking - last <= 0.2 + PERIOD, "braking starts within the deadman + 1 cycle"
    ticks = robot.run_until_idle(1000)
    assert robot.controller.statistics().deadman_stops == 1
    assert ticks > 5, "then ramped down"
    assert robot.commands[-1][0] is CommandMode.IDLE
    check_command_limits(robot.commands, UR10E_LIMITS, PERIOD)
    _check_jerk(robot)


def test_a_tool_twist_turns_with_the_tool() -> None:
    """Linear x and angular z in the tool frame: the tool's x axis turns, and the TCP's way with it (a
    circle); the same numbers in the base frame would go on along base x."""
    robot = _robot()
    _twist(robot, [0.05, 0.0, 0.0, 0.0, 0.0, 0.5], round(math.pi / 0.5 / PERIOD), frame="tool")
    pose = _tcp(robot, -1)
    before = _tcp(robot, -2)
    way = _unit([b - a for a, b in zip(before[:3], pose[:3], strict=True)])
    r = frame_of_pose(pose)
    tool_x = (r[0], r[3], r[6])
    assert sum(a * b for a, b in zip(way, tool_x, strict=True)) > 0.999
    # Half a turn about the tool's z axis: its x axis now points back where it started.
    r0 = frame_of_pose(KIN.forward(Q0))
    assert r[0] * r0[0] + r[3] * r0[3] + r[6] * r0[6] < -0.99
    check_command_limits(robot.commands, UR10E_LIMITS, PERIOD)
    _check_jerk(robot)


def test_a_tool_twist_turns_about_the_tcp_point_with_the_tcp_offset() -> None:
    robot = _robot()
    robot.controller.set_tcp([0.0, 0.0, 0.2, 0.0, 0.0, 0.0])
    assert robot.controller.tcp == (0.0, 0.0, 0.2, 0.0, 0.0, 0.0)
    start = tuple(KIN.forward(Q0, robot.controller.tcp))
    _twist(robot, [0.0, 0.0, 0.0, 0.4, 0.0, 0.0], 500, frame="tool")
    end = _tcp(robot, -1)
    assert math.dist(start[:3], end[:3]) < 2e-3, "the TCP point stays where it is"
    flange = [KIN.forward(Q0)[:3], KIN.forward(robot.commands[-1][1])[:3]]
    assert math.dist(*flange) > 0.05, "the flange swings around it"


def _check_slowing(robot: SimRobot, commanded: float, sigma: float, share: float) -> None:
    """Never faster than ``commanded``, at most ``share`` of it where the Jacobian's smallest singular
    value is below ``sigma`` (and it got there), the speed changing smoothly, the joints within limits."""
    speeds = _speeds(robot)
    sigmas = [singularity(KIN.jacobian_rows(c[1])) for c in robot.commands[1:]]
    assert max(speeds) <= commanded * 1.001, "never faster than asked"
    near = [s for s, g in zip(speeds, sigmas, strict=True) if g < sigma]
    assert near, "it went up to the singularity"
    assert max(near) < share * commanded, "slowed near it"
    # Slowed smoothly: the TCP's speed changes by less than 2 mm/s a cycle (1 m/s^2): no jump.
    assert max(abs(b - a) for a, b in itertools.pairwise(speeds)) < 0.002
    check_command_limits(robot.commands, UR10E_LIMITS, PERIOD)
    _check_jerk(robot)


def test_a_twist_into_the_wrist_singularity_slows_smoothly_within_the_joint_limits() -> None:
    """The twist that turns wrist 3 (q5) toward 0, where the wrist axes 4 and 6 line up: as the
    Jacobian's smallest singular value falls the TCP slows (to under a third of the twist below 0.01),
    then passes through and speeds up again; no joint over its speed, acceleration or jerk limit at
    any cycle. Without the slow-down it went through at 0.135 m/s, faster than the 0.117 asked for,
    the wrist joints lagging their damped-least-squares targets."""
    q0 = [0.0, -1.2, 1.5, -1.9, 0.4, 0.0]
    column = [-row[4] for row in KIN.jacobian_rows(q0)]
    k = 1.0 / math.sqrt(sum(v * v for v in column[3:]))
    twist = [v * k for v in column]  # 1 rad/s about wrist 3's axis, its TCP point's velocity with it
    commanded = math.sqrt(sum(v * v for v in twist[:3]))
    robot = _robot(q0)
    _twist(robot, twist, 1000)
    assert min(abs(c[1][4]) for c in robot.commands) < 1e-3, "q5 went through 0"
    _check_slowing(robot, commanded, 0.01, 0.35)


def test_a_twist_out_of_reach_slows_smoothly_within_the_joint_limits() -> None:
    """Straight out of reach (the elbow stretches): the TCP slows to a crawl as the arm straightens."""
    robot = _robot([0.0, -1.4, 1.6, -0.2, 0.2, 0.0])
    _twist(robot, [-0.1, 0.0, 0.0, 0.0, 0.0, 0.0], 4000)
    assert abs(robot.commands[-1][1][2]) < 0.1, "the elbow is nearly straight"
    _check_slowing(robot, 0.1, 0.02, 0.12)


def test_a_twist_pushing_a_joint_to_its_limit_brakes_before_it_then_leaves_it() -> None:
    limits = JointLimits(
        names=UR10E_LIMITS.names,
        min_position=(-0.3, *UR10E_LIMITS.min_position[1:]),
        max_position=UR10E_LIMITS.max_position,
        max_velocity=UR10E_LIMITS.max_velocity,
        max_acceleration=UR10E_LIMITS.max_acceleration,
        max_jerk=UR10E_LIMITS.max_jerk,
    )
    robot = _robot(limits=limits)
    # Sideways: the shoulder pan turns toward its lower limit, -0.3.
    _twist(robot, [0.0, 0.3, 0.0, 0.0, 0.0, 0.0], 1500)
    pan = [c[1][0] for c in robot.commands]
    assert min(pan) >= -0.3, "braked before the limit"
    assert min(pan) < -0.29, "and went close to it"
    assert robot.controller.mode == "stream_twist"
    assert robot.commands[-1][2] == pytest.approx([0.0] * 6, abs=1e-12), "the whole arm waits there"
    still = _tcp(robot, -1)
    _twist(robot, [0.0, 0.3, 0.0, 0.0, 0.0, 0.0], 200)
    assert math.dist(still[:3], _tcp(robot, -1)[:3]) < 1e-9, "and does not creep on"
    # The other way leaves the limit.
    _twist(robot, [0.0, -0.3, 0.0, 0.0, 0.0, 0.0], 1000)
    assert robot.commands[-1][1][0] > -0.2
    check_command_limits(robot.commands, limits, PERIOD)
    _check_jerk(robot, limits)


def test_a_zero_twist_decelerates_smoothly_within_the_cartesian_limits() -> None:
    robot = _robot()
    _twist(robot, [0.2, 0.0, 0.0, 0.0, 0.0, 0.0], 800)
    first = len(robot.commands)
    _twist(robot, [0.0] * 6, 800)
    assert robot.controller.mode == "stream_twist"
    speeds = _speeds(robot, first)
    assert speeds[0] == pytest.approx(0.2, rel=0.02)
    assert speeds[-1] < 1e-9
    stopped = next(k for k, s in enumerate(speeds) if s < 1e-6)
    # The smoothing brakes at 1.2/sqrt(3) m/s^2 at most (an axis's share of the linear acceleration).
    assert stopped * PERIOD >= 0.2 / (1.2 / math.sqrt(3.0))
    accelerations = [abs(b - a) / PERIOD for a, b in itertools.pairwise(speeds)]
    assert max(accelerations) <= 1.2 * 1.05
    check_command_limits(robot.commands, UR10E_LIMITS, PERIOD)
    _check_jerk(robot)


@pytest.mark.parametrize(
    ("twist", "frame", "reason"),
    [
        ([0.0] * 6, "world", "frame 'world' is not one of base, tool"),
        ([0.0] * 5, "base", "5 values"),
        ([0.0, math.nan, 0.0, 0.0, 0.0, 0.0], "base", "vy is nan, not a finite number"),
        ([0.0, 0.0, 0.0, 0.0, 0.0, math.inf], "tool", "wz is inf"),
        ([0.8, 0.8, 0.0, 0.0, 0.0, 0.0], "base", r"linear speed 1\.13137 m/s exceeds the cap 1 m/s"),
        ([0.0, 0.0, 0.0, 2.0, 2.0, 2.0], "base", r"angular speed 3\.4641 rad/s exceeds the cap 3 rad/s"),
    ],
)
def test_bad_twists_are_refused_naming_what_is_wrong(twist: list[float], frame: str, reason: str) -> None:
    robot = _robot()
    with pytest.raises(GoalRejected, match=reason):
        robot.controller.stream_twist(twist, frame, robot.state, robot.now)
    assert robot.controller.mode == "idle"


def test_a_twist_needs_the_arm_and_a_ready_robot_with_no_goal() -> None:
    robot = SimRobot.create(UR10E_LIMITS, Q0)
    with pytest.raises(GoalRejected, match="no arm kinematics"):
        robot.controller.stream_twist([0.1, 0, 0, 0, 0, 0], "base", robot.state, robot.now)
    robot.controller.set_arm(KIN, TWIST)
    robot.controller.accept_move("m1", UR_JOINTS, [0.1, *Q0[1:]], robot.state, robot.now)
    with pytest.raises(GoalRejected, match="busy: goal m1 is executing"):
        robot.controller.stream_twist([0.1, 0, 0, 0, 0, 0], "base", robot.state, robot.now)
    robot.controller.cancel()
    robot.run_until_idle(2000)
    # Taking the arm away while a twist runs brakes it to rest, as the deadman does.
    _twist(robot, [0.1, 0.0, 0.0, 0.0, 0.0, 0.0], 200)
    robot.controller.set_arm(None, TWIST)
    robot.step()
    assert robot.controller.mode == "stopping"
    robot.run_until_idle(1000)
    check_command_limits(robot.commands, UR10E_LIMITS, PERIOD)
    robot.state.program_running = False
    with pytest.raises(GoalRejected, match="robot not ready"):
        robot.controller.stream_twist([0.1, 0, 0, 0, 0, 0], "base", robot.state, robot.now)


def test_stop_goals_and_joint_streams_end_a_twist_as_they_end_joint_streams() -> None:
    robot = _robot()
    _twist(robot, [0.1, 0.0, 0.0, 0.0, 0.0, 0.0], 300)
    # A goal waits for an active twist stream, or preempts it.
    with pytest.raises(GoalRejected, match="busy: a twist stream is active"):
        robot.controller.accept_move("m1", UR_JOINTS, Q0, robot.state, robot.now)
    with pytest.raises(GoalRejected, match="set_tcp: the robot is moving"):
        robot.controller.set_tcp([0.0] * 6)
    robot.controller.accept_move("m1", UR_JOINTS, Q0, robot.state, robot.now, preempt=True)
    assert robot.controller.mode == "goal"
    robot.run_until_result("m1", 3000)
    robot.run_until_idle(1000)
    # stop() ramps a twist down like a joint stream.
    _twist(robot, [0.1, 0.0, 0.0, 0.0, 0.0, 0.0], 300)
    robot.controller.stop("stop requested", robot.now)
    assert robot.controller.mode == "stopping"
    robot.run_until_idle(1000)
    # A joint velocity stream takes over a twist directly, and a twist a joint stream.
    _twist(robot, [0.1, 0.0, 0.0, 0.0, 0.0, 0.0], 300)
    for _ in range(300):
        robot.controller.stream_velocities(UR_JOINTS, [0.0, 0.0, 0.0, 0.0, 0.0, 0.2], robot.state, robot.now)
        robot.step()
    assert robot.controller.mode == "stream_velocity"
    assert robot.commands[-1][2] == pytest.approx([0.0, 0.0, 0.0, 0.0, 0.0, 0.2], abs=1e-9)
    _twist(robot, [0.0, 0.0, -0.1, 0.0, 0.0, 0.0], 300)
    assert robot.controller.mode == "stream_twist"
    robot.run_until_idle(1000)
    assert robot.controller.statistics().deadman_stops == 1
    robot.controller.set_tcp([0.0, 0.0, 0.1, 0.0, 0.0, 0.0])
    check_command_limits(robot.commands, UR10E_LIMITS, PERIOD)
    _check_jerk(robot)
