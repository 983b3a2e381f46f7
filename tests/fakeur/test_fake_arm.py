"""The fake controller's simulated arm: modes, refusals, motion within limits, safety stops."""

from __future__ import annotations

import itertools
import math

import pytest

from urdaemon.description.frames import frame_of_pose
from urdaemon.description.urmodels import load_ur_model
from urdaemon.fakeur.fake_arm import HISTORY_STEPS, FakeArm
from urdaemon.fakeur.joint_motion import JointMove, SpeedRamp, joint_move
from urdaemon.fakeur.life import BOOT_TIME_S, BRAKE_RELEASE_TIME_S, UNLOCK_TOO_SOON, UNLOCK_WAIT_S
from urdaemon.model import RobotMode, SafetyMode
from urdaemon.protocols.rtde_variables import RuntimeState

DT = 0.002


def _arm(powered: bool = False) -> FakeArm:
    model = load_ur_model("ur10e")
    return FakeArm(model, model.dh, powered=powered)


def _mode(arm: FakeArm) -> RobotMode:
    """The arm's robot mode, read through a call so that the type checker does not pin it."""
    return arm.robot_mode


def _safety(arm: FakeArm) -> SafetyMode:
    return arm.safety_mode


def _state(arm: FakeArm) -> RuntimeState:
    return arm.runtime_state


def _run(arm: FakeArm, seconds: float) -> None:
    for _ in range(round(seconds / DT)):
        arm.step(DT)


def test_power_on_boots_to_idle_and_brake_release_to_running() -> None:
    arm = _arm()
    assert arm.robot_mode is RobotMode.POWER_OFF
    assert arm.life.brake_release(arm.timestamp) == "robot is POWER_OFF, not IDLE"
    assert arm.life.power_on(arm.timestamp) is None
    assert _mode(arm) is RobotMode.BOOTING
    _run(arm, BOOT_TIME_S + 0.01)
    assert _mode(arm) is RobotMode.IDLE
    assert arm.life.brake_release(arm.timestamp) is None
    _run(arm, BRAKE_RELEASE_TIME_S + 0.01)
    assert _mode(arm) is RobotMode.RUNNING
    assert arm.life.robot_status_bits & 1 == 1
    arm.power_off()
    assert arm.robot_mode is RobotMode.POWER_OFF
    assert arm.life.robot_status_bits == 0


def test_program_cannot_start_unless_running() -> None:
    arm = _arm()
    assert arm.start_program() == "robot is POWER_OFF, not RUNNING"
    arm = _arm(powered=True)
    assert arm.start_program() is None
    assert arm.runtime_state is RuntimeState.PLAYING
    assert arm.program_running
    assert arm.life.robot_status_bits == 0b11


def test_servoj_tracks_the_target_within_the_velocity_limits() -> None:
    arm = _arm(powered=True)
    start = list(arm.q)
    target = [start[0] + 1.0, *start[1:]]
    peak = 0.0
    for _ in range(2000):
        arm.servoj(target)
        arm.step(DT)
        peak = max(peak, abs(arm.qd[0]))
        assert abs(arm.qd[0]) <= arm.max_velocity[0] + 1e-12
        if abs(arm.q[0] - target[0]) < 1e-12:
            break
    assert arm.q[0] == pytest.approx(target[0], abs=1e-12)
    assert peak == pytest.approx(arm.max_velocity[0])


def test_speedj_ramps_at_the_given_acceleration_and_stop_decelerates() -> None:
    arm = _arm(powered=True)
    arm.speedj([0.5, 0, 0, 0, 0, 0], acceleration=2.0)
    _run(arm, 0.1)
    assert arm.qd[0] == pytest.approx(0.2, abs=1e-9)
    _run(arm, 0.5)
    assert arm.qd[0] == pytest.approx(0.5)
    arm.stop(1.0)
    _run(arm, 0.25)
    assert arm.qd[0] == pytest.approx(0.25, abs=1e-9)
    _run(arm, 0.3)
    assert arm.qd[0] == 0.0


def test_no_motion_while_not_running() -> None:
    arm = _arm()
    before = list(arm.q)
    arm.servoj([v + 0.5 for v in before])
    arm.speedj([1.0] * 6)
    _run(arm, 0.2)
    assert arm.q == before


def test_protective_stop_stops_motion_pauses_the_program_and_needs_an_unlock() -> None:
    arm = _arm(powered=True)
    arm.start_program()
    arm.speedj([1.0, 0, 0, 0, 0, 0])
    _run(arm, 0.2)
    arm.protective_stop()
    assert arm.safety_mode is SafetyMode.PROTECTIVE_STOP
    assert arm.runtime_state is RuntimeState.PAUSED
    assert arm.unlock_protective_stop() == "robot still moving"
    _run(arm, 0.3)
    assert arm.qd == [0.0] * 6
    arm.speedj([1.0] * 6)
    _run(arm, 0.1)
    assert arm.qd == [0.0] * 6, "no motion during a protective stop"
    assert arm.life.safety_status_bits == 1 << 2
    assert arm.unlock_protective_stop() == UNLOCK_TOO_SOON, "at rest, but within 5 s of the stop"
    _run(arm, UNLOCK_WAIT_S)
    assert arm.unlock_protective_stop() is None
    assert _safety(arm) is SafetyMode.NORMAL
    assert arm.unlock_protective_stop() == "safety mode is NORMAL, not PROTECTIVE_STOP"


