"""The per-robot motion controller: executes goals and joint streams, one ``tick`` per robot cycle.

Pure and single-threaded: time comes in as ``now`` (host monotonic seconds) and the robot cycle is the
clock. The controller keeps one setpoint (position, velocity, acceleration) while it commands motion;
every mode change continues from that setpoint so commanded motion stays jerk-limited, and when nothing
is commanded the setpoint is forgotten, so new motion starts from the measured pose and never resumes
toward a stale target.

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

import enum
import functools
import math
from collections.abc import Generator, Sequence
from dataclasses import dataclass
from typing import Any

from ruckig import (
    ControlInterface,
    InputParameter,
    OutputParameter,
    Result,
    Ruckig,
    Synchronization,
)

from urdaemon.control.goals import GoalFeedback, GoalResult, GoalStatus, Tolerances, TrajectoryPoint
from urdaemon.control.limits import (
    BRAKE_DOWN,
    BRAKE_UP,
    apply_permutation,
    braking_needed,
    check_finite,
    check_positions_within,
    check_velocities_within,
    joint_permutation,
    stopping_distance,
)
from urdaemon.control.scaling import (
    SLIDER_ACCELERATION_RESERVE,
    TimeScaling,
    clamp_scaling,
    planning_limits,
)
from urdaemon.control.trajectory import (
    MAX_GOAL_TIME_S,
    RUCKIG_ERRORS,
    PlannedTrajectory,
    TrajectoryCheck,
    TrajectoryPlanner,
    check_points,
    plan_move,
    position_extrema,
    run_robustly,
)
from urdaemon.errors import GoalRejected
from urdaemon.model import CommandMode, JointCommand, JointLimits, RobotState

__all__ = ["MAX_JOINT_TOLERANCE", "ControllerStatistics", "MotionController"]

_WORKING = Result.Working
_FINISHED = Result.Finished
_POSITION = ControlInterface.Position
_VELOCITY = ControlInterface.Velocity

# Converting a real-time setpoint into trajectory time divides by the speed scaling; below this floor
# the division would only produce huge values that ruckig then brakes anyway.
_MIN_SEED_SCALING = 0.05
# Trajectory time that counts as "at the end" despite float accumulation of period × scaling.
_END_EPS = 1e-9
_EXTREMA_EPS = 1e-9
_PERM_CACHE_SIZE = 32
RELEASE_SEGMENTS = 64
"""Segments of a finished goal's plan freed per tick (~20 µs): freeing a 5 000-point plan at once
would hold the loop for ~1.5 ms."""
SETTLE_POSITION = 2e-5
"""rad: how close every joint must be to a succeeded goal's final point for the hold to end."""
SETTLE_VELOCITY = 1e-3
"""rad/s: how slowly every joint must move for the hold to end."""
SETTLE_TIME = 1.0
"""s: how long the final point of a succeeded goal is held at most for the robot to settle on it. A
robot follows its setpoint with a lag (a UR's servoj: lookahead time × speed), so letting go when the
goal tolerance is met would leave it wherever the lag had it (the tolerance, not the target); UR's ROS 2
driver holds the last point for the same reason. Only after success: a stop, cancel or deadman lets go
once its ramp has ended, as a robot that cannot reach a point must not be pushed toward it."""
MAX_JOINT_TOLERANCE = 2.0 * math.pi
"""Largest finite path or goal tolerance of a joint (rad): one turn; infinity switches the check off."""


class _Mode(enum.Enum):
    IDLE = "idle"
    GOAL = "goal"
    STREAM_POSITION = "stream_position"
    STREAM_VELOCITY = "stream_velocity"
    STOPPING = "stopping"
    EXTERNAL = "external"
    """A goal the robot interpolates itself (passthrough): we hold still and wait for its result."""


@dataclass(frozen=True, slots=True)
class ControllerStatistics:
    """Counters since the controller was created."""

    ticks: int
    goals_accepted: int
    goals_succeeded: int
    goals_aborted: int
    goals_canceled: int
    goals_preempted: int
    stream_commands: int
    deadman_stops: int


