"""URScript kinematics and dynamics builtins (PolyScope 5.23+): the Jacobian and its time derivative,
the mass matrix, the Coriolis and centrifugal torques, and ``direct_torque``.

All read the arm's rigid-body model (``FakeArm.drive.dynamics``, description/dynamics.py: UR's published link
inertials on the arm's calibrated kinematics) with the payload set on the arm. A matrix is a list of
rows, as ``m[row, column]`` indexes it (ur_rtde's script reads ``mass_matrix[i, j]``).

* ``get_jacobian(q, tcp)``: the TCP's geometric Jacobian, rows vx vy vz wx wy wz in the base frame
  (m/s and rad/s per rad/s: the layout of UR's tool speeds), columns the joints; ``q`` defaults to
  where the arm is and ``tcp`` to the active TCP.
* ``get_jacobian_time_derivative(q, qd, tcp)``: dJ/dt along ``qd`` (default: the joint speeds).
* ``get_mass_matrix(q, include_rotors_inertia)``: M(q) in kg·m²; the rotors' inertia is not published
  by UR, so asking for it stops the program as not simulated.
* ``get_coriolis_and_centrifugal_torques(q, qd)``: C(q, q')·q' in N·m.
* ``direct_torque(torque, …)``: one cycle of joint torque control on top of gravity compensation
  (``FakeArm.direct_torque``); the friction arguments are checked and change nothing (the fake's
  joints have no friction to compensate).
"""

from __future__ import annotations

import math
from collections.abc import Generator, Sequence
from typing import Any

from urdaemon.fakeur.fake_arm import arm_payload
from urdaemon.fakeur.urscript.runtime import ScriptRuntimeError, UrList, builtin
from urdaemon.fakeur.urscript.script_host import ScriptHost
from urdaemon.fakeur.urscript.signatures import Computed

__all__: list[str] = []


def _joints(name: str, value: Any, default: Sequence[float]) -> list[float]:
    """Six finite numbers, or ``default`` for a parameter left at its 'current value' (computed, empty)."""
    if value is None or isinstance(value, Computed) or (isinstance(value, (list, tuple)) and len(value) == 0):
        return list(default)
    if not isinstance(value, (list, tuple)) or len(value) != 6:
        raise ScriptRuntimeError(f"{name}: expected a list of 6 numbers, got {value!r}")
    out = []
    for v in value:
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
            raise ScriptRuntimeError(f"{name}: expected a list of 6 finite numbers, got {value!r}")
        out.append(float(v))
    return out


def _matrix(rows: Sequence[Sequence[float]]) -> UrList:
    return UrList(UrList(float(v) for v in row) for row in rows)


@builtin("get_jacobian")
def get_jacobian(host: ScriptHost, q: Any, tcp: Any) -> UrList:
    """The TCP's geometric Jacobian at ``q`` with ``tcp`` (6x6, rows vx vy vz wx wy wz in base)."""
    arm = host.arm
    joints = _joints("get_jacobian q", q, arm.q)
    offset = _joints("get_jacobian tcp", tcp, arm.tcp_offset)
    return _matrix(arm.drive.dynamics.jacobian(joints, offset))


@builtin("get_jacobian_time_derivative")
def get_jacobian_time_derivative(host: ScriptHost, q: Any, qd: Any, tcp: Any) -> UrList:
    """dJ/dt at ``q`` moving at ``qd`` with ``tcp`` (6x6, the layout of get_jacobian)."""
    arm = host.arm
    joints = _joints("get_jacobian_time_derivative q", q, arm.q)
    speeds = _joints("get_jacobian_time_derivative qd", qd, arm.qd)
    offset = _joints("get_jacobian_time_derivative tcp", tcp, arm.tcp_offset)
    return _matrix(arm.drive.dynamics.jacobian_derivative(joints, speeds, offset))


@builtin("get_mass_matrix")
def get_mass_matrix(host: ScriptHost, q: Any, include_rotors_inertia: Any) -> UrList:
    """M(q) (6x6, kg·m²) of the arm with its payload."""
    arm = host.arm
    joints = _joints("get_mass_matrix q", q, arm.q)
    if not isinstance(include_rotors_inertia, bool):
        raise ScriptRuntimeError(
            f"get_mass_matrix: include_rotors_inertia must be True or False, got {include_rotors_inertia!r}"
        )
    if include_rotors_inertia:
        raise ScriptRuntimeError(
            "get_mass_matrix: not simulated by the fake controller: include_rotors_inertia=True needs "
            "the joints' rotor inertias, which UR does not publish"
        )
    return _matrix(arm.drive.dynamics.mass_matrix(joints, arm_payload(arm)))


@builtin("get_coriolis_and_centrifugal_torques")
def get_coriolis_and_centrifugal_torques(host: ScriptHost, q: Any, qd: Any) -> UrList:
    """C(q, q')·q' (N·m) of the arm with its payload."""
    arm = host.arm
    joints = _joints("get_coriolis_and_centrifugal_torques q", q, arm.q)
    speeds = _joints("get_coriolis_and_centrifugal_torques qd", qd, arm.qd)
    return UrList(arm.drive.dynamics.coriolis(joints, speeds, arm_payload(arm)))


def _scales(name: str, value: Any) -> None:
    """A friction scale: six numbers in [0, 1] (the manual's range), or left at its default."""
    if value is None or isinstance(value, Computed):
        return
    scales = _joints(name, value, ())
    if any(not 0.0 <= v <= 1.0 for v in scales):
        raise ScriptRuntimeError(f"{name}: every scale must lie in [0, 1], got {value!r}")


@builtin("direct_torque", blocking=True)
def direct_torque(host: ScriptHost, *args: Any) -> Generator[None, None, None]:
    """direct_torque(torque, [viscous_scale, coulomb_scale,] friction_comp): the joint torques (N·m) on
    top of gravity compensation for this cycle; returns after it (to be called every cycle)."""
    torque = _joints("direct_torque torque", args[0] if args else None, ())
    if len(torque) != 6:
        raise ScriptRuntimeError("direct_torque: expected a list of 6 torques")
    if len(args) == 4:  # 5.25's signature: torque, viscous_scale, coulomb_scale, friction_comp
        _scales("direct_torque viscous_scale", args[1])
        _scales("direct_torque coulomb_scale", args[2])
    friction = args[-1] if len(args) > 1 else True
    if not isinstance(friction, bool) and not isinstance(friction, Computed):
        raise ScriptRuntimeError(f"direct_torque: friction_comp must be True or False, got {friction!r}")
    host.arm.direct_torque(torque)
    yield
