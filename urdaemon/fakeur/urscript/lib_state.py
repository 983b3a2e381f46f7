"""URScript state getters and kinematics builtins, read from the fake arm.

Joint values come from ``FakeArm`` (actual: where the arm is; target: what the running motion
commands); TCP values apply the arm's TCP offset (``set_tcp``) to the flange pose. The TCP wrench is
the arm's measured one (``arm.tcp_force``, set by the contact model); the joint torques beyond what the
arm's own motion needs are that wrench's (Jᵀ·F); temperatures are constants (no thermal model).
Inverse kinematics is ``urdaemon.description.ik`` on the arm's calibrated model.
"""

from __future__ import annotations

import math
from typing import Any, Final

from urdaemon.description.frames import frame_of_pose, inverse, rotate
from urdaemon.fakeur.fake_arm import FakeArm
from urdaemon.fakeur.joint_motion import JointMove, ServoFilter
from urdaemon.fakeur.tcp_motion import CartesianMove
from urdaemon.fakeur.urscript.lib_motion import flange_pose, inverse_near, tcp_pose, tool_speed
from urdaemon.fakeur.urscript.runtime import ScriptRuntimeError, UrList, UrPose, builtin
from urdaemon.fakeur.urscript.script_host import ScriptHost
from urdaemon.fakeur.urscript.signatures import Computed

__all__ = ["tool_accelerometer"]

JOINT_TEMPERATURE: Final = 30.0
"""°C: what every joint reports (the controller's primary and RTDE data say the same)."""
CONTROLLER_TEMPERATURE: Final = 35.0
"""°C: the control box of the model (a constant: the fake has no thermal model)."""
NO_TOOL_CURRENT: Final = 0.0
"""A: the tool connector's current with nothing connected to it."""


def _joints(name: str, value: Any) -> list[float]:
    if not isinstance(value, (list, tuple)) or len(value) != 6:
        raise ScriptRuntimeError(f"{name}: expected a list of 6 numbers, got {value!r}")
    return [float(v) for v in value]


def _optional(value: Any) -> Any:
    """None for a parameter left at its 'current value' default (computed, no value, or an empty list)."""
    if value is None or isinstance(value, Computed) or (isinstance(value, (list, tuple)) and len(value) == 0):
        return None
    return value


@builtin("get_actual_joint_positions")
def get_actual_joint_positions(host: ScriptHost) -> UrList:
    """The joint positions where the arm is (rad)."""
    return UrList(host.arm.q)


@builtin("get_joint_positions")
def get_joint_positions(host: ScriptHost) -> UrList:
    """The target joint positions (undocumented; UR's External Control script uses it)."""
    return UrList(host.arm.target_q)


@builtin("get_target_joint_positions")
def get_target_joint_positions(host: ScriptHost) -> UrList:
    """The joint positions the running motion commands (rad)."""
    return UrList(host.arm.target_q)


@builtin("get_actual_joint_speeds")
def get_actual_joint_speeds(host: ScriptHost) -> UrList:
    """The joint speeds (rad/s)."""
    return UrList(host.arm.qd)


@builtin("get_target_joint_speeds")
def get_target_joint_speeds(host: ScriptHost) -> UrList:
    """The joint speeds the running motion commands (rad/s)."""
    return UrList(host.arm.target_qd)


@builtin("get_actual_joint_accelerations")
def get_actual_joint_accelerations(host: ScriptHost) -> UrList:
    """The joint accelerations (rad/s²)."""
    return UrList(host.arm.qdd)


@builtin("get_target_joint_accelerations")
def get_target_joint_accelerations(host: ScriptHost) -> UrList:
    """The joint accelerations commanded (the fake arm follows its commands: the actual ones)."""
    return UrList(host.arm.qdd)


@builtin("get_actual_tcp_pose")
def get_actual_tcp_pose(host: ScriptHost) -> UrPose:
    """The TCP pose where the arm is (base frame)."""
    return UrPose(tcp_pose(host.arm, host.arm.q))


@builtin("get_target_tcp_pose")
def get_target_tcp_pose(host: ScriptHost) -> UrPose:
    """The TCP pose the running motion commands."""
    return UrPose(tcp_pose(host.arm, host.arm.target_q))


@builtin("get_target_tcp_pose_along_path")
def get_target_tcp_pose_along_path(host: ScriptHost) -> UrPose:
    """The target TCP pose without path offset (the fake has none: the target TCP pose)."""
    return UrPose(tcp_pose(host.arm, host.arm.target_q))


