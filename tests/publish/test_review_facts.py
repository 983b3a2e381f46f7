"""Limits the codec checks are control's own facts, defined once (review of issue 13)."""

from __future__ import annotations

import ast
import inspect
from types import ModuleType

from urdaemon.control import intake, trajectory
from urdaemon.publish import fields, move_goal

LIMITS = {"MAX_GOAL_TIME_S": trajectory.MAX_GOAL_TIME_S, "MAX_JOINT_TOLERANCE": intake.MAX_JOINT_TOLERANCE}


def _assigned(module: ModuleType) -> set[str]:
    tree = ast.parse(inspect.getsource(module))
    return {
        target.id
        for node in ast.walk(tree)
        if isinstance(node, ast.Assign | ast.AnnAssign)
        for target in (node.targets if isinstance(node, ast.Assign) else [node.target])
        if isinstance(target, ast.Name)
    }


def test_codec_takes_the_goal_time_and_tolerance_limits_from_control() -> None:
    """Reproduction: ``MAX_GOAL_TIME_S`` and ``MAX_JOINT_TOLERANCE`` were assigned in codec.py as
    well as in control/ (two definitions that could drift apart); the decoders must import control's
    (the tolerances' checks in fields.py, a move's duration in its decoder)."""
    for module, names in ((fields, LIMITS), (move_goal, ("MAX_GOAL_TIME_S",))):
        assigned = _assigned(module)
        for name in names:
            assert name not in assigned, (module.__name__, name)
            assert vars(module)[name] is LIMITS[name], (module.__name__, name)
