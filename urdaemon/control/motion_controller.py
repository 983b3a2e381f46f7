"""The per-robot motion controller: executes goals and joint streams, one ``tick`` per robot cycle.

Pure and single-threaded: time comes in as ``now`` (host monotonic seconds) and the robot cycle is the
clock. The controller keeps one setpoint (position, velocity, acceleration) while it commands motion;
every mode change continues from that setpoint so commanded motion stays jerk-limited, and when nothing
is commanded the setpoint is forgotten, so new motion starts from the measured pose and never resumes
toward a stale target.

``MotionController`` is the one façade the daemon uses. It owns the mode (what runs: idle, a goal, a
stream, a stop, a passthrough goal), the dispatch of each ``tick`` to the part that runs, and every
change of mode; the parts do the work: ``intake`` checks a request and completes it, ``goal_run``
executes one goal, ``streams`` follows joint streams (braking near the limits, the deadman),
``stopping`` ramps to rest and holds a succeeded goal's point, ``online`` is the ruckig plumbing both
use, ``setpoint`` the state they share, and ``ledger`` keeps the results, feedback and counters.

Policies (documented contracts):

* ``cancel`` and ``stop`` emit the goal's result at once; the jerk-limited stop runs afterwards (a new
  goal or stream may take over from that stop without a jump).
* Feedback ``desired`` is the setpoint commanded on the previous cycle, the one the measurement is
  compared with (the robot lags one cycle), so ``error`` is the tracking error the path check sees.
* A path-tolerance violation or a robot that stops being ready aborts to IDLE at once, without a stop
  ramp: the robot is not following the setpoint, so ramping it down would command a pose it is not at.
* Streams are not slowed by ``speed_scaling`` (the client owns their timing); goals are: their time
  scaling follows it smoothly within the joint limits (``control/scaling.py``), so goals are planned
  with a reserve of acceleration and jerk (``plan_limits``) and a step of the slider takes ~1-3 s.
* A goal whose last point has a non-zero velocity gets its result when it reaches the goal tolerance,
  then a jerk-limited stop continues from that motion.
"""

from __future__ import annotations

from collections.abc import Generator, Sequence
from typing import cast

from urdaemon.control.busy import (
    STREAMS,
    Mode,
    check_at_rest,
    check_can_start,
    check_still,
    check_stream_command,
)
from urdaemon.control.cartesian import CartesianLimits
from urdaemon.control.goal_run import GoalRun
from urdaemon.control.goal_types import GoalFeedback, GoalResult, GoalStatus, Tolerances, TrajectoryPoint
from urdaemon.control.intake import GoalIntake, GoalTolerances
from urdaemon.control.ledger import ControllerStatistics, GoalLedger
from urdaemon.control.online import OnlineGenerator
from urdaemon.control.planned import ReadyPlan, plan_seed
from urdaemon.control.planned_trajectory import PlannedTrajectory
from urdaemon.control.scaling import planning_limits
from urdaemon.control.setpoint import Setpoint, write_idle
from urdaemon.control.stopping import StopRamp
from urdaemon.control.streams import STREAM_EXPIRED, StreamFollower
from urdaemon.control.trajectory import TrajectoryPlanner
from urdaemon.control.twist import TwistFollower
from urdaemon.description.arm import ArmKinematics
from urdaemon.description.ik_types import run_steps
from urdaemon.model import JointCommand, JointLimits, RobotState

__all__ = [
    "ControllerStatistics",
    "MotionController",
]


def _check_settings(
    period: float,
    path_tolerance: float,
    goal_tolerance: float,
    goal_time_tolerance: float,
    stream_timeout: float,
    feedback_period: float,
) -> None:
    """Refuse a controller setting out of range, naming it."""
    for label, value in (
        ("period", period),
        ("path_tolerance", path_tolerance),
        ("goal_tolerance", goal_tolerance),
        ("stream_timeout", stream_timeout),
    ):
        if not (value > 0.0):
            raise ValueError(f"MotionController: {label} must be > 0, got {value}")
    for label, value in (
        ("goal_time_tolerance", goal_time_tolerance),
        ("feedback_period", feedback_period),
    ):
        if not (value >= 0.0):
            raise ValueError(f"MotionController: {label} must be >= 0, got {value}")


