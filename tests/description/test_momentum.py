"""The arm's linear momentum (RTDE's ``actual_momentum``) against an independent computation.

UR's RTDE guide defines ``actual_momentum`` as the norm of the robot's Cartesian linear momentum. The
momentum of a set of rigid bodies is its total mass times the speed of its overall centre of mass, so
the reference here places every link's centre of mass (and the payload's) with the link frames of
tests/description/test_dynamics.py's Newton–Euler (the ROS description's joint origins, numpy), and
differentiates the overall centre of mass numerically along the joint speeds. The module sums m·v per
link from its Jacobian columns instead: the two share the published inertials and nothing else.

Reproduction on the code before: ``ArmDynamics`` had no ``linear_momentum`` (the fake reported 0).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from tests.description.test_dynamics import MODELS, PAYLOAD, Reference
from urdaemon.description.dynamics import ArmDynamics, Payload
from urdaemon.description.urmodels import load_ur_model

angles = st.lists(st.floats(-math.pi, math.pi), min_size=6, max_size=6)
speeds = st.lists(st.floats(-2.0, 2.0), min_size=6, max_size=6)
names = st.sampled_from(MODELS)


def _mass_moment(reference: Reference, q: Sequence[float]) -> np.ndarray:
    """Σ m·c (kg·m, base frame) over the moving links and the payload at ``q``."""
    rotation, position = np.eye(3), np.zeros(3)
    total = np.zeros(3)
    for i, (offset, turn) in enumerate(reference.joints):
        c, s = math.cos(q[i]), math.sin(q[i])
        position = position + rotation @ offset
        rotation = rotation @ turn @ np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
        mass, com, _ = reference.bodies[i]
        total += mass * (position + rotation @ com)
        if i == 5 and reference.payload is not None:
            total += reference.payload[0] * (position + rotation @ reference.payload[1])
    return total


def _reference_momentum(name: str, payload: Payload | None, q: Sequence[float], qd: Sequence[float]) -> float:
    reference = Reference(name, payload)
    h = 1e-6
    ahead = _mass_moment(reference, [a + h * b for a, b in zip(q, qd, strict=True)])
    behind = _mass_moment(reference, [a - h * b for a, b in zip(q, qd, strict=True)])
    return float(np.linalg.norm((ahead - behind) / (2 * h)))


@settings(max_examples=40, deadline=None)
@given(name=names, q=angles, qd=speeds, loaded=st.booleans())
def test_the_linear_momentum_is_the_mass_times_the_speed_of_the_centre_of_mass(
    name: str, q: list[float], qd: list[float], loaded: bool
) -> None:
    payload = PAYLOAD if loaded else None
    model = load_ur_model(name)
    momentum = ArmDynamics(model, model.dh).linear_momentum(q, qd, payload)
    expected = _reference_momentum(name, payload, q, qd)
    assert abs(momentum - expected) <= 1e-6 * max(1.0, expected), (momentum, expected)


def test_a_resting_arm_has_none_and_a_turning_base_what_its_centres_of_mass_carry() -> None:
    model = load_ur_model("ur10e")
    dynamics = ArmDynamics(model, model.dh)
    q = [0.3, -1.2, 1.1, -0.4, 0.9, 0.2]
    assert dynamics.linear_momentum(q, [0.0] * 6) == 0.0
    # only the base turns: every link's centre of mass moves on a circle about the base's z axis
    speed = 0.7
    expected = _reference_momentum("ur10e", None, q, [speed, 0.0, 0.0, 0.0, 0.0, 0.0])
    assert expected > 1.0, "a ur10e turning at 0.7 rad/s carries kilograms at tenths of a metre a second"
    assert abs(dynamics.linear_momentum(q, [speed, 0.0, 0.0, 0.0, 0.0, 0.0]) - expected) <= 1e-6 * expected
