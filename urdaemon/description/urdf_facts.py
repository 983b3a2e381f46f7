"""The URDF's kinematic facts (links, joints: type, parent, child, origin, axis, limit, mimic).

Read with ``xml.etree.ElementTree`` in plain floats, so the serve process needs neither yourdfpy nor
the trimesh, scipy and networkx it pulls in. The shape mirrors the parts of yourdfpy's ``URDF`` that
``KinematicTree.from_urdf``, ``robot_joint_names`` and ``joint_limits_for`` read (``robot.joints``,
``joint_map``, ``base_link``), with the same defaults, so either may be passed to them.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from dataclasses import dataclass, field

from urdaemon.description._transforms import Matrix, xyz_rpy_matrix
from urdaemon.errors import DescriptionError

__all__ = ["FactJoint", "FactLimit", "FactMimic", "UrdfFacts", "read_urdf_facts"]


@dataclass(frozen=True)
class FactLimit:
    """``<limit>``: each attribute None when absent."""

    lower: float | None
    upper: float | None
    velocity: float | None
    effort: float | None


@dataclass(frozen=True)
class FactMimic:
    """``<mimic joint multiplier offset>`` (defaults 1 and 0)."""

    joint: str
    multiplier: float
    offset: float


@dataclass(frozen=True)
class FactJoint:
    """One ``<joint>``: ``origin`` 4x4 row-major (None without ``<origin>``), axis (1, 0, 0) if absent."""

    name: str
    type: str | None
    parent: str
    child: str
    origin: Matrix | None
    axis: tuple[float, float, float]
    limit: FactLimit | None
    mimic: FactMimic | None


@dataclass(frozen=True)
class FactRobot:
    """The joints and links in document order."""

    joints: tuple[FactJoint, ...]
    links: tuple[str, ...]


@dataclass(frozen=True)
class UrdfFacts:
    """A URDF's kinematic facts."""

    robot: FactRobot
    joint_map: dict[str, FactJoint] = field(repr=False)
    base_link: str | None


def _floats(text: str, name: str) -> tuple[float, float, float]:
    values = tuple(float(v) for v in text.split())
    if len(values) != 3:
        raise DescriptionError(f"cannot read the URDF: {name} {text!r} is not three numbers")
    return values[0], values[1], values[2]


def _origin(element: ET.Element | None) -> Matrix | None:
    """xyz and rpy as the matrix ``T(xyz) Rz(yaw) Ry(pitch) Rx(roll)``."""
    if element is None:
        return None
    return xyz_rpy_matrix(
        _floats(element.get("xyz", "0 0 0"), "xyz"), _floats(element.get("rpy", "0 0 0"), "rpy")
    )


def _optional(element: ET.Element, name: str) -> float | None:
    value = element.get(name)
    return None if value is None else float(value)


def _joint(element: ET.Element) -> FactJoint:
    parent, child = element.find("parent"), element.find("child")
    if parent is None or child is None:
        raise DescriptionError(f"cannot read the URDF: joint {element.get('name')!r} lacks parent or child")
    axis = element.find("axis")
    limit = element.find("limit")
    mimic = element.find("mimic")
    return FactJoint(
        name=element.attrib["name"],
        type=element.get("type"),
        parent=parent.attrib["link"],
        child=child.attrib["link"],
        origin=_origin(element.find("origin")),
        axis=(1.0, 0.0, 0.0) if axis is None else _floats(axis.get("xyz", "1 0 0"), "axis"),
        limit=None
        if limit is None
        else FactLimit(
            _optional(limit, "lower"),
            _optional(limit, "upper"),
            _optional(limit, "velocity"),
            _optional(limit, "effort"),
        ),
        mimic=None
        if mimic is None
        else FactMimic(
            mimic.attrib["joint"], float(mimic.get("multiplier", 1.0)), float(mimic.get("offset", 0.0))
        ),
    )


def read_urdf_facts(text: str) -> UrdfFacts:
    """Parse URDF text into its kinematic facts; DescriptionError if it cannot be read."""
    try:
        root = ET.fromstring(text)
        joints = tuple(_joint(e) for e in root.findall("joint"))
        links = tuple(e.attrib["name"] for e in root.findall("link"))
    except (ET.ParseError, KeyError, ValueError) as err:
        raise DescriptionError(f"cannot read the URDF: {type(err).__name__}: {err}") from err
    children = {j.child for j in joints}
    roots = [link for link in links if link not in children]
    return UrdfFacts(
        robot=FactRobot(joints, links),
        joint_map={j.name: j for j in joints},
        base_link=roots[0] if len(roots) == 1 else None,
    )
