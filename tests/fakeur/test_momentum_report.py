"""RTDE's ``actual_momentum``: the norm of the arm's Cartesian linear momentum (UR's RTDE guide), from
the model's link masses and centres of mass (docs/fake-robot.md, "Dynamics"), checked against the
independent computation of tests/description/test_momentum.py while the arm moves, with our own RTDE
codec; computed only for a recipe that names it, at most once a cycle.

Reproduction on the code before: ``actual_momentum`` was 0.0 whatever the arm did (it was not in the
report table), so the moving-arm test fails there.
"""

from __future__ import annotations

import asyncio
from typing import Any

import pytest

from tests.description.test_momentum import _reference_momentum
from tests.fakeur.judges import send_script
from tests.fakeur.test_controller import fake
from tests.helpers import rtde_sample
from urdaemon.description.dynamics import ArmDynamics
from urdaemon.description.urmodels import load_ur_model
from urdaemon.fakeur.fake_arm import FakeArm
from urdaemon.fakeur.reports import output_getter
from urdaemon.fakeur.urscript.script_host import InputRegisters

pytestmark = pytest.mark.timeout(120)

MODEL = "ur10e"
SPEEDS = [0.3, -0.2, 0.25, 0.1, -0.15, 0.2]
"""rad/s: every joint turns, so every link's centre of mass moves."""


async def test_a_moving_arm_reports_its_linear_momentum() -> None:
    async with fake(powered=True, controller_version=(5, 26, 0, 0)) as controller:
        arm = controller.arm
        await controller.until(lambda: arm.robot_mode.name == "RUNNING")
        script = f"def drift():\n  speedj({SPEEDS}, 2.0, 5.0)\nend\n"
        await asyncio.to_thread(send_script, controller.address, 30002, script)
        await controller.until(lambda: abs(arm.qd[0] - SPEEDS[0]) < 1e-9)
        sample: dict[str, Any] = await rtde_sample(
            controller.address, ("actual_q", "actual_qd", "actual_momentum")
        )
        q, qd = sample["actual_q"], sample["actual_qd"]
        assert max(abs(a - b) for a, b in zip(qd, SPEEDS, strict=True)) < 1e-9, f"not at speed: {qd}"
        expected = _reference_momentum(MODEL, None, q, qd)
        assert expected > 0.5, expected
        assert abs(sample["actual_momentum"] - expected) <= 1e-6 * expected, (
            sample["actual_momentum"],
            expected,
        )


def test_the_momentum_is_computed_once_a_cycle_and_not_at_rest(monkeypatch: pytest.MonkeyPatch) -> None:
    model = load_ur_model(MODEL)
    arm = FakeArm(model, model.dh, powered=True)
    calls: list[int] = []
    compute = ArmDynamics.linear_momentum

    def counted(self: ArmDynamics, *args: Any) -> float:
        calls.append(1)
        return compute(self, *args)

    monkeypatch.setattr(ArmDynamics, "linear_momentum", counted)
    first = output_getter("actual_momentum", "DOUBLE", InputRegisters())
    second = output_getter("actual_momentum", "DOUBLE", InputRegisters())  # another client's recipe
    assert first(arm) == 0.0
    assert second(arm) == 0.0
    assert not calls, "a resting arm has no momentum to compute"
    arm.qd[:] = SPEEDS
    arm.timestamp += 0.002  # the next cycle
    value = first(arm)
    assert second(arm) == value > 0.0
    assert len(calls) == 1, "two clients in one cycle: one computation"
    arm.timestamp += 0.002
    first(arm)
    assert len(calls) == 2