class _Goal:
    """Book-keeping of the executing goal."""

    __slots__ = (
        "duration",
        "end_now",
        "final",
        "goal_id",
        "goal_time",
        "goal_tol",
        "next_feedback",
        "path_tol",
        "plan",
        "t",
    )

    def __init__(
        self,
        goal_id: str,
        plan: PlannedTrajectory,
        path_tol: tuple[float, ...],
        goal_tol: tuple[float, ...],
        goal_time: float,
    ) -> None:
        self.goal_id = goal_id
        self.plan = plan
        self.duration = plan.duration
        self.final = plan.final_positions
        self.path_tol = path_tol
        self.goal_tol = goal_tol
        self.goal_time = goal_time
        self.t = 0.0
        self.end_now: float | None = None
        self.next_feedback = -math.inf


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
        self._n = n
        self._period = period
        self._path_tolerance = path_tolerance
        self._goal_tolerance = goal_tolerance
        self._goal_time_tolerance = goal_time_tolerance
        self._stream_timeout = stream_timeout
        self._feedback_period = feedback_period
        self._init_limits(limits, period)

        self._mode = _Mode.IDLE
        self._goal: _Goal | None = None
        # The setpoint in real time units: what was commanded last cycle, and its derivatives.
        self._pos = [0.0] * n
        self._vel = [0.0] * n
        self._acc = [0.0] * n
        # The goal's sample in trajectory time units (velocity/acceleration before speed scaling).
        self._pvel = [0.0] * n
        self._pacc = [0.0] * n
        # The goal's time scaling: follows the robot's speed_scaling within the joint limits.
        self._scaling = TimeScaling(limits, self.plan_limits, period)
        self._meas = [0.0] * n
        self._zeros = [0.0] * n

        self._init_online(limits, period)
        self._hold = False
        """The stop that runs holds a succeeded goal's final point until the robot settles on it."""
        self._ramp_done = False
        """The stop's ramp has ended (only a hold keeps the controller out of IDLE)."""
        self._settle_ticks = 0
        self._settle_limit = max(1, round(SETTLE_TIME / period))

        self._events: list[GoalFeedback | GoalResult] = []
        # Plans of ended goals, freed RELEASE_SEGMENTS a tick.
        self._released: list[PlannedTrajectory] = []
        self._perm_cache: dict[tuple[str, ...], tuple[int, ...]] = {}
        self._init_counters()

    def _init_limits(self, limits: JointLimits, period: float) -> None:
        """The joint limits as lists for the per-cycle checks, and the distance that needs no braking."""
        self._lo = list(limits.min_position)
        self._hi = list(limits.max_position)
        self._vmax = list(limits.max_velocity)
        self._amax = list(limits.max_acceleration)
        self._jmax = list(limits.max_jerk)
        # Beyond this distance from both limits no stop from any admissible state can reach a limit,
        # so the per-cycle braking check is skipped (the common case, far from the limits).
        self._safe_distance = [
            stopping_distance(v + a * period, a, a, j) + 2.0 * v * period + 1e-6
            for v, a, j in zip(self._vmax, self._amax, self._jmax, strict=True)
        ]

    def _init_online(self, limits: JointLimits, period: float) -> None:
        """The online (ruckig) follower of streams and stops, and the stream's per-joint state."""
        n = limits.dof
        self._otg: Any = Ruckig(n, period)
        self._inp: Any = InputParameter(n)
        self._out: Any = OutputParameter(n)
        # bound once: the online update runs every tick and must not build a closure each time
        self._update = functools.partial(self._otg.update, self._inp, self._out)
        self._inp.max_velocity = list(limits.max_velocity)
        self._inp.max_acceleration = list(limits.max_acceleration)
        self._inp.max_jerk = list(limits.max_jerk)
        self._inp.synchronization = Synchronization.No
        self._per_dof_active = False
        self._braking = [False] * n
        self._stream_target = [0.0] * n
        self._stream_target_velocity = [0.0] * n
        self._stream_velocity = [0.0] * n
        self._effective_velocity = [0.0] * n
        self._latch = [0] * n
        self._last_stream_now = -math.inf

    def _init_counters(self) -> None:
        """The statistics' counters, all zero."""
        self._ticks = 0
        self._goals_accepted = 0
        self._goals_succeeded = 0
        self._goals_aborted = 0
        self._goals_canceled = 0
        self._goals_preempted = 0
        self._stream_commands = 0
        self._deadman_stops = 0

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
        """What the controller is doing: idle, goal, stream_position, stream_velocity or stopping."""
        return self._mode.value

    def statistics(self) -> ControllerStatistics:
        """A snapshot of the counters."""
        return ControllerStatistics(
            ticks=self._ticks,
            goals_accepted=self._goals_accepted,
            goals_succeeded=self._goals_succeeded,
            goals_aborted=self._goals_aborted,
            goals_canceled=self._goals_canceled,
            goals_preempted=self._goals_preempted,
            stream_commands=self._stream_commands,
            deadman_stops=self._deadman_stops,
        )

    def drain_events(self) -> list[GoalFeedback | GoalResult]:
        """Feedback and results emitted since the last drain, oldest first."""
        events = self._events
        self._events = []
        return events

    # ------------------------------------------------------------------ goals

    def check_trajectory(
        self, joint_names: Sequence[str], points: Sequence[TrajectoryPoint], state: RobotState
    ) -> TrajectoryCheck:
        """Validate a trajectory in steps (``step(count)``, a few µs a step, until False); its result is
        the planner that can plan the tail (``plan_next()``) before accepting. The same refusals, in
        the same order, as ``prepare_trajectory``; nothing changes in the controller."""
        return TrajectoryCheck(self._check_steps(tuple(joint_names), points, state))

    def prepare_trajectory(
        self, joint_names: Sequence[str], points: Sequence[TrajectoryPoint], state: RobotState
    ) -> TrajectoryPlanner:
        """Validate a trajectory at once; its planner can plan the tail (``plan_next()``) before accepting."""
        return self.check_trajectory(joint_names, points, state).run()

    def _check_steps(
        self, joint_names: tuple[str, ...], points: Sequence[TrajectoryPoint], state: RobotState
    ) -> Generator[None, None, TrajectoryPlanner]:
        perm = self._permutation(joint_names)
        if not points:
            raise GoalRejected("the trajectory has no points")
        mapped: list[TrajectoryPoint] = []
        for k, pt in enumerate(points):
            mapped.append(_mapped_point(perm, k, pt))
            yield
        del points  # the caller may free the sender's points from here on
        for k, pt in enumerate(mapped):
            self._check_point_accelerations(k, pt)
            yield
        seed_p, _, _ = self._goal_seed(state)
        return (yield from check_points(mapped, self.plan_limits, seed_p))

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
        self._check_can_start(goal_id, state, now, preempt)
        if planner is None:
            planner = self.prepare_trajectory(joint_names, points, state)
        elif planner.limits is not self.plan_limits:
            raise ValueError("the planner was prepared by another controller")
        path_tol, goal_tol, goal_time = self._resolve_tolerances(tolerances)
        seed_p, seed_v, seed_a = self._goal_seed(state)
        plan = planner.finish(seed_p, seed_v, seed_a)
        self._start_goal(goal_id, plan, path_tol, goal_tol, goal_time, seed_p, seed_v, seed_a, state)
        return plan.duration

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
        if self._goal is not None:
            raise GoalRejected(
                f"busy: goal {self._goal.goal_id} is running; a passthrough trajectory starts from rest"
            )
        if self._mode is not _Mode.IDLE:
            raise GoalRejected(
                f"busy: the robot is {self._mode.value.replace('_', ' ')}; a passthrough trajectory starts "
                "from rest"
            )
        self._check_can_start(goal_id, state, now, False)
        if planner.limits is not self.plan_limits:
            raise ValueError("the planner was prepared by another controller")
        path_tol, goal_tol, goal_time = self._resolve_tolerances(tolerances)
        zeros = [0.0] * self._n
        plan = planner.finish(list(state.positions), zeros, zeros)
        self._pos[:] = state.positions
        self._vel[:] = self._zeros
        self._acc[:] = self._zeros
        self._goal = _Goal(goal_id, plan, tuple(math.inf for _ in path_tol), goal_tol, goal_time)
        self._mode = _Mode.EXTERNAL
        self._last_stream_now = -math.inf
        self._goals_accepted += 1
        return plan.duration

    def finish_external(self, goal_id: str, status: GoalStatus, reason: str, state: RobotState) -> bool:
        """End the passthrough goal ``goal_id`` as the robot reported; False if it is not the active one.

        A reported success with a joint outside the goal tolerance ends ABORTED, naming the joint.
        """
        goal = self._goal
        if goal is None or goal.goal_id != goal_id or self._mode is not _Mode.EXTERNAL:
            return False
        if status is GoalStatus.SUCCEEDED:
            for i, (final, actual) in enumerate(zip(goal.final, state.positions, strict=True)):
                if abs(final - actual) > goal.goal_tol[i]:
                    status = GoalStatus.ABORTED
                    reason = (
                        f"the robot reported success but {self.joint_names[i]} is {final - actual:.4g} "
                        f"from its goal (tolerance {goal.goal_tol[i]:.4g})"
                    )
                    break
        self._pos[:] = goal.final
        self._finish_goal(status, reason, state.positions)
        self._go_idle()
        return True

    @property
    def external_goal_id(self) -> str | None:
        """The id of the running passthrough goal, or None."""
        return self._goal.goal_id if self._goal is not None and self._mode is _Mode.EXTERNAL else None

    def check_can_start(self, state: RobotState, now: float, preempt: bool) -> None:
        """Raise GoalRejected if a goal could not start now (not ready, busy); nothing changes."""
        self._check_can_start("", state, now, preempt)

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
        self._check_can_start(goal_id, state, now, preempt)
        perm = self._permutation(joint_names)
        target = apply_permutation(perm, positions, "positions")
        path_tol, goal_tol, goal_time = self._resolve_tolerances(tolerances)
        seed_p, seed_v, seed_a = self._goal_seed(state)
        plan = plan_move(
            seed_p,
            seed_v,
            seed_a,
            target,
            self.plan_limits,
            duration=duration,
            velocity_scale=velocity_scale,
            acceleration_scale=acceleration_scale,
        )
        self._start_goal(goal_id, plan, path_tol, goal_tol, goal_time, seed_p, seed_v, seed_a, state)
        return plan.duration

    def cancel(self, goal_id: str | None = None) -> bool:
        """Cancel the executing goal (or only ``goal_id``); False if no such goal. Result now, then a stop."""
        goal = self._goal
        if goal is None or (goal_id is not None and goal_id != goal.goal_id):
            return False
        self._finish_goal(GoalStatus.CANCELED, "canceled by request", self._meas)
        if self._mode is _Mode.EXTERNAL:
            self._go_idle()  # the robot stops its own trajectory on CANCEL
        else:
            self._enter_stopping()
        return True

    def stop(self, reason: str, now: float) -> None:
        """Bring whatever runs to a jerk-limited stop; an executing goal ends ABORTED with ``reason`` now."""
        if self._goal is not None:
            self._finish_goal(GoalStatus.ABORTED, reason, self._meas)
            if self._mode is _Mode.EXTERNAL:
                self._go_idle()
            else:
                self._enter_stopping()
        elif self._mode is _Mode.STREAM_POSITION or self._mode is _Mode.STREAM_VELOCITY:
            self._enter_stopping()
        # Commands of a stopped stream must not keep it "active" for busy checks.
        self._last_stream_now = -math.inf

    def abort(self, reason: str) -> None:
        """End whatever runs at once and go idle, forgetting the setpoint (the robot is gone or stopped).

        An executing goal ends ABORTED with ``reason``. No stop ramp is commanded: after a link loss or
        a restart the robot is not following our setpoint, so the next motion seeds from the measured pose.
        """
        if self._goal is not None:
            self._finish_goal(GoalStatus.ABORTED, reason, self._meas)
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
        self._check_can_stream(state)
        perm = self._permutation(joint_names)
        limits = self.limits
        target = apply_permutation(perm, positions, "positions")
        check_finite("positions", target, self.joint_names)
        check_positions_within(limits, target, "stream target")
        tvel = self._zeros
        if velocities is not None:
            given = apply_permutation(perm, velocities, "velocities")
            check_finite("velocities", given, self.joint_names)
            check_velocities_within(limits, given, "stream target")
            tvel = list(given)
            safe = self._safe_distance
            for i in range(self._n):
                v = tvel[i]
                q = target[i]
                if v == 0.0 or (q + safe[i] < self._hi[i] and q - safe[i] > self._lo[i]):
                    continue
                # Coasting on at the target velocity must still be able to stop inside the limits.
                mask = braking_needed(
                    target[i], v, 0.0, self._lo[i], self._hi[i], self._amax[i], self._jmax[i], self._period
                )
                if (v > 0.0 and mask & BRAKE_UP) or (v < 0.0 and mask & BRAKE_DOWN):
                    tvel[i] = 0.0
        self._begin_stream(state)
        inp = self._inp
        inp.control_interface = _POSITION
        self._clear_braking()
        self._stream_target[:] = target
        self._stream_target_velocity[:] = tvel
        inp.target_position = self._stream_target
        inp.target_velocity = tvel
        inp.target_acceleration = self._zeros
        self._mode = _Mode.STREAM_POSITION
        self._last_stream_now = now
        self._stream_commands += 1

    def stream_velocities(
        self, joint_names: Sequence[str], velocities: Sequence[float], state: RobotState, now: float
    ) -> None:
        """Make ``velocities`` the newest streaming target velocity (limits are guarded every cycle)."""
        self._check_can_stream(state)
        perm = self._permutation(joint_names)
        target = apply_permutation(perm, velocities, "velocities")
        check_finite("velocities", target, self.joint_names)
        check_velocities_within(self.limits, target, "stream target")
        self._begin_stream(state)
        inp = self._inp
        if self._mode is not _Mode.STREAM_VELOCITY:
            inp.control_interface = _VELOCITY
            self._clear_braking()
            # Forces the first tick to push the effective target into ruckig.
            self._effective_velocity[:] = [math.nan] * self._n
            self._latch[:] = [0] * self._n
        self._stream_velocity[:] = target
        inp.target_acceleration = self._zeros
        self._mode = _Mode.STREAM_VELOCITY
        self._last_stream_now = now
        self._stream_commands += 1

    # ------------------------------------------------------------------ the cycle

    def tick(self, state: RobotState, command: JointCommand, now: float) -> None:
        """Advance one robot cycle and write this cycle's command into ``command``."""
        self._ticks += 1
        if self._released:
            self._release_plans()
        self._meas[:] = state.positions
        mode = self._mode
        if mode is _Mode.IDLE:
            self._write_idle(state, command)
            return
        if not state.ready_for_motion:
            if self._goal is not None:
                self._finish_goal(GoalStatus.ABORTED, state.not_ready_reason(), state.positions)
            self._go_idle()
            self._write_idle(state, command)
            return
        if mode is _Mode.GOAL:
            self._tick_goal(state, command, now)
        elif mode is _Mode.EXTERNAL:
            self._tick_external(state, command, now)
        elif mode is _Mode.STOPPING:
            self._tick_stopping(state, command)
        elif now - self._last_stream_now > self._stream_timeout:
            self._deadman_stops += 1
            self._enter_stopping()
            self._tick_stopping(state, command)
        elif mode is _Mode.STREAM_POSITION:
            self._tick_stream_position(state, command)
        else:
            self._tick_stream_velocity(state, command)

    def _release_plans(self) -> None:
        """Free a few segments of an ended goal's plan (the last ended first)."""
        released = self._released
        if not released[-1].release(RELEASE_SEGMENTS):
            released.pop()

    def _tick_external(self, state: RobotState, command: JointCommand, now: float) -> None:
        """The robot runs the trajectory: command nothing, estimate progress for feedback."""
        goal = self._goal
        assert goal is not None
        goal.t = min(goal.t + self._period * state.speed_scaling, goal.duration)
        self._write_idle(state, command)
        if now >= goal.next_feedback:
            goal.plan.sample(goal.t, self._pos, self._vel, self._acc)
            self._emit_feedback(goal, self._pos, state.positions, now)

    def _emit_feedback(
        self, goal: _Goal, desired: Sequence[float], actual: Sequence[float], now: float
    ) -> None:
        goal.next_feedback = now + self._feedback_period
        want, got = tuple(desired), tuple(actual)
        self._events.append(
            GoalFeedback(
                goal_id=goal.goal_id,
                time_from_start=goal.t,
                duration=goal.duration,
                desired=want,
                actual=got,
                error=tuple(d - a for d, a in zip(want, got, strict=True)),
            )
        )

    def _tick_goal(self, state: RobotState, command: JointCommand, now: float) -> None:
        goal = self._goal
        assert goal is not None
        meas = state.positions
        pos = self._pos
        n = self._n
        # The robot lags one cycle, so compare it with the setpoint commanded last cycle.
        path_tol = goal.path_tol
        for i in range(n):
            err = pos[i] - meas[i]
            if err > path_tol[i] or -err > path_tol[i]:
                self._finish_goal(
                    GoalStatus.ABORTED,
                    f"path tolerance violated: {self.joint_names[i]} is {err:.4g} from its setpoint, "
                    f"tolerance {path_tol[i]:.4g}",
                    meas,
                )
                self._go_idle()
                self._write_idle(state, command)
                return
        if now >= goal.next_feedback:
            self._emit_feedback(goal, pos, meas, now)
        if goal.t >= goal.duration:
            if self._tick_goal_end(goal, state, command, now):
                return
            # Holding the final point: the setpoint stays as it is.
        else:
            scaling = self._scaling
            s = scaling.value
            if s == state.speed_scaling and scaling.rate == 0.0:
                t = goal.t + self._period * s
            else:
                t = goal.t + scaling.advance(state.speed_scaling)
                s = scaling.value
            if t >= goal.duration - _END_EPS:
                t = goal.duration
                goal.end_now = now
            goal.t = t
            goal.plan.sample(t, pos, self._pvel, self._pacc)
            if s == 1.0:
                self._vel[:] = self._pvel
            else:
                vel = self._vel
                pvel = self._pvel
                for i in range(n):
                    vel[i] = pvel[i] * s
        command.mode = CommandMode.POSITION
        command.positions[:] = pos
        command.velocities[:] = self._vel

    def _tick_goal_end(self, goal: _Goal, state: RobotState, command: JointCommand, now: float) -> bool:
        """Past the planned end: succeed within the goal tolerance, abort after the goal time.

        True when the goal ended and this tick's command is written; False while holding the final point.
        """
        if goal.end_now is None:
            goal.end_now = now
        meas = state.positions
        n = self._n
        final = goal.final
        goal_tol = goal.goal_tol
        worst = -1
        for i in range(n):
            if abs(final[i] - meas[i]) > goal_tol[i]:
                worst = i
                break
        if worst < 0:
            self._finish_goal(GoalStatus.SUCCEEDED, "reached the goal within tolerance", meas)
            self._enter_stopping()
            self._hold = True
            self._tick_stopping(state, command)
            return True
        if now - goal.end_now > goal.goal_time:
            err = final[worst] - meas[worst]
            self._finish_goal(
                GoalStatus.ABORTED,
                f"goal tolerance not reached {goal.goal_time:.4g} s after the planned end: "
                f"{self.joint_names[worst]} is {err:.4g} from its goal, tolerance {goal_tol[worst]:.4g}",
                meas,
            )
            self._enter_stopping()
            self._tick_stopping(state, command)
            return True
        return False

    def _check_point_accelerations(self, k: int, pt: TrajectoryPoint) -> None:
        """Refuse client accelerations within a limit but inside the reserve kept for the speed scaling."""
        if pt.accelerations is None:
            return
        planned = self.plan_limits.max_acceleration
        for i, a in enumerate(pt.accelerations):
            if planned[i] < abs(a) <= self._amax[i] * (1.0 + 1e-9):
                share = 100.0 * (1.0 - SLIDER_ACCELERATION_RESERVE)
                raise GoalRejected(
                    f"point {k}: {self.joint_names[i]} acceleration {a:.6g} exceeds {planned[i]:.6g}, "
                    f"{share:.0f} % of its limit {self._amax[i]:.6g}: the rest is kept so the speed "
                    "scaling can change smoothly while a goal runs"
                )

    def _tick_stopping(self, state: RobotState, command: JointCommand) -> None:
        result = self._online_step()
        if result == _FINISHED:
            self._ramp_done = True
        if result is None or (result == _FINISHED and (not self._hold or self._settled(state))):
            self._go_idle()
            self._write_idle(state, command)
            return
        self._write_setpoint(command)

    def release_hold(self) -> None:
        """Go idle now if all that runs is the hold of a succeeded goal's final point (freedrive and
        passthrough start from rest, and waiting for the robot to settle must not refuse them)."""
        if self._mode is _Mode.STOPPING and self._hold and self._ramp_done:
            self._go_idle()

    def _settled(self, state: RobotState) -> bool:
        """Whether the robot rests on the held point, or has been given all the time it gets."""
        self._settle_ticks += 1
        if self._settle_ticks > self._settle_limit:
            return True
        pos = self._pos
        meas = state.positions
        speed = state.velocities
        for i in range(self._n):
            if abs(pos[i] - meas[i]) > SETTLE_POSITION or abs(speed[i]) > SETTLE_VELOCITY:
                return False
        return True

    def _tick_stream_position(self, state: RobotState, command: JointCommand) -> None:
        inp = self._inp
        out = self._out
        self._brake_coasting_joints()
        try:
            result = run_robustly(self._update, inp)
            if out.new_calculation and self._brake_overshooting_joints(out):
                # Same start state, now with those joints braking instead of following the target.
                result = run_robustly(self._update, inp)
        except RUCKIG_ERRORS:
            result = None
        if result != _WORKING and result != _FINISHED:
            self._go_idle()
            self._write_idle(state, command)
            return
        self._accept_output()
        self._write_setpoint(command)

    def _tick_stream_velocity(self, state: RobotState, command: JointCommand) -> None:
        n = self._n
        want = self._stream_velocity
        eff = self._effective_velocity
        latch = self._latch
        pos = self._pos
        vel = self._vel
        acc = self._acc
        safe = self._safe_distance
        lo = self._lo
        hi = self._hi
        vmax = self._vmax
        changed = False
        for i in range(n):
            w = want[i]
            if w > 0.0:
                if latch[i] != 1:
                    latch[i] = 0
                    p = pos[i]
                    if (hi[i] - p <= safe[i] or abs(vel[i]) > vmax[i]) and braking_needed(
                        p, vel[i], acc[i], lo[i], hi[i], self._amax[i], self._jmax[i], self._period
                    ) & BRAKE_UP:
                        # Latched until the client stops asking to go up, so it does not creep on.
                        latch[i] = 1
                if latch[i] == 1:
                    w = 0.0
            elif w < 0.0:
                if latch[i] != -1:
                    latch[i] = 0
                    p = pos[i]
                    if (p - lo[i] <= safe[i] or abs(vel[i]) > vmax[i]) and braking_needed(
                        p, vel[i], acc[i], lo[i], hi[i], self._amax[i], self._jmax[i], self._period
                    ) & BRAKE_DOWN:
                        latch[i] = -1
                if latch[i] == -1:
                    w = 0.0
            else:
                latch[i] = 0
            if w != eff[i]:
                eff[i] = w
                changed = True
        if changed:
            self._inp.target_velocity = eff
        result = self._online_step()
        if result is None:
            self._go_idle()
            self._write_idle(state, command)
            return
        self._write_setpoint(command)

    # ------------------------------------------------------------------ helpers

    def _check_can_start(self, goal_id: str, state: RobotState, now: float, preempt: bool) -> None:
        if not state.ready_for_motion:
            raise GoalRejected(f"robot not ready: {state.not_ready_reason()}")
        goal = self._goal
        if goal is not None and self._mode is _Mode.EXTERNAL:
            # the robot runs that trajectory itself: taking over mid-way would fight it
            raise GoalRejected(f"busy: passthrough goal {goal.goal_id} runs on the robot; cancel it first")
        if goal is not None:
            if goal_id == goal.goal_id:
                raise GoalRejected(f"goal {goal_id} is already executing")
            if not preempt:
                raise GoalRejected(f"busy: goal {goal.goal_id} is executing")
        if not preempt and self._stream_active(now):
            raise GoalRejected(
                f"busy: a joint stream is active (last command {now - self._last_stream_now:.3g} s ago, "
                f"timeout {self._stream_timeout:.3g} s)"
            )

    def _check_can_stream(self, state: RobotState) -> None:
        if not state.ready_for_motion:
            raise GoalRejected(f"robot not ready: {state.not_ready_reason()}")
        if self._goal is not None:
            raise GoalRejected(f"busy: goal {self._goal.goal_id} is executing")

    def _stream_active(self, now: float) -> bool:
        mode = self._mode
        return (mode is _Mode.STREAM_POSITION or mode is _Mode.STREAM_VELOCITY) and (
            now - self._last_stream_now <= self._stream_timeout
        )

    def _permutation(self, joint_names: Sequence[str]) -> tuple[int, ...]:
        key = tuple(joint_names)
        perm = self._perm_cache.get(key)
        if perm is None:
            perm = joint_permutation(key, self.joint_names)
            if len(self._perm_cache) >= _PERM_CACHE_SIZE:
                self._perm_cache.clear()
            self._perm_cache[key] = perm
        return perm

    def _resolve_tolerances(
        self, tolerances: Tolerances | None
    ) -> tuple[tuple[float, ...], tuple[float, ...], float]:
        n = self._n
        path: tuple[float, ...] = (self._path_tolerance,) * n
        goal: tuple[float, ...] = (self._goal_tolerance,) * n
        goal_time = self._goal_time_tolerance
        if tolerances is None:
            return path, goal, goal_time
        for label, given in (("path", tolerances.path), ("goal", tolerances.goal)):
            if given is None:
                continue
            if len(given) != n:
                raise GoalRejected(f"{label} tolerances have {len(given)} values for {n} joints")
            for name, value in zip(self.joint_names, given, strict=True):
                # Infinity is allowed: it switches the check off for that joint.
                if not (value > 0.0):
                    raise GoalRejected(f"{label} tolerance of {name} must be > 0, got {value}")
                if MAX_JOINT_TOLERANCE < value < math.inf:
                    raise GoalRejected(
                        f"{label} tolerance of {name} is {value:.6g}, more than one turn "
                        f"({MAX_JOINT_TOLERANCE:.6g} rad); leave it out for the default"
                    )
            if label == "path":
                path = tuple(float(v) for v in given)
            else:
                goal = tuple(float(v) for v in given)
        if tolerances.goal_time is not None:
            if not (tolerances.goal_time >= 0.0):
                raise GoalRejected(f"goal_time tolerance must be >= 0, got {tolerances.goal_time}")
            if MAX_GOAL_TIME_S < tolerances.goal_time < math.inf:
                raise GoalRejected(
                    f"goal_time tolerance is {tolerances.goal_time:.6g} s, more than the longest goal "
                    f"({MAX_GOAL_TIME_S:.6g} s)"
                )
            goal_time = float(tolerances.goal_time)
        return path, goal, goal_time

    def _goal_seed(self, state: RobotState) -> tuple[list[float], list[float], list[float]]:
        """Start state of a new goal in trajectory time units: the setpoint if moving, else measured."""
        mode = self._mode
        if mode is _Mode.GOAL:
            return list(self._pos), list(self._pvel), list(self._pacc)
        if mode is _Mode.IDLE:
            return list(state.positions), [0.0] * self._n, [0.0] * self._n
        # A stream or stop runs in real time; the goal will run at speed_scaling, so rescale. If the
        # rescaled state is beyond the limits the goal could not continue the motion without a jump.
        s = max(state.speed_scaling, _MIN_SEED_SCALING)
        vel = [v / s for v in self._vel]
        acc = [a / (s * s) for a in self._acc]
        for i in range(self._n):
            if abs(vel[i]) > self._vmax[i] * (1.0 + 1e-9) or abs(acc[i]) > self._amax[i] * (1.0 + 1e-9):
                raise GoalRejected(
                    f"cannot take over the current motion at speed scaling {state.speed_scaling:.3g}: "
                    f"{self.joint_names[i]} moves too fast to continue at that time scale; stop first"
                )
        return list(self._pos), vel, acc

    def _start_goal(
        self,
        goal_id: str,
        plan: PlannedTrajectory,
        path_tol: tuple[float, ...],
        goal_tol: tuple[float, ...],
        goal_time: float,
        seed_p: list[float],
        seed_v: list[float],
        seed_a: list[float],
        state: RobotState,
    ) -> None:
        if self._goal is not None:
            self._finish_goal(GoalStatus.PREEMPTED, f"preempted by goal {goal_id}", state.positions)
        if self._mode is _Mode.IDLE:
            self._pos[:] = seed_p
            self._vel[:] = self._zeros
            self._acc[:] = self._zeros
        self._pvel[:] = seed_v
        self._pacc[:] = seed_a
        if self._mode is _Mode.IDLE:
            self._scaling.start(clamp_scaling(state.speed_scaling), seed_a)
        elif self._mode is _Mode.GOAL:
            self._scaling.start(None, seed_a)  # continues the pace of the goal it preempts: no jolt
        else:
            # a stream or stop: the seed was converted into trajectory time at this scaling
            self._scaling.start(max(clamp_scaling(state.speed_scaling), _MIN_SEED_SCALING), seed_a)
        self._goal = _Goal(goal_id, plan, path_tol, goal_tol, goal_time)
        self._mode = _Mode.GOAL
        self._last_stream_now = -math.inf
        self._goals_accepted += 1

    def _finish_goal(self, status: GoalStatus, reason: str, measured: Sequence[float]) -> None:
        goal = self._goal
        assert goal is not None
        self._goal = None
        if goal.plan.segment_count > RELEASE_SEGMENTS:
            self._released.append(goal.plan)  # freed over the next ticks, not all at once here
        actual = tuple(measured)
        self._events.append(
            GoalResult(
                goal_id=goal.goal_id,
                status=status,
                reason=reason,
                final_positions=actual,
                final_error=tuple(d - a for d, a in zip(self._pos, actual, strict=True)),
                duration=goal.t,
            )
        )
        if status is GoalStatus.SUCCEEDED:
            self._goals_succeeded += 1
        elif status is GoalStatus.ABORTED:
            self._goals_aborted += 1
        elif status is GoalStatus.CANCELED:
            self._goals_canceled += 1
        else:
            self._goals_preempted += 1

    def _seed_online(self) -> None:
        inp = self._inp
        inp.current_position = self._pos
        inp.current_velocity = self._vel
        inp.current_acceleration = self._acc

    def _begin_stream(self, state: RobotState) -> None:
        """Seed the online generator for a stream: from the setpoint if moving, else from measured."""
        if self._mode is _Mode.IDLE:
            self._pos[:] = state.positions
            self._vel[:] = self._zeros
            self._acc[:] = self._zeros
            self._seed_online()

    def _enter_stopping(self) -> None:
        """Switch to a jerk-limited stop from the current setpoint (a goal's is first made real-time)."""
        mode = self._mode
        if mode is _Mode.IDLE or mode is _Mode.STOPPING:
            return
        if mode is _Mode.GOAL:
            s = self._scaling.value
            r = self._scaling.rate
            for i in range(self._n):
                self._vel[i] = self._pvel[i] * s
                self._acc[i] = self._pacc[i] * s * s + self._pvel[i] * r
        self._seed_online()
        inp = self._inp
        inp.control_interface = _VELOCITY
        self._clear_braking()
        inp.target_velocity = self._zeros
        inp.target_acceleration = self._zeros
        self._mode = _Mode.STOPPING
        self._hold = False
        self._ramp_done = False
        self._settle_ticks = 0
        self._last_stream_now = -math.inf

    def _go_idle(self) -> None:
        # Forgetting the setpoint is implicit: IDLE seeds every new motion from the measured state.
        self._mode = _Mode.IDLE
        self._last_stream_now = -math.inf

    def _online_step(self) -> Any:
        """One online ruckig cycle from the setpoint; None when ruckig failed."""
        try:
            result = run_robustly(self._update, self._inp)
        except RUCKIG_ERRORS:
            return None
        if result != _WORKING and result != _FINISHED:
            return None
        self._accept_output()
        return result

    def _accept_output(self) -> None:
        out = self._out
        out.pass_to_input(self._inp)
        self._pos[:] = out.new_position
        self._vel[:] = out.new_velocity
        self._acc[:] = out.new_acceleration

    def _set_braking(self, joints: list[int]) -> None:
        """Make ``joints`` of a position stream brake to rest (velocity interface, target 0)."""
        inp = self._inp
        interfaces = list(inp.per_dof_control_interface or [_POSITION] * self._n)
        target_velocity = list(inp.target_velocity)
        for i in joints:
            interfaces[i] = _VELOCITY
            target_velocity[i] = 0.0
            self._braking[i] = True
        inp.per_dof_control_interface = interfaces
        inp.target_velocity = target_velocity
        self._per_dof_active = True

    def _clear_braking(self) -> None:
        if self._per_dof_active:
            self._inp.per_dof_control_interface = None
            self._per_dof_active = False
            self._braking[:] = [False] * self._n

    def _brake_overshooting_joints(self, out: Any) -> bool:
        """Brake the joints whose freshly planned stream path leaves the limits; True if any."""
        pos = self._pos
        vel = self._vel
        acc = self._acc
        target = self._stream_target
        target_vel = self._stream_target_velocity
        safe = self._safe_distance
        near = False
        for i in range(self._n):
            p = pos[i]
            q = target[i]
            top = p if p > q else q
            bottom = p if p < q else q
            hi = self._hi[i]
            lo = self._lo[i]
            # Coarse filter first: one worst-case stop from each end of the span.
            if top + 2.0 * safe[i] < hi and bottom - 2.0 * safe[i] > lo:
                continue
            # An excursion beyond the start-to-target span is at most the stop from the current state
            # plus the run-up to the target velocity; the margin absorbs the bound's looseness.
            amax = self._amax[i]
            jmax = self._jmax[i]
            reach = (
                1.5
                * (
                    stopping_distance(abs(vel[i]), abs(acc[i]), amax, jmax)
                    + stopping_distance(abs(target_vel[i]), 0.0, amax, jmax)
                )
                + 1e-3
            )
            if top + reach >= hi or bottom - reach <= lo:
                near = True
                break
        if not near:
            return False
        bad: list[int] = []
        for i, (ext_min, ext_max) in enumerate(position_extrema(out.trajectory)):
            if self._braking[i]:
                continue
            # A joint already outside a limit may only move back in.
            hi = max(self._hi[i], pos[i]) + _EXTREMA_EPS
            lo = min(self._lo[i], pos[i]) - _EXTREMA_EPS
            if ext_max > hi or ext_min < lo:
                bad.append(i)
        if bad:
            self._set_braking(bad)
            return True
        return False

    def _brake_coasting_joints(self) -> None:
        """Brake joints that passed their stream target and coast on toward a limit they must not pass."""
        pos = self._pos
        vel = self._vel
        target = self._stream_target
        safe = self._safe_distance
        bad: list[int] | None = None
        for i in range(self._n):
            v = vel[i]
            if v == 0.0 or self._braking[i]:
                continue
            p = pos[i]
            if v > 0.0:
                if p < target[i] or self._hi[i] - p > safe[i]:
                    continue
                direction = BRAKE_UP
            else:
                if p > target[i] or p - self._lo[i] > safe[i]:
                    continue
                direction = BRAKE_DOWN
            mask = braking_needed(
                p, v, self._acc[i], self._lo[i], self._hi[i], self._amax[i], self._jmax[i], self._period
            )
            if mask & direction:
                if bad is None:
                    bad = []
                bad.append(i)
        if bad is not None:
            self._set_braking(bad)

    def _write_idle(self, state: RobotState, command: JointCommand) -> None:
        command.mode = CommandMode.IDLE
        command.positions[:] = state.positions
        command.velocities[:] = self._zeros

    def _write_setpoint(self, command: JointCommand) -> None:
        command.mode = CommandMode.POSITION
        command.positions[:] = self._pos
        command.velocities[:] = self._vel


def _mapped_point(perm: Sequence[int], k: int, pt: TrajectoryPoint) -> TrajectoryPoint:
    """Point ``k`` in controller joint order; rejects a wrong length."""
    return TrajectoryPoint(
        positions=apply_permutation(perm, pt.positions, f"point {k} positions"),
        time_from_start=float(pt.time_from_start),
        velocities=(
            None if pt.velocities is None else apply_permutation(perm, pt.velocities, f"point {k} velocities")
        ),
        accelerations=(
            None
            if pt.accelerations is None
            else apply_permutation(perm, pt.accelerations, f"point {k} accelerations")
        ),
    )