class MotionController:
    """Executes trajectory goals, point-to-point moves and joint streams for one robot."""

    def __init__(
        self,
        limits: JointLimits,
        *,
        period: float,
        path_tolerance: float = 0.2,
        goal_tolerance: float = 0.01,
        goal_time_tolerance: float = 1.0,
        stream_timeout: float = 0.2,
        feedback_period: float = 0.1,
    ) -> None:
        _check_settings(
            period, path_tolerance, goal_tolerance, goal_time_tolerance, stream_timeout, feedback_period
        )
        n = limits.dof
        self.limits = limits
        self.plan_limits = planning_limits(limits)
        """The limits goals are planned with: ``limits`` less the reserves the speed scaling needs."""
        self.joint_names: tuple[str, ...] = limits.names
        defaults = GoalTolerances((path_tolerance,) * n, (goal_tolerance,) * n, goal_time_tolerance)
        self._intake = GoalIntake(limits, self.plan_limits, defaults)
        self._mode = Mode.IDLE
        self._goal: GoalRun | None = None
        self._setpoint = Setpoint(limits, self.plan_limits, period)
        online = OnlineGenerator(limits, period, self._setpoint)
        self._streams = StreamFollower(limits, period, stream_timeout, online, self._setpoint)
        self._stop = StopRamp(period, online, self._setpoint)
        self._twist = TwistFollower(limits, period, self._streams, self._setpoint)
        self._ledger = GoalLedger(
            self._setpoint, period=period, feedback_period=feedback_period, names=self.joint_names
        )
        # the ledger's lists, looked up every cycle
        self._events = self._ledger.events
        self._released = self._ledger.released
        self._meas = [0.0] * n
        self._ticks = 0

    # ------------------------------------------------------------------ queries

    @property
    def active_goal_id(self) -> str | None:
        """The id of the executing goal, or None."""
        return self._goal.goal_id if self._goal is not None else None

    @property
    def has_events(self) -> bool:
        """True when feedback or results wait to be drained (cheap: checked every cycle)."""
        return bool(self._events)

    @property
    def mode(self) -> str:
        """What runs: idle, goal, stream_position, stream_velocity, stream_twist, stopping or external
        (passthrough)."""
        return self._mode.value

    def statistics(self) -> ControllerStatistics:
        """A snapshot of the counters."""
        return self._ledger.statistics(self._ticks)

    def drain_events(self) -> list[GoalFeedback | GoalResult]:
        """Feedback and results emitted since the last drain, oldest first."""
        return self._ledger.drain()

    # ------------------------------------------------------------------ goals

    def check_trajectory(
        self, joint_names: Sequence[str], points: Sequence[TrajectoryPoint], state: RobotState
    ) -> Generator[None, None, TrajectoryPlanner]:
        """Validate a trajectory in steps (a generator, a few µs a step); it returns the planner that
        can plan the tail (``tail_steps()``) before accepting. The same refusals, in the same order, as
        ``prepare_trajectory``; nothing changes in the controller."""
        return self._intake.check_steps(tuple(joint_names), points, lambda: self._goal_seed(state)[0])

    def prepare_trajectory(
        self, joint_names: Sequence[str], points: Sequence[TrajectoryPoint], state: RobotState
    ) -> TrajectoryPlanner:
        """Validate a trajectory at once; its planner can plan the tail (``tail_steps()``) before
        accepting."""
        return run_steps(self.check_trajectory(joint_names, points, state))

    def accept_trajectory(
        self,
        goal_id: str,
        joint_names: Sequence[str],
        points: Sequence[TrajectoryPoint],
        state: RobotState,
        now: float,
        *,
        tolerances: Tolerances | None = None,
        preempt: bool = False,
        planner: TrajectoryPlanner | None = None,
    ) -> float:
        """Plan and start a trajectory goal; returns its planned duration, raises GoalRejected.

        ``planner`` (from ``prepare_trajectory`` for the same points) may carry an already planned tail.
        """
        check_can_start(self._mode, self._goal, self._streams, goal_id, state, now, preempt)
        if planner is None:
            planner = self.prepare_trajectory(joint_names, points, state)
        self._intake.check_planner(planner)
        resolved = self._intake.tolerances(tolerances)
        seed = self._goal_seed(state)
        plan = planner.finish(*seed)
        return self._start_goal(goal_id, plan, resolved, seed, state)

    def accept_move(
        self,
        goal_id: str,
        joint_names: Sequence[str],
        positions: Sequence[float],
        state: RobotState,
        now: float,
        *,
        duration: float | None = None,
        velocity_scale: float = 1.0,
        acceleration_scale: float = 1.0,
        tolerances: Tolerances | None = None,
        preempt: bool = False,
    ) -> float:
        """Plan and start a point-to-point move; returns its planned duration, raises GoalRejected."""
        check_can_start(self._mode, self._goal, self._streams, goal_id, state, now, preempt)
        resolved = self._intake.tolerances(tolerances)
        seed = self._goal_seed(state)
        intake = self._intake
        plan = intake.plan_move(joint_names, positions, seed, duration, velocity_scale, acceleration_scale)
        return self._start_goal(goal_id, plan, resolved, seed, state)

    def accept_planned(
        self,
        goal_id: str,
        plan: ReadyPlan,
        state: RobotState,
        now: float,
        *,
        tolerances: Tolerances | None = None,
    ) -> float:
        """Start ``plan``, made where the robot rests (``goal_start``); returns its duration. Refused
        (GoalRejected) when busy as ``accept_move`` is without preempting, when the robot moves, or when
        the plan does not start at rest within ``PLAN_START_TOLERANCE`` of where a new goal starts now."""
        check_can_start(self._mode, self._goal, self._streams, goal_id, state, now, False)
        check_at_rest(self._mode, self._goal, self._setpoint.at_rest(), "a planned goal starts from rest")
        seed = plan_seed(plan, self.goal_start(state)[0], self.joint_names)
        resolved = self._intake.tolerances(tolerances)
        self._go_idle()  # a stop holding still lets go: the plan starts from rest, at its start
        return self._start_goal(goal_id, cast(PlannedTrajectory, plan), resolved, seed, state)

    def goal_start(self, state: RobotState) -> tuple[list[float], bool]:
        """The joints a new goal starts from (the setpoint while we command motion, else the measured
        pose), and whether the robot is at rest there (idle, or a stop holding still)."""
        mode = self._mode
        return self._setpoint.goal_start(state, mode is Mode.IDLE, mode is Mode.STOPPING or mode is Mode.GOAL)

    def accept_external(
        self,
        goal_id: str,
        planner: TrajectoryPlanner,
        state: RobotState,
        now: float,
        *,
        tolerances: Tolerances | None = None,
    ) -> float:
        """Start a goal the robot executes itself (passthrough); planned here only to check and to report.

        The robot follows its own interpolation, so no path tolerance applies; the goal ends with
        ``finish_external`` (the robot's result), a cancel, a stop, or the robot becoming not ready.
        """
        self.release_hold()
        check_at_rest(self._mode, self._goal, False, "a passthrough trajectory starts from rest")
        check_can_start(self._mode, self._goal, self._streams, goal_id, state, now, False)
        self._intake.check_planner(planner)
        resolved = self._intake.tolerances(tolerances).without_path()
        plan = planner.finish(*self._goal_seed(state))  # from rest: idle
        self._setpoint.rest_at(state.positions)
        self._goal = self._ledger.open(goal_id, plan, resolved)
        self._mode = Mode.EXTERNAL
        self._streams.forget()
        return plan.duration

    def finish_external(self, goal_id: str, status: GoalStatus, reason: str, state: RobotState) -> bool:
        """End the passthrough goal ``goal_id`` as the robot reported; False if it is not the active one.

        A reported success with a joint outside the goal tolerance ends ABORTED, naming the joint.
        """
        goal = self._goal
        if goal is None or goal.goal_id != goal_id or self._mode is not Mode.EXTERNAL:
            return False
        status, reason = goal.robot_ended(status, reason, state.positions)
        self._finish_goal(status, reason, state.positions)
        self._go_idle()
        return True

    def check_can_start(self, state: RobotState, now: float, preempt: bool) -> None:
        """Raise GoalRejected if a goal could not start now (not ready, busy); nothing changes."""
        check_can_start(self._mode, self._goal, self._streams, "", state, now, preempt)

    def cancel(self, goal_id: str | None = None) -> bool:
        """Cancel the executing goal (or only ``goal_id``); False if no such goal. Result now, then a stop."""
        goal = self._goal
        if goal is None or (goal_id is not None and goal_id != goal.goal_id):
            return False
        self._end_goal_now(GoalStatus.CANCELED, "canceled by request")
        return True

    def stop(self, reason: str, now: float) -> None:
        """Bring whatever runs to a jerk-limited stop; an executing goal ends ABORTED with ``reason`` now."""
        if self._goal is not None:
            self._end_goal_now(GoalStatus.ABORTED, reason)
        elif self._mode in STREAMS:
            self._enter_stopping()
        # Commands of a stopped stream must not keep it "active" for busy checks.
        self._streams.forget()

    def abort(self, reason: str) -> None:
        """End whatever runs at once and go idle, forgetting the setpoint (the robot is gone or stopped).

        An executing goal ends ABORTED with ``reason``. No stop ramp is commanded: after a link loss or
        a restart the robot is not following our setpoint, so the next motion seeds from the measured pose.
        """
        if self._goal is not None:
            self._finish_goal(GoalStatus.ABORTED, reason, self._meas)
        self._go_idle()

    def _end_goal_now(self, status: GoalStatus, reason: str) -> None:
        """End the goal as asked: its result now, then a stop (the robot stops a passthrough itself)."""
        self._finish_goal(status, reason, self._meas)
        if self._mode is Mode.EXTERNAL:
            self._go_idle()
        else:
            self._enter_stopping()

    def release_hold(self) -> None:
        """Go idle now if all that runs is the hold of a succeeded goal's final point (freedrive and
        passthrough start from rest, and waiting for the robot to settle must not refuse them)."""
        if self._mode is Mode.STOPPING and self._stop.only_holding:
            self._go_idle()

    # ------------------------------------------------------------------ streams

    def stream_positions(
        self,
        joint_names: Sequence[str],
        positions: Sequence[float],
        velocities: Sequence[float] | None,
        state: RobotState,
        now: float,
    ) -> None:
        """Make ``positions`` (and ``velocities`` there, if given) the newest streaming target."""
        start = check_stream_command(self._mode, self._goal, state)
        perm = self._intake.permutation(joint_names)
        self._streams.follow_positions(perm, positions, velocities, start, now)
        self._mode = Mode.STREAM_POSITION
        self._ledger.stream_commands += 1

    def stream_velocities(
        self, joint_names: Sequence[str], velocities: Sequence[float], state: RobotState, now: float
    ) -> None:
        """Make ``velocities`` the newest streaming target velocity (limits are guarded every cycle)."""
        start = check_stream_command(self._mode, self._goal, state)
        perm = self._intake.permutation(joint_names)
        self._streams.follow_velocities(perm, velocities, start, self._mode is not Mode.STREAM_VELOCITY, now)
        self._mode = Mode.STREAM_VELOCITY
        self._ledger.stream_commands += 1

    def stream_twist(self, twist: Sequence[float], frame: str, state: RobotState, now: float) -> None:
        """Make ``twist`` (vx, vy, vz, wx, wy, wz: m/s, rad/s) in ``frame`` ("base" or "tool") the newest
        twist target; refused without ``set_arm``, above the caps, or when a joint stream's would be."""
        start = check_stream_command(self._mode, self._goal, state)
        self._twist.follow(twist, frame, start, self._mode is not Mode.STREAM_TWIST, now)
        self._mode = Mode.STREAM_TWIST
        self._ledger.stream_commands += 1

    def release(self) -> None:
        """Let go of every ruckig object and goal plan (served no more: ``Daemon.release``); unusable then."""
        self._goal, self._released[:] = None, []
        self._streams.release()  # and the online generator it shares with the stop ramp
        self._twist.release()

    def set_arm(self, kin: ArmKinematics | None, twist: CartesianLimits) -> None:
        """The arm's kinematics (None: no Cartesian commands); twist speeds capped, smoothed by ``twist``."""
        self._twist.set_arm(kin, twist)

    @property
    def tcp(self) -> tuple[float, ...]:
        """The TCP offset (flange -> TCP pose) every Cartesian command uses."""
        return self._twist.tcp

    def set_tcp(self, tcp: Sequence[float]) -> None:
        """Make ``tcp`` the TCP offset; refused (GoalRejected) unless the robot rests."""
        check_still(self._mode, self._goal, self._setpoint.at_rest(), "set_tcp: the robot is moving")
        self._twist.set_tcp(tcp)

    # ------------------------------------------------------------------ the cycle

    def tick(self, state: RobotState, command: JointCommand, now: float) -> None:
        """Advance one robot cycle and write this cycle's command into ``command``."""
        self._ticks += 1
        if self._released:
            self._ledger.release_some()
        self._meas[:] = state.positions
        mode = self._mode
        if mode is Mode.IDLE:
            write_idle(command, state.positions, self._setpoint.zeros)
            return
        if not state.ready_for_motion:
            if self._goal is not None:
                self._finish_goal(GoalStatus.ABORTED, state.not_ready_reason(), state.positions)
            self._idle_now(state, command)
            return
        if mode is Mode.GOAL:
            goal = self._goal
            assert goal is not None
            ended = goal.tick(state, command, now)
            if ended is not None:
                self._finish_goal(ended.status, ended.reason, state.positions)
                self._end_motion(state, command, ramp=ended.ramp, hold=ended.status is GoalStatus.SUCCEEDED)
        elif mode is Mode.STOPPING:
            self._tick_stopping(state, command)
        elif mode is Mode.EXTERNAL:
            goal = self._goal
            assert goal is not None
            goal.follow_robot(state, command, now)
        else:
            if mode is Mode.STREAM_POSITION:
                stream_ended = self._streams.tick_positions(command, now)
            elif mode is Mode.STREAM_TWIST:
                stream_ended = self._twist.tick(command, now)
            else:
                stream_ended = self._streams.tick_velocities(command, now)
            if stream_ended:
                # the deadman stops the stream; a failed step leaves it idle at once
                expired = stream_ended == STREAM_EXPIRED
                if expired:
                    self._ledger.deadman_stops += 1
                self._end_motion(state, command, ramp=expired, hold=False)

    def _end_motion(self, state: RobotState, command: JointCommand, *, ramp: bool, hold: bool) -> None:
        """What ran ended this cycle: a stop ramp follows (holding a succeeded goal's point), or idle."""
        if ramp:
            self._enter_stopping(hold=hold)
            self._tick_stopping(state, command)
        else:
            self._idle_now(state, command)

    def _tick_stopping(self, state: RobotState, command: JointCommand) -> None:
        if not self._stop.tick(state, command):
            self._idle_now(state, command)

    def _idle_now(self, state: RobotState, command: JointCommand) -> None:
        self._go_idle()
        write_idle(command, state.positions, self._setpoint.zeros)

    # ------------------------------------------------------------------ helpers

    def _goal_seed(self, state: RobotState) -> tuple[list[float], list[float], list[float]]:
        mode = self._mode
        return self._setpoint.goal_seed(state, idle=mode is Mode.IDLE, in_goal=mode is Mode.GOAL)

    def _start_goal(
        self,
        goal_id: str,
        plan: PlannedTrajectory,
        tolerances: GoalTolerances,
        seed: tuple[list[float], list[float], list[float]],
        state: RobotState,
    ) -> float:
        """Start the goal planned as ``plan`` from ``seed``, preempting a running one; its duration."""
        if self._goal is not None:
            self._finish_goal(GoalStatus.PREEMPTED, f"preempted by goal {goal_id}", state.positions)
        mode = self._mode
        self._setpoint.start_goal(
            seed, state.speed_scaling, at_rest=mode is Mode.IDLE, after_goal=mode is Mode.GOAL
        )
        self._goal = self._ledger.open(goal_id, plan, tolerances)
        self._mode = Mode.GOAL
        self._streams.forget()
        return plan.duration

    def _finish_goal(self, status: GoalStatus, reason: str, measured: Sequence[float]) -> None:
        goal = self._goal
        assert goal is not None
        self._goal = None
        self._ledger.close(goal, status, reason, measured)

    def _enter_stopping(self, *, hold: bool = False) -> None:
        """Switch to a jerk-limited stop from the current setpoint (a goal's is first made real-time);
        ``hold``: a succeeded goal's final point is then held until the robot settles on it."""
        mode = self._mode
        if mode is Mode.IDLE or mode is Mode.STOPPING:
            return
        self._stop.start(hold=hold, after_goal=mode is Mode.GOAL)
        self._mode = Mode.STOPPING
        self._streams.forget()

    def _go_idle(self) -> None:
        # Forgetting the setpoint is implicit: IDLE seeds every new motion from the measured state.
        self._mode = Mode.IDLE
        self._streams.forget()
