"""The drawn and collision shapes of a UR arm's links, made from its kinematics (no mesh files).

Each link gets cylinders in its own frame, built from the joint origins the URDF uses
(calibration included, so the shapes move with the joints) and sized from the model:

- a joint housing: a cylinder along the link's z (the joint axis) at the link origin, stretched
  along z to cover the child joint's offset along that axis (the forearm's d4 at the elbow);
- a tube from there to the child joint's origin, across the axis, so with the housing the path is
  an L, as on the real arm, not a diagonal stick (its ends lie inside the housings, so it needs no
  rounded caps);
- the base (on ``base_link_inertia``): a cylinder up to the shoulder housing;
- on ``wrist_3_link``: the wrist 3 housing from the wrist 2 axis to the tool plate, and the tool
  flange disc ending on the flange frame.

Radii scale with the distance between the wrist 1 and wrist 2 axes (nominal DH ``d5``), which grows
with the joint sizes from the UR3e to the UR20/UR30 (see ``Radii.of``). The shapes are ours and
approximate: enough to recognise the arm in a viewer and for coarse collision checks.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Literal

from urdaemon.description._transforms import matrix_of, rpy_of
from urdaemon.description.calibration import Origin, UrChain
from urdaemon.description.frames import Frame, axis_rotation
from urdaemon.description.urmodels import UR_LINKS, UrModel

__all__ = ["GEOMETRY_LINKS", "MATERIALS", "Radii", "Shape", "ur_geometry"]

GEOMETRY_LINKS: tuple[str, ...] = ("base_link_inertia", *UR_LINKS[1:])
"""The links that carry shapes, without the robot prefix: the moving links, and the base on
``base_link_inertia`` (the DH base frame) instead of the mounting frame ``base_link``."""

Material = Literal["housing", "tube"]

MATERIALS: dict[Material, tuple[float, float, float, float]] = {
    "housing": (0.23, 0.29, 0.36, 1.0),  # dark blue-grey joint covers
    "tube": (0.78, 0.80, 0.82, 1.0),  # light grey tubes and base
}
"""RGBA of each material; the URDF names them ``urdaemon_ur_<key>``."""

_HOUSING_LINKS = ("shoulder_link", "upper_arm_link", "forearm_link")
_MIN_TUBE = 1e-3
"""A child joint closer than this (m) to the link's axis gets no tube: the housing covers it."""


@dataclass(frozen=True, slots=True)
class Radii:
    """The radii (m) of one model's shapes, and the housings' half-length factor."""

    joint: float
    """Base, shoulder, upper-arm and elbow housings: 0.6·d5."""
    wrist: float
    """Wrist 1, 2 and 3 housings: 0.45·d5."""
    tube: float
    """Upper arm and forearm tubes: 0.4·d5."""
    wrist_tube: float
    """The short tubes between the wrist axes: 0.25·d5 (inside the flange disc at the tool end)."""
    flange: float
    """Tool flange disc: 0.7 of the wrist radius; its thickness is 0.15 of the wrist radius."""

    @classmethod
    def of(cls, model: UrModel) -> Radii:
        """Radii from the model's nominal ``d5`` (the wrist 1 to wrist 2 axis distance)."""
        d5 = abs(model.dh.d[4])
        wrist = 0.45 * d5
        return cls(joint=0.6 * d5, wrist=wrist, tube=0.4 * d5, wrist_tube=0.25 * d5, flange=0.7 * wrist)


@dataclass(frozen=True, slots=True)
class Shape:
    """One cylinder in its link's frame: its axis is its origin's z, centred on the origin."""

    name: str
    xyz: tuple[float, float, float]
    rpy: tuple[float, float, float]
    radius: float
    length: float
    material: Material

    def params(self) -> dict[str, Any]:
        """The ``ur_arm.xacro`` params entry of this shape (``xyz`` and ``rpy`` as URDF text, which
        xacro reads with one expression each instead of three)."""
        return {
            "name": self.name,
            "xyz": " ".join(repr(v) for v in self.xyz),
            "rpy": " ".join(repr(v) for v in self.rpy),
            "radius": self.radius,
            "length": self.length,
            "material": self.material,
        }