@builtin("get_target_tcp_speed_along_path")
def get_target_tcp_speed_along_path(host: ScriptHost) -> UrList:
    """The target TCP speed without path offset (the fake has none: the target TCP speed)."""
    return tool_speed(host.arm, host.arm.target_q, host.arm.target_qd)


@builtin("get_actual_tool_flange_pose")
def get_actual_tool_flange_pose(host: ScriptHost) -> UrPose:
    """The tool flange pose where the arm is (no TCP offset)."""
    return UrPose(flange_pose(host.arm, host.arm.q))


@builtin("get_actual_tcp_speed")
def get_actual_tcp_speed(host: ScriptHost) -> UrList:
    """The TCP speed [vx, vy, vz, wx, wy, wz] (m/s, rad/s; base frame)."""
    return tool_speed(host.arm, host.arm.q, host.arm.qd)


@builtin("get_target_tcp_speed")
def get_target_tcp_speed(host: ScriptHost) -> UrList:
    """The TCP speed the running motion commands."""
    return tool_speed(host.arm, host.arm.target_q, host.arm.target_qd)


@builtin("get_tcp_force")
def get_tcp_force(host: ScriptHost) -> UrPose:
    """The wrench at the TCP, p[Fx, Fy, Fz, Tx, Ty, Tz] (N, N·m, base frame): what the arm measures
    (``arm.tcp_force``, zero in free air; the fake's contact model sets it)."""
    return UrPose(host.arm.tcp_force)


@builtin("force")
def force(host: ScriptHost) -> float:
    """The force at the TCP (N): the norm of the force part of ``get_tcp_force()``."""
    fx, fy, fz = host.arm.tcp_force[:3]
    return math.sqrt(fx * fx + fy * fy + fz * fz)


@builtin("get_tool_accelerometer_reading")
def get_tool_accelerometer_reading(host: ScriptHost) -> UrList:
    """What the tool's accelerometer reads (m/s², TCP frame): see :func:`tool_accelerometer`."""
    return UrList(tool_accelerometer(host.arm))


def tool_accelerometer(arm: FakeArm) -> tuple[float, float, float]:
    """The tool accelerometer's reading (m/s², TCP frame) of the arm standing still.

    Model: an accelerometer at rest measures the reaction to gravity, which is the arm's gravity vector
    as ``set_gravity`` takes it (pointing up, base frame), turned into the TCP frame; so an axis pointing
    up reads +9.82. The acceleration of the arm's own motion is left out (a still robot's reading)."""
    frame = frame_of_pose(tcp_pose(arm, arm.q))
    return rotate(inverse(frame), arm.gravity)


@builtin("get_tool_current")
def get_tool_current(host: ScriptHost) -> float:
    """The current the tool connector supplies (A): nothing is connected to the fake's tool, so no
    current flows at any tool voltage."""
    return NO_TOOL_CURRENT


@builtin("get_controller_temp")
def get_controller_temp(host: ScriptHost) -> float:
    """The control box's temperature (°C): :data:`CONTROLLER_TEMPERATURE`."""
    return CONTROLLER_TEMPERATURE


@builtin("get_tool_temp")
def get_tool_temp(host: ScriptHost) -> float:
    """The tool flange's temperature (°C): the joints' (:data:`JOINT_TEMPERATURE`), as RTDE reports."""
    return JOINT_TEMPERATURE


@builtin("reset_revolution_counter")
def reset_revolution_counter(host: ScriptHost, qNear: Any) -> None:
    """Unwind joints whose safety limits are "unlimited" by whole turns towards ``qNear``.

    The manual applies it only to such joints; every joint of the fake's models has finite limits
    (±2π), so after checking ``qNear`` there is nothing to reset (refused if a model ever has one)."""
    _joints("reset_revolution_counter qNear", qNear)
    arm = host.arm
    unlimited = [i for i in range(6) if math.isinf(arm.min_position[i]) or math.isinf(arm.max_position[i])]
    if unlimited:
        raise ScriptRuntimeError(
            f"reset_revolution_counter: not simulated for the unlimited joints {unlimited} of this model"
        )


@builtin("get_joint_torques")
def get_joint_torques(host: ScriptHost) -> UrList:
    """The joint torques (N·m) "corrected by the torque needed to move the robot itself" (the manual):
    what is left when the arm's model (gravity, its motion) is taken out, the torques of the external
    wrench at the TCP, Jᵀ·F (``arm.tcp_force``, base frame). Zero in free air: the fake arm follows
    its model exactly, under direct_torque too."""
    arm = host.arm
    force = arm.tcp_force
    if not any(force):
        return UrList([0.0] * 6)
    jacobian = arm.drive.dynamics.jacobian(arm.q, arm.tcp_offset)
    return UrList(sum(jacobian[r][c] * force[r] for r in range(6)) for c in range(6))


