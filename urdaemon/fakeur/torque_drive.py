"""The fake arm's dynamics and its direct torque mode (``TorqueDrive``), pure with time passed in.

The manual's ``direct_torque``: the controller always compensates gravity (of the arm and its set
payload), so the torque commanded moves the joints by q'' = M⁻¹ (τ − c(q, q')). Each joint's total
torque (the command plus its gravity torque) is held within its ``max_effort``, its speed within its
``max_velocity``; the step is semi-implicit Euler. A command lasts one controller cycle: the arm
(fakeur/fake_arm.py) stops as a protective stop does in a cycle with no new one, back in position
control. The fake's joints have no friction, so there is none to compensate: ``friction_comp`` and the
friction scales change nothing. The dynamics are description/dynamics.py on the arm's calibrated DH,
made on first use (the serve process never needs them).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING

from urdaemon.description.urmodels import DhParameters, UrModel

if TYPE_CHECKING:
    from urdaemon.description.dynamics import ArmDynamics, Payload

__all__ = ["TorqueDrive", "payload_of"]


def payload_of(mass: float, cog: Sequence[float], inertia: Sequence[float]) -> Payload:
    """A payload as the dynamics take it, from the arm's ``set_target_payload`` values."""
    from urdaemon.description.dynamics import Payload

    return Payload.of(mass, cog, inertia)


class TorqueDrive:
    """One arm's rigid-body dynamics, its direct torque command, and its joint torques per cycle."""

    __slots__ = ("_dh", "_dynamics", "_efforts", "_model", "_torques", "renewed", "torque")

    def __init__(self, model: UrModel, dh: DhParameters) -> None:
        self._model = model
        self._dh = dh
        self._dynamics: ArmDynamics | None = None
        self._efforts = [j.max_effort for j in model.joints]
        self.torque = [0.0] * 6
        """N·m: the command, on top of the controller's gravity compensation."""
        self.renewed = False
        """Whether a command came since the last step."""
        self._torques: tuple[float, list[float]] | None = None
        """The last joint torques and the timestamp they are for."""

    @property
    def dynamics(self) -> ArmDynamics:
        """The arm's dynamics (description/dynamics.py), made on first use."""
        model = self._dynamics
        if model is None:
            from urdaemon.description.dynamics import ArmDynamics

            model = self._dynamics = ArmDynamics(self._model, self._dh)
        return model

    def command(self, torque: Sequence[float]) -> None:
        """This cycle's torque command (N·m)."""
        self.torque[:] = [float(v) for v in torque]
        self.renewed = True

    def step(
        self,
        q: list[float],
        qd: list[float],
        qdd: list[float],
        gravity: Sequence[float],
        payload: Payload,
        vmax: Sequence[float],
        dt: float,
    ) -> bool:
        """Move ``q``, ``qd``, ``qdd`` (in place) one cycle under the command; False (nothing moved) if no
        command came since the last step."""
        if not self.renewed:
            return False
        self.renewed = False
        dynamics, efforts = self.dynamics, self._efforts
        hold = dynamics.gravity_torques(q, gravity, payload)
        motor = [max(-efforts[i], min(efforts[i], self.torque[i] + hold[i])) for i in range(6)]
        acceleration = dynamics.forward_dynamics(q, qd, motor, gravity, payload)
        for i in range(6):
            v = max(-vmax[i], min(vmax[i], qd[i] + acceleration[i] * dt))
            qdd[i] = (v - qd[i]) / dt
            qd[i] = v
            q[i] += v * dt
        return True

    def joint_torques(
        self,
        timestamp: float,
        q: Sequence[float],
        qd: Sequence[float],
        qdd: Sequence[float],
        gravity: Sequence[float],
        payload: Payload,
    ) -> list[float]:
        """N·m: τ = M q'' + c(q, q') + g(q) at ``timestamp`` (computed once per timestamp)."""
        cached = self._torques
        if cached is not None and cached[0] == timestamp:
            return list(cached[1])
        torques = self.dynamics.inverse_dynamics(q, qd, qdd, gravity, payload)
        self._torques = (timestamp, torques)
        return list(torques)
