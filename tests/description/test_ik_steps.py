"""IK in bounded chunks (``nearest_steps``) and a UR arm bounded by the cell's joint limits.

The work of one chunk is counted, not timed: an instrumented chain counts its forward evaluations
(each with its Jacobian: the unit of a Newton step) between two yields of the generator.

Reproduction on the code before (5494921 + issue 17's first commits): ``nearest_steps`` did not exist
(AttributeError: every chunk test fails), and ``arm_kinematics`` handed the cell's joint limits to
custom robots' chains only, so a UR arm picked the elbow-up branch the cell's limits forbid.
"""

from __future__ import annotations

import math
from collections.abc import Generator
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from urdaemon.description.arm import arm_kinematics
from urdaemon.description.calibration import robot_dh
from urdaemon.description.chain import ChainKinematics
from urdaemon.description.ik import UrKinematics
from urdaemon.description.urmodels import load_ur_model

from .support import REAL_UR10E, make_cell
from .test_chain import SIX, _custom, _random_q

TCP = (0.01, -0.02, 0.12, 0.1, -0.2, 0.3)
OUT_OF_REACH = (
    (5.0, 0.0, 0.0, 0.0, 0.0, 0.0),
    (0.0, 0.0, 3.0, 1.0, 0.0, 0.0),
    (1.5, 1.5, 0.2, 0.0, 3.0, 0.0),
)
"""Poses no arm here reaches (the reviewer's probe: 2-4 ms at once for the six-joint chain)."""


def _chunks(steps: Generator[None, None, Any], evaluations: list[int]) -> tuple[Any, list[int]]:
    """Run ``steps``; what it returns and the evaluations counted in each chunk (between yields)."""
    per_chunk = []
    while True:
        before = evaluations[0]
        try:
            next(steps)
        except StopIteration as stop:
            per_chunk.append(evaluations[0] - before)
            return stop.value, per_chunk
        per_chunk.append(evaluations[0] - before)


@pytest.fixture
def chain_evaluations(monkeypatch: pytest.MonkeyPatch) -> list[int]:
    """Counts ChainKinematics' walks of its chain (a forward evaluation, with or without Jacobian)."""
    count = [0]
    walk = ChainKinematics._walk

    def counted(self: ChainKinematics, q: Any, rows: Any) -> Any:
        count[0] += 1
        return walk(self, q, rows)

    monkeypatch.setattr(ChainKinematics, "_walk", counted)
    return count


@pytest.fixture
def ur_evaluations(monkeypatch: pytest.MonkeyPatch) -> list[int]:
    """Counts UrKinematics' evaluations of its calibrated chain."""
    count = [0]
    chain = UrKinematics._chain

    def counted(self: UrKinematics, q: Any, tcp: Any) -> Any:
        count[0] += 1
        return chain(self, q, tcp)

    monkeypatch.setattr(UrKinematics, "_chain", counted)
    return count


def test_a_custom_robots_pose_out_of_reach_is_solved_one_evaluation_per_chunk(
    tmp_path: Path, chain_evaluations: list[int]
) -> None:
    """The numeric IK's nine starts for a pose out of reach (hundreds of evaluations, 2-4 ms at once)
    come in chunks of at most one evaluation each; the answer is ``nearest``'s: None."""
    _, kin = _custom(tmp_path, SIX)
    q0 = [0.1] * kin.dof
    for pose in OUT_OF_REACH:
        found, per_chunk = _chunks(kin.nearest_steps(pose, q0), chain_evaluations)
        assert found is None
        assert max(per_chunk) <= 1, per_chunk
        assert len(per_chunk) >= 50  # the work was there: it is spread, not skipped
        assert kin.nearest(pose, q0) is None


def test_a_custom_robots_steps_answer_exactly_as_nearest(
    tmp_path: Path, chain_evaluations: list[int]
) -> None:
    """From a near and a far qnear (the restarts), what the chunks return is ``nearest``'s, bit for bit."""
    _, kin = _custom(tmp_path, SIX)
    rng = np.random.default_rng(17)
    found_count = 0
    for _ in range(20):
        q = _random_q(kin, rng)
        pose = kin.forward(q, TCP)
        for spread in (0.05, 1.0):
            qnear = [v + float(rng.uniform(-spread, spread)) for v in q]
            found, per_chunk = _chunks(kin.nearest_steps(pose, qnear, TCP), chain_evaluations)
            assert found == kin.nearest(pose, qnear, TCP)
            assert max(per_chunk) <= 1
            found_count += found is not None
    assert found_count >= 20