def test_leaving_the_joint_limits_triggers_a_protective_stop() -> None:
    arm = _arm(powered=True)
    arm.q[2] = arm.max_position[2] - 0.001
    arm.speedj([0, 0, 1.0, 0, 0, 0])
    _run(arm, 0.1)
    assert arm.safety_mode is SafetyMode.PROTECTIVE_STOP
    assert arm.q[2] <= arm.max_position[2]


def test_emergency_stop_powers_off_and_power_on_is_refused_until_released() -> None:
    arm = _arm(powered=True)
    arm.start_program()
    arm.emergency_stop()
    assert arm.robot_mode is RobotMode.POWER_OFF
    assert arm.runtime_state is RuntimeState.STOPPED
    assert arm.life.power_on(arm.timestamp) == "emergency stop active"
    arm.life.release_emergency_stop()
    assert arm.safety_mode is SafetyMode.NORMAL
    assert arm.life.power_on(arm.timestamp) is None


def test_tcp_pose_is_the_dh_forward_kinematics_as_a_rotation_vector() -> None:
    arm = _arm(powered=True)
    arm.q = [0.0] * 6
    x, y, z, rx, ry, rz = arm.tcp_pose()
    dh = arm.dh
    # at zero angles the UR tool sits at x = a2 + a3, y = -(d4 + d6)... (standard UR DH layout)
    assert x == pytest.approx(dh.a[1] + dh.a[2], abs=1e-9)
    assert y == pytest.approx(-(dh.d[3] + dh.d[5]), abs=1e-9)
    assert z == pytest.approx(dh.d[0] - dh.d[4], abs=1e-9)
    assert math.sqrt(rx * rx + ry * ry + rz * rz) == pytest.approx(math.pi / 2, abs=1e-9)


def test_a_played_motion_advances_by_the_speed_slider_and_stops_when_not_renewed() -> None:
    """play(): dt × slider of program time per cycle; once over, the arm stops at the given deceleration."""
    arm = _arm(powered=True)
    arm.speed_slider = 0.5
    start = list(arm.q)
    ramp = SpeedRamp(start, [0.0] * 6, [0.4, 0, 0, 0, 0, 0], 100.0, 0.1)
    assert arm.play(ramp, 2.0)
    _run(arm, 0.1)
    assert arm.motion_time == pytest.approx(0.05)
    assert arm.qd[0] == pytest.approx(0.2, abs=1e-9), "the motion's 0.4 rad/s at half speed"
    _run(arm, 0.1)
    assert arm.motion is ramp
    arm.step(DT)
    assert arm.motion is not ramp, "over and not renewed: a stop"
    _run(arm, 0.5)
    assert arm.qd == [0.0] * 6
    assert arm.steady
    assert arm.target_q == arm.q


def test_play_is_refused_while_the_arm_cannot_move() -> None:
    arm = _arm()
    assert not arm.play(SpeedRamp(arm.q, [0.0] * 6, [1.0] * 6, 1.0, 1.0), 1.0)
    assert arm.motion is None


def test_history_keeps_the_positions_of_past_cycles() -> None:
    arm = _arm(powered=True)
    arm.play(SpeedRamp(arm.q, [0.0] * 6, [0.5, 0, 0, 0, 0, 0], 100.0, 1.0), 1.0)
    seen = []
    for _ in range(HISTORY_STEPS + 10):
        arm.step(DT)
        seen.append(list(arm.q))
    assert arm.history.ago(0) == seen[-1]
    assert arm.history.ago(5) == seen[-6]
    assert arm.history.ago(HISTORY_STEPS - 1) == seen[-HISTORY_STEPS]
    assert arm.history.ago(HISTORY_STEPS + 100) == seen[-HISTORY_STEPS]


def test_actual_tcp_pose_applies_the_tcp_offset() -> None:
    arm = _arm(powered=True)
    assert arm.actual_tcp_pose() == arm.tcp_pose(), "no offset: the flange"
    arm.tcp_offset = [0.0, 0.0, 0.2, 0.0, 0.0, 0.0]
    x, y, z, *_ = arm.tcp_pose()
    rotation = frame_of_pose(arm.tcp_pose())
    tool = arm.actual_tcp_pose()
    # 0.2 m along the flange's z axis (the third column of its rotation)
    assert tool[:3] == pytest.approx(
        (x + 0.2 * rotation[2], y + 0.2 * rotation[5], z + 0.2 * rotation[8]), abs=1e-12
    )
    assert tool[3:] == pytest.approx(arm.tcp_pose()[3:], abs=1e-12)


# ---- pausing and resuming along the path ------------------------------------------------------------------


