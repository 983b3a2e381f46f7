"""The online trajectory generator: ruckig moving the setpoint one cycle toward a target.

Owns ruckig's instance with its input and output parameters, and the per-joint braking interface (a
joint told to brake follows a velocity target of zero while the others follow the target). It shares
the setpoint's lists: ``seed`` starts ruckig from them, and every accepted cycle is written back into
them in place. The stream follower and the stop ramp drive it; a goal samples its own plan instead.
"""

from __future__ import annotations

import functools
from typing import Any

from ruckig import ControlInterface, InputParameter, OutputParameter, Result, Ruckig, Synchronization

from urdaemon.control.ruckig_calls import RUCKIG_ERRORS, run_robustly
from urdaemon.control.setpoint import Setpoint
from urdaemon.model import JointLimits

__all__ = ["FINISHED", "POSITION", "VELOCITY", "WORKING", "OnlineGenerator"]

WORKING = Result.Working
FINISHED = Result.Finished
POSITION = ControlInterface.Position
VELOCITY = ControlInterface.Velocity


class OnlineGenerator:
    """Jerk-limited next setpoints from ruckig's online mode, toward a position or a velocity target."""

    __slots__ = ("_acc", "_per_dof", "_pos", "_vel", "_zeros", "braking", "inp", "out", "update")

    def __init__(self, limits: JointLimits, period: float, setpoint: Setpoint) -> None:
        n = limits.dof
        otg: Any = Ruckig(n, period)
        self.inp: Any = InputParameter(n)
        self.out: Any = OutputParameter(n)
        self.update = functools.partial(otg.update, self.inp, self.out)
        """One ruckig cycle, bound once: it runs every tick and must not build a closure each time."""
        self.inp.max_velocity = list(limits.max_velocity)
        self.inp.max_acceleration = list(limits.max_acceleration)
        self.inp.max_jerk = list(limits.max_jerk)
        self.inp.synchronization = Synchronization.No
        self._pos = setpoint.pos
        self._vel = setpoint.vel
        self._acc = setpoint.acc
        self._zeros = setpoint.zeros
        self._per_dof = False
        self.braking = [False] * n
        """Per joint: told to brake to rest instead of following the position target."""

    def release(self) -> None:
        """Let go of the ruckig objects (the daemon stopped): nothing that still holds this generator
        at interpreter exit keeps them alive for nanobind to report as leaked. Unusable afterwards."""
        del self.update, self.inp, self.out

    def seed(self) -> None:
        """Continue from the setpoint (after it was set other than by this generator)."""
        inp = self.inp
        inp.current_position = self._pos
        inp.current_velocity = self._vel
        inp.current_acceleration = self._acc

    def toward_position(self, target: list[float], target_velocity: list[float]) -> None:
        """Every joint follows ``target``, arriving at ``target_velocity`` (no joint brakes)."""
        inp = self.inp
        inp.control_interface = POSITION
        self.unbrake()
        inp.target_position = target
        inp.target_velocity = target_velocity
        inp.target_acceleration = self._zeros

    def toward_velocity(self, target_velocity: list[float] | None) -> None:
        """Every joint follows a velocity target (None: the one set next, by ``inp.target_velocity``)."""
        inp = self.inp
        inp.control_interface = VELOCITY
        self.unbrake()
        if target_velocity is not None:
            inp.target_velocity = target_velocity
        inp.target_acceleration = self._zeros

    def brake(self, joints: list[int]) -> None:
        """Make ``joints`` brake to rest (velocity interface, target 0) while the others follow on."""
        inp = self.inp
        interfaces = list(inp.per_dof_control_interface or [POSITION] * len(self.braking))
        target_velocity = list(inp.target_velocity)
        for i in joints:
            interfaces[i] = VELOCITY
            target_velocity[i] = 0.0
            self.braking[i] = True
        inp.per_dof_control_interface = interfaces
        inp.target_velocity = target_velocity
        self._per_dof = True

    def unbrake(self) -> None:
        """No joint brakes: all follow the one control interface."""
        if self._per_dof:
            self.inp.per_dof_control_interface = None
            self._per_dof = False
            self.braking[:] = [False] * len(self.braking)

    def step(self) -> Any:
        """One cycle from the setpoint into the setpoint; ruckig's result, None when ruckig failed."""
        try:
            result = run_robustly(self.update, self.inp)
        except RUCKIG_ERRORS:
            return None
        if result != WORKING and result != FINISHED:
            return None
        self.accept()
        return result

    def accept(self) -> None:
        """Take the cycle just calculated: it becomes the setpoint and the next cycle's start."""
        out = self.out
        out.pass_to_input(self.inp)
        self._pos[:] = out.new_position
        self._vel[:] = out.new_velocity
        self._acc[:] = out.new_acceleration
