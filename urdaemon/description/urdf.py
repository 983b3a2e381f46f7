"""Read a cell URDF (yourdfpy, no meshes) and derive a robot's joint limits from it.

yourdfpy (and the trimesh, scipy and networkx it imports) is loaded only when ``load_urdf`` is
called: serving reads the URDF with ``urdf_facts.read_urdf_facts`` instead, which
``joint_limits_for`` accepts as well.
"""

from __future__ import annotations

import io
import math
from typing import TYPE_CHECKING, Any

from urdaemon.cell.robot_options import Robot
from urdaemon.description.build import robot_joint_names
from urdaemon.description.urmodels import UrModel, load_ur_model
from urdaemon.errors import DescriptionError
from urdaemon.model import JointLimits

if TYPE_CHECKING:
    import yourdfpy

__all__ = ["joint_limits_for", "load_urdf"]

_Row = tuple[float, float, float, float, float, float]


def load_urdf(text: str) -> yourdfpy.URDF:
    """Parse URDF text into a yourdfpy model with its scene graph, loading no meshes."""
    import yourdfpy  # heavy (trimesh, scipy, networkx): only for readers of geometry

    try:
        return yourdfpy.URDF.load(
            io.StringIO(text),
            build_scene_graph=True,
            load_meshes=False,
            build_collision_scene_graph=False,
            load_collision_meshes=False,
        )
    except Exception as err:  # yourdfpy raises whatever lxml, networkx or its parser raise
        raise DescriptionError(f"cannot read the URDF: {type(err).__name__}: {err}") from err


def joint_limits_for(robot: Robot, urdf: Any) -> JointLimits:
    """The robot's limits: position, velocity, effort from the URDF; rates from the model; overrides.

    ``urdf`` is a yourdfpy ``URDF`` or a ``UrdfFacts``.
    """
    names = robot_joint_names(robot, urdf)
    model = load_ur_model(robot.model) if robot.is_ur else None
    rows = [_joint_row(robot, model, name, urdf.joint_map[name]) for name in names]
    try:
        return JointLimits(
            names=names,
            min_position=tuple(row[0] for row in rows),
            max_position=tuple(row[1] for row in rows),
            max_velocity=tuple(row[2] for row in rows),
            max_acceleration=tuple(row[3] for row in rows),
            max_jerk=tuple(row[4] for row in rows),
            max_effort=tuple(row[5] for row in rows),
        )
    except ValueError as err:
        raise DescriptionError(f"robot {robot.name!r}: {err}") from err


def _joint_row(robot: Robot, model: UrModel | None, name: str, joint: Any) -> _Row:
    """One joint's (lower, upper, velocity, acceleration, jerk, effort) after the cell's override."""
    short = name[len(robot.prefix) :]
    limit = joint.limit
    lo: float | None
    hi: float | None
    if joint.type == "continuous":
        lo, hi = -math.inf, math.inf
    else:
        lo = None if limit is None else limit.lower
        hi = None if limit is None else limit.upper
    vel = None if limit is None else limit.velocity
    if model is not None:
        acc, jrk = model.joint(short).max_acceleration, model.joint(short).max_jerk
    else:
        assert robot.description is not None  # the cell schema guarantees it for model 'custom'
        acc, jrk = robot.description.default_max_acceleration, robot.description.default_max_jerk
    override = robot.joint_limits.get(short)
    if override is not None:
        lo = lo if override.min_position is None else override.min_position
        hi = hi if override.max_position is None else override.max_position
        vel = vel if override.max_velocity is None else override.max_velocity
        acc = acc if override.max_acceleration is None else override.max_acceleration
        jrk = jrk if override.max_jerk is None else override.max_jerk
    if lo is None or hi is None:
        raise DescriptionError(f"robot {robot.name!r}: joint {name!r} has no <limit lower upper> in the URDF")
    if vel is None or not 0.0 < vel < math.inf:
        raise DescriptionError(
            f"robot {robot.name!r}: joint {name!r} has no positive <limit velocity>; "
            f"set it in the description or as joint_limits.{short}.max_velocity"
        )
    effort = 0.0 if limit is None or limit.effort is None else float(limit.effort)
    return (float(lo), float(hi), float(vel), acc, jrk, effort)