_Vec = tuple[float, float, float]


def ur_geometry(model: UrModel, chain: UrChain) -> dict[str, tuple[Shape, ...]]:
    """The shapes of every link in ``GEOMETRY_LINKS`` for a robot whose URDF origins are ``chain``."""
    radii = Radii.of(model)
    first = chain.joints[0].xyz
    shoulder_bottom = _sub(first, _scale(_axis_z(chain.joints[0]), 0.8 * radii.joint))
    shapes: dict[str, tuple[Shape, ...]] = {
        "base_link_inertia": (_cylinder("base", (0.0, 0.0, 0.0), shoulder_bottom, radii.joint, "tube"),),
    }
    moving = GEOMETRY_LINKS[1:]
    for index, link in enumerate(moving[:-1]):
        big = link in _HOUSING_LINKS
        shapes[link] = _arm_link(
            chain.joints[index + 1].xyz,
            radii.joint if big else radii.wrist,
            radii.tube if big else radii.wrist_tube,
        )
    shapes["wrist_3_link"] = _wrist_3(chain.flange, abs(model.dh.d[5]), radii)
    return shapes


def _arm_link(child: _Vec, housing: float, tube: float) -> tuple[Shape, ...]:
    """Housing along z covering the child's offset along the axis, then a tube across to it."""
    half = 0.8 * housing
    corner = (0.0, 0.0, child[2])
    low, high = min(0.0, child[2]) - half, max(0.0, child[2]) + half
    shapes = [_cylinder("housing", (0.0, 0.0, low), (0.0, 0.0, high), housing, "housing")]
    if _norm(_sub(child, corner)) > _MIN_TUBE:
        shapes.append(_cylinder("tube", corner, child, tube, "tube"))
    return tuple(shapes)


def _wrist_3(flange: Origin, d6: float, radii: Radii) -> tuple[Shape, ...]:
    """The wrist 3 housing from the wrist 2 axis to the tool plate, then the flange disc."""
    plate = flange.xyz
    normal = (flange.matrix[0][0], flange.matrix[1][0], flange.matrix[2][0])  # the flange's x
    thickness = 0.15 * radii.wrist
    inner = _sub(plate, _scale(normal, thickness))
    return (
        _cylinder("housing", _sub(plate, _scale(normal, d6)), inner, radii.wrist, "housing"),
        _cylinder("flange", inner, plate, radii.flange, "tube"),
    )


def _cylinder(name: str, start: _Vec, end: _Vec, radius: float, material: Material) -> Shape:
    """A cylinder whose axis runs from ``start`` to ``end``."""
    axis = _sub(end, start)
    length = _norm(axis)
    centre = _scale(_add(start, end), 0.5)
    return Shape(name, centre, _rpy_along(_scale(axis, 1.0 / length)), radius, length, material)


def _rpy_along(direction: _Vec) -> _Vec:
    """URDF rpy of a rotation taking z onto the unit vector ``direction`` (shortest turn)."""
    x, y, z = direction
    across = math.hypot(x, y)  # |z × direction|
    if across < 1e-15:
        return (0.0, 0.0, 0.0) if z > 0 else (math.pi, 0.0, 0.0)
    turn: Frame = axis_rotation(-y / across, x / across, 0.0, math.atan2(across, z))
    return rpy_of(matrix_of(turn))


def _axis_z(origin: Origin) -> _Vec:
    m = origin.matrix
    return (m[0][2], m[1][2], m[2][2])


def _add(a: _Vec, b: _Vec) -> _Vec:
    return (a[0] + b[0], a[1] + b[1], a[2] + b[2])


def _sub(a: _Vec, b: _Vec) -> _Vec:
    return (a[0] - b[0], a[1] - b[1], a[2] - b[2])


def _scale(a: _Vec, k: float) -> _Vec:
    return (a[0] * k, a[1] * k, a[2] * k)


def _norm(a: _Vec) -> float:
    return math.sqrt(a[0] * a[0] + a[1] * a[1] + a[2] * a[2])