@pytest.mark.parametrize("calibrated", [False, True])
def test_a_ur_pose_out_of_reach_is_solved_in_bounded_chunks(
    calibrated: bool, ur_evaluations: list[int]
) -> None:
    model = load_ur_model("ur10e")
    kin = UrKinematics(model, REAL_UR10E if calibrated else None)
    q0 = (0.3, -1.2, 1.5, -1.9, 1.2, 0.4)
    # Just past the reach (a calibrated arm tries Newton's steps and continuation on every branch).
    reach = abs(model.dh.a[1]) + abs(model.dh.a[2])
    for pose in (*OUT_OF_REACH, (reach + 0.02, 0.2, 0.3, 0.0, 3.1, 0.0)):
        found, per_chunk = _chunks(kin.nearest_steps(pose, q0, TCP), ur_evaluations)
        assert found is None
        assert max(per_chunk) <= 1, per_chunk


def test_ur_steps_answer_exactly_as_nearest_and_nearest_in(ur_evaluations: list[int]) -> None:
    kin = UrKinematics(load_ur_model("ur10e"), REAL_UR10E)
    rng = np.random.default_rng(7)
    for _ in range(20):
        q = tuple(float(v) for v in rng.uniform(-2.5, 2.5, 6))
        pose = kin.forward(q, TCP)
        qnear = [v + float(rng.uniform(-0.05, 0.05)) for v in q]
        found, per_chunk = _chunks(kin.nearest_steps(pose, qnear, TCP), ur_evaluations)
        assert found == kin.nearest(pose, qnear, TCP)
        assert max(per_chunk) <= 1
        wanted = {"elbow": "down" if kin.configuration_of(q).elbow == "up" else "up"}
        other, per_chunk = _chunks(kin.nearest_in_steps(pose, qnear, TCP, wanted), ur_evaluations)
        assert other == kin.nearest_in(pose, qnear, TCP, wanted)
        assert max(per_chunk) <= 1


def test_a_ur_arm_bounded_by_the_cells_joint_limits_picks_the_other_branch(tmp_path: Path) -> None:
    """The cell narrows the elbow to [-pi, 0]: the pose of an elbow at +1.6 rad is reached on the
    other elbow branch, where the model's limits (+-pi) would give the nearest, forbidden one."""
    cell = make_cell(tmp_path, {"name": "arm", "model": "ur5e", "pose": {"xyz": [0.0, 0.0, 0.0]}})
    robot = cell.robots[0]
    model = load_ur_model("ur5e")
    lower = [-math.inf if j.min_position is None else j.min_position for j in model.joints]
    upper = [math.inf if j.max_position is None else j.max_position for j in model.joints]
    upper[2] = 0.0  # elbow_joint: the cell's joint_limits
    names = [j.name for j in model.joints]
    q = (0.3, -1.2, 1.6, -1.9, -1.2, 0.4)
    free = UrKinematics(model, robot_dh(robot))
    pose = free.forward(q, TCP)
    assert free.nearest(pose, q, TCP) == pytest.approx(q, abs=1e-9)  # the model allows it
    bounded = arm_kinematics(robot, None, names, (lower, upper))  # type: ignore[arg-type]
    found = bounded.nearest(pose, q, TCP)
    assert found is not None
    assert found[2] < 0.0
    assert all(lo <= v <= hi for v, lo, hi in zip(found, lower, upper, strict=True))
    assert bounded.forward(found, TCP) == pytest.approx(pose, abs=1e-9)


def test_ur_bounds_choose_the_turn_within_them() -> None:
    """A joint with a range wider than a turn takes the 2pi shift nearest qnear that lies in the
    bounds; one that has none in them drops the solution."""
    model = load_ur_model("ur5e")
    lower = [-math.inf if j.min_position is None else j.min_position for j in model.joints]
    upper = [math.inf if j.max_position is None else j.max_position for j in model.joints]
    q = (0.3, -1.2, 1.6, -1.9, -1.2, 0.4)
    pose = UrKinematics(model).forward(q)
    lower[5], upper[5] = 5.0, 7.0  # wrist_3: 0.4 + 2pi is the turn within
    found = UrKinematics(model, None, (lower, upper)).nearest(pose, q)
    assert found is not None
    assert found[5] == pytest.approx(0.4 + 2.0 * math.pi, abs=1e-9)
    lower[5], upper[5] = 0.5, 1.0  # a narrow wrist_3: a branch with no turn of its q6 in it is dropped
    bounded = UrKinematics(model, None, (lower, upper))
    free = UrKinematics(model).solutions(pose, None, q)
    kept = bounded.solutions(pose, None, q)
    assert len(kept) < len(free)
    assert all(0.5 <= s.q[5] <= 1.0 for s in kept)
    found = bounded.nearest(pose, q)
    assert found is None or 0.5 <= found[5] <= 1.0