@builtin("get_joint_temp")
def get_joint_temp(host: ScriptHost, j: Any) -> float:
    """The temperature of joint ``j`` (°C)."""
    if isinstance(j, bool) or not isinstance(j, int) or not 0 <= j <= 5:
        raise ScriptRuntimeError(f"get_joint_temp: joint index must be 0 to 5, got {j!r}")
    return JOINT_TEMPERATURE


@builtin("get_actual_joint_positions_history")
def get_actual_joint_positions_history(host: ScriptHost, steps: Any) -> UrList:
    """The joint positions ``steps`` controller cycles ago (0: now)."""
    if isinstance(steps, bool) or not isinstance(steps, int) or steps < 0:
        raise ScriptRuntimeError(
            f"get_actual_joint_positions_history: steps must be an integer >= 0, got {steps!r}"
        )
    return UrList(host.arm.history.ago(steps))


@builtin("is_steady")
def is_steady(host: ScriptHost) -> bool:
    """True when the arm is fully at rest and no motion is commanded."""
    return host.arm.steady


@builtin("get_target_waypoint")
def get_target_waypoint(host: ScriptHost) -> UrPose:
    """The TCP pose the active move ends at (the target TCP pose when no move is active)."""
    arm = host.arm
    motion = arm.motion
    if isinstance(motion, CartesianMove):
        return UrPose(motion.pose(motion.duration))
    if isinstance(motion, (JointMove, ServoFilter)):
        return UrPose(tcp_pose(arm, motion.target))
    return UrPose(tcp_pose(arm, arm.target_q))


@builtin("get_forward_kin")
def get_forward_kin(host: ScriptHost, q: Any, tcp: Any) -> UrPose:
    """The TCP pose of joints ``q`` (default: where the arm is) with ``tcp`` (default: the active TCP)."""
    arm = host.arm
    joints = arm.q if _optional(q) is None else _joints("get_forward_kin q", q)
    offset = None if _optional(tcp) is None else _joints("get_forward_kin tcp", tcp)
    return UrPose(tcp_pose(arm, joints, offset))


def _solve(name: str, host: ScriptHost, x: Any, qnear: Any, position: Any, orientation: Any, tcp: Any) -> Any:
    arm = host.arm
    pose = _joints(f"{name} x", x)
    near = arm.q if _optional(qnear) is None else _joints(f"{name} qnear", qnear)
    offset = arm.tcp_offset if _optional(tcp) is None else _joints(f"{name} tcp", tcp)
    position_error = 1e-10 if _optional(position) is None else float(position)
    orientation_error = 1e-10 if _optional(orientation) is None else float(orientation)
    return inverse_near(arm, pose, near, offset, position_error, orientation_error)


@builtin("get_inverse_kin")
def get_inverse_kin(
    host: ScriptHost,
    x: Any,
    qnear: Any,
    maxPositionError: Any,
    maxOrientationError: Any,
    tcp: Any,
) -> UrList:
    """Joints reaching ``x`` nearest ``qnear``; a runtime error if there are none (as the controller)."""
    q = _solve("get_inverse_kin", host, x, qnear, maxPositionError, maxOrientationError, tcp)
    if q is None:
        raise ScriptRuntimeError(f"get_inverse_kin: no solution for {x!r}")
    return UrList(q)


@builtin("get_inverse_kin_has_solution")
def get_inverse_kin_has_solution(
    host: ScriptHost,
    pose: Any,
    qnear: Any,
    maxPositionError: Any,
    maxOrientationError: Any,
    tcp: Any,
) -> bool:
    """Whether get_inverse_kin would find a solution."""
    return (
        _solve("get_inverse_kin_has_solution", host, pose, qnear, maxPositionError, maxOrientationError, tcp)
        is not None
    )


@builtin("is_within_safety_limits")
def is_within_safety_limits(host: ScriptHost, pose: Any) -> bool:
    """Whether a pose (by IK nearest the arm's joints) or a joint list lies within the joint limits."""
    arm = host.arm
    if isinstance(pose, UrPose):
        q = _solve("is_within_safety_limits", host, pose, None, None, None, None)
        if q is None:
            return False
    else:
        q = _joints("is_within_safety_limits", pose)
    return all(arm.min_position[i] <= q[i] <= arm.max_position[i] for i in range(6)) and all(
        math.isfinite(v) for v in q
    )
