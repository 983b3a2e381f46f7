"""Limits the codec checks are control's own facts, defined once (review of issue 13)."""

from __future__ import annotations

import ast
import inspect

from urdaemon.control import intake, trajectory
from urdaemon.publish import codec


def test_codec_takes_the_goal_time_and_tolerance_limits_from_control() -> None:
    """Reproduction: ``MAX_GOAL_TIME_S`` and ``MAX_JOINT_TOLERANCE`` were assigned in codec.py as
    well as in control/ (two definitions that could drift apart); codec must import control's."""
    tree = ast.parse(inspect.getsource(codec))
    assigned = {
        target.id
        for node in ast.walk(tree)
        if isinstance(node, ast.Assign | ast.AnnAssign)
        for target in (node.targets if isinstance(node, ast.Assign) else [node.target])
        if isinstance(target, ast.Name)
    }
    assert "MAX_GOAL_TIME_S" not in assigned
    assert "MAX_JOINT_TOLERANCE" not in assigned
    assert vars(codec)["MAX_GOAL_TIME_S"] is trajectory.MAX_GOAL_TIME_S
    assert vars(codec)["MAX_JOINT_TOLERANCE"] is intake.MAX_JOINT_TOLERANCE