def _paused_and_resumed(arm: FakeArm, move: JointMove, pause_after: int) -> list[tuple[RuntimeState, float]]:
    """Play ``move``, pause after ``pause_after`` cycles, resume 50 cycles after PAUSED, play it out;
    (runtime state, speed scaling) after each cycle."""
    seen = []
    assert arm.start_program() is None
    assert arm.play(move, 1.0)
    for _ in range(pause_after):
        arm.step(DT)
        seen.append((arm.runtime_state, arm.speed_scaling))
    arm.pause_program()
    for _ in range(1000):
        arm.step(DT)
        seen.append((arm.runtime_state, arm.speed_scaling))
        if arm.runtime_state is RuntimeState.PAUSED:
            break
    _run(arm, 50 * DT)
    seen.extend([(arm.runtime_state, arm.speed_scaling)] * 50)
    assert arm.resume_program() is None
    for _ in range(2000):
        arm.step(DT)
        seen.append((arm.runtime_state, arm.speed_scaling))
        if arm.motion is None:
            break
    return seen


def test_a_pause_ramps_the_speed_scaling_down_along_the_path_and_resume_ramps_it_up() -> None:
    """Before, ``pause_program`` stopped the arm as a protective stop does (10 rad/s², the motion
    dropped): the arm came to rest off the motion's timing and never went on after resume."""
    arm = _arm(powered=True)
    start = list(arm.q)
    target = [start[0] + 0.6, start[1] - 0.3, *start[2:]]
    move = joint_move(start, target, velocity=1.0, acceleration=2.0, max_velocity=arm.max_velocity)
    positions: list[list[float]] = [list(arm.q)]
    original_step = arm.step

    def step(dt: float) -> None:
        original_step(dt)
        positions.append(list(arm.q))

    arm.step = step  # type: ignore[method-assign]
    seen = _paused_and_resumed(arm, move, pause_after=300)  # mid-move, at its cruise speed
    states = [state for state, _ in seen]
    assert RuntimeState.PAUSING in states, "slows down first"
    first_pausing = states.index(RuntimeState.PAUSING)
    paused = states.index(RuntimeState.PAUSED)
    ramp = [scaling for _, scaling in seen[first_pausing:paused]]
    assert paused - first_pausing > 10, "a ramp, not a stop in a cycle"
    assert all(b < a for a, b in itertools.pairwise(ramp)), "the scaling ramps down"
    assert seen[paused][1] == 0.0
    resumed = [scaling for state, scaling in seen[paused:] if state is RuntimeState.PLAYING]
    assert resumed[0] < 0.2, "the scaling ramps back up"
    assert resumed[-1] == 1.0
    # every position lies on the move's path (a straight line in joint space), joint 0 never goes back
    for q in positions:
        fraction = (q[0] - start[0]) / 0.6
        assert q[1] == pytest.approx(start[1] - 0.3 * fraction, abs=1e-12)
    steps = [b[0] - a[0] for a, b in itertools.pairwise(positions)]
    assert min(steps) >= 0.0
    speeds = [s / DT for s in steps]
    accelerations = [(b - a) / DT for a, b in itertools.pairwise(speeds)]
    assert max(abs(a) for a in accelerations) <= arm.max_acceleration[0] + 1e-6, "within the joint limits"
    assert arm.q == pytest.approx(target, abs=1e-12), "the move ends on its target"
    assert arm.qd == [0.0] * 6


def test_a_pause_at_rest_pauses_at_once_and_resume_plays_at_once() -> None:
    arm = _arm(powered=True)
    assert arm.start_program() is None
    arm.pause_program()
    assert arm.runtime_state is RuntimeState.PAUSED
    arm.step(DT)
    assert arm.speed_scaling == 0.0
    assert arm.resume_program() is None
    assert _state(arm) is RuntimeState.PLAYING
    arm.step(DT)
    assert arm.speed_scaling == 1.0


def test_a_stream_of_one_cycle_speedj_moves_smoothly_at_any_speed_slider() -> None:
    """A program plays one speedj of one cycle's program time per cycle (the control script's
    spline). At a slider of 0.7 each takes 1.43 cycles: before, the arm stopped at each motion's end
    and the next one began a cycle later, so the arm moved 0.7, 0.7, 0, 0.7, 0.7, 0.1 ... steps."""
    arm = _arm(powered=True)
    assert arm.start_program() is None
    arm.speed_slider = 0.7
    velocity = [0.5, 0.0, 0.0, 0.0, 0.0, 0.0]
    arm.play(SpeedRamp(arm.q, [0.0] * 6, velocity, 1e6, DT), 1.0)  # at speed at once
    positions = []
    for _ in range(200):
        motion = arm.motion
        assert motion is not None
        if arm.motion_time >= motion.duration - 1e-9:  # what a speedj builtin sees: over, the next one
            arm.play(SpeedRamp(arm.target_q, arm.commanded_velocity, velocity, 1e6, DT), 1.0)
        arm.step(DT)
        positions.append(arm.q[0])
    steps = [b - a for a, b in itertools.pairwise(positions[1:])]
    assert steps == pytest.approx([0.5 * 0.7 * DT] * len(steps), rel=1e-9)
