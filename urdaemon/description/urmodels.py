"""The shipped Universal Robots model data (``resources/ur/<model>.yaml``) as frozen, checked values.

Each file holds the nominal standard-DH kinematics, the controller's kinematics hash, per-joint limits
and per-link inertials of one arm model; ``resources/ur/README.md`` says where the numbers come from.
"""

from __future__ import annotations

import math
import re
import types
from collections.abc import Mapping
from dataclasses import dataclass
from functools import cache
from pathlib import Path
from typing import Any

import yaml

from urdaemon.description._checks import BadKey, as_float, floats, mapping, only_keys, vec3
from urdaemon.errors import DescriptionError
from urdaemon.model import UR_JOINTS
from urdaemon.paths import resource_path
from urdaemon.protocols.kinematics_hash import KINEMATICS_HASH_PATTERN

__all__ = [
    "INERTIA_KEYS",
    "UR_LINKS",
    "DhParameters",
    "LinkInertial",
    "UrJoint",
    "UrModel",
    "load_ur_model",
    "load_ur_model_file",
    "parse_dh",
]

UR_LINKS: tuple[str, ...] = (
    "base_link",
    "shoulder_link",
    "upper_arm_link",
    "forearm_link",
    "wrist_1_link",
    "wrist_2_link",
    "wrist_3_link",
)
"""The links that carry inertial data, without the robot prefix; link i+1 moves with joint i."""

INERTIA_KEYS: tuple[str, ...] = ("ixx", "iyy", "izz", "ixy", "ixz", "iyz")
"""The order of ``LinkInertial.inertia`` (the order of the data files)."""

DH_KEYS: tuple[str, ...] = ("theta", "a", "d", "alpha")
_MODEL_NAME = re.compile(r"^[a-z0-9]+$")
_HASH = KINEMATICS_HASH_PATTERN
_TOP_KEYS = ("model", "series", "robot_type", "control_rate_hz", "kinematics_hash", "dh", "joints", "links")
_SERIES = ("cb3", "e-series", "ur-series")
_RATE_KEYS = ("max_velocity", "max_effort", "max_acceleration", "max_jerk")


@dataclass(frozen=True, slots=True)
class DhParameters:
    """Standard Denavit–Hartenberg parameters of a 6-joint arm, joint order shoulder_pan … wrist_3."""

    theta: tuple[float, ...]
    a: tuple[float, ...]
    d: tuple[float, ...]
    alpha: tuple[float, ...]

    def __post_init__(self) -> None:
        for key in DH_KEYS:
            values = getattr(self, key)
            if len(values) != 6:
                raise ValueError(f"DhParameters.{key} has {len(values)} values, needs 6")
            if not all(math.isfinite(v) for v in values):
                raise ValueError(f"DhParameters.{key} must be finite: {values}")

    def plus(self, delta: DhParameters) -> DhParameters:
        """These parameters with ``delta`` added element-wise."""
        return DhParameters(
            theta=tuple(x + y for x, y in zip(self.theta, delta.theta, strict=True)),
            a=tuple(x + y for x, y in zip(self.a, delta.a, strict=True)),
            d=tuple(x + y for x, y in zip(self.d, delta.d, strict=True)),
            alpha=tuple(x + y for x, y in zip(self.alpha, delta.alpha, strict=True)),
        )


@dataclass(frozen=True, slots=True)
class UrJoint:
    """Limits of one UR joint (name without prefix); a continuous joint has no position limits."""

    name: str
    min_position: float | None
    max_position: float | None
    continuous: bool
    max_velocity: float
    max_effort: float
    max_acceleration: float
    max_jerk: float


@dataclass(frozen=True, slots=True)
class LinkInertial:
    """Mass, centre of mass (link frame), and inertia about it in a frame turned by ``center_of_mass_rpy``."""

    mass: float
    center_of_mass: tuple[float, float, float]
    center_of_mass_rpy: tuple[float, float, float]
    inertia: tuple[float, ...] | None
    """(ixx, iyy, izz, ixy, ixz, iyz) in kg·m², or None when the data has no tensor."""


@dataclass(frozen=True, slots=True)
class UrModel:
    """Everything urdaemon knows about one UR arm model."""

    model: str
    series: str
    robot_type: int
    control_rate_hz: float
    kinematics_hash: str
    dh: DhParameters
    joints: tuple[UrJoint, ...]
    links: Mapping[str, LinkInertial]
    """Link name (without prefix) → inertial; read-only."""

    def joint(self, name: str) -> UrJoint:
        """The joint called ``name`` (without prefix)."""
        for joint in self.joints:
            if joint.name == name:
                return joint
        raise KeyError(name)


@cache
def load_ur_model(name: str) -> UrModel:
    """The shipped data of UR model ``name`` (e.g. ``ur10e``), read once and cached."""
    if not _MODEL_NAME.match(name):
        raise DescriptionError(f"invalid UR model name {name!r}")
    return load_ur_model_file(resource_path("ur", f"{name}.yaml"), expected_model=name)


def load_ur_model_file(path: str | Path, *, expected_model: str | None = None) -> UrModel:
    """Read and check one model data file (uncached); errors name the file and the key."""
    path = Path(path)
    try:
        data = yaml.safe_load(path.read_text(encoding="utf-8"))
    except OSError as err:
        raise DescriptionError(f"{path}: cannot read UR model data: {err.strerror or err}") from err
    except yaml.YAMLError as err:
        raise DescriptionError(f"{path}: not valid YAML: {err}") from err
    try:
        return _parse_model(data, expected_model)
    except BadKey as err:
        raise DescriptionError(f"{path}: {err.key}: {err.reason}") from None


def parse_dh(value: Any, key: str) -> DhParameters:
    """A ``{theta, a, d, alpha}`` mapping of 6 numbers each; raises ``BadKey`` naming the key."""
    table = mapping(value, key)
    only_keys(table, key, DH_KEYS)
    lists = {k: floats(table[k], 6, f"{key}.{k}") for k in DH_KEYS}
    return DhParameters(theta=lists["theta"], a=lists["a"], d=lists["d"], alpha=lists["alpha"])


def _parse_model(data: Any, expected_model: str | None) -> UrModel:
    top = mapping(data, "(top level)")
    only_keys(top, "", _TOP_KEYS)
    model = top["model"]
    if not isinstance(model, str):
        raise BadKey("model", f"must be a string, got {model!r}")
    if expected_model is not None and model != expected_model:
        raise BadKey("model", f"says {model!r} but the file is for {expected_model!r}")
    series = top["series"]
    if series not in _SERIES:
        raise BadKey("series", f"must be one of {', '.join(_SERIES)}, got {series!r}")
    robot_type = top["robot_type"]
    if isinstance(robot_type, bool) or not isinstance(robot_type, int):
        raise BadKey("robot_type", f"must be an integer, got {robot_type!r}")
    rate = as_float(top["control_rate_hz"], "control_rate_hz", positive=True)
    kinematics_hash = top["kinematics_hash"]
    if not isinstance(kinematics_hash, str) or not _HASH.match(kinematics_hash):
        raise BadKey("kinematics_hash", f"must look like calib_<digits>, got {kinematics_hash!r}")
    dh = parse_dh(top["dh"], "dh")
    joints_table = mapping(top["joints"], "joints")
    if tuple(joints_table) != UR_JOINTS:
        raise BadKey(
            "joints",
            f"must list exactly {', '.join(UR_JOINTS)} in this order, "
            f"got {', '.join(map(str, joints_table))}",
        )
    joints = tuple(_parse_joint(name, joints_table[name]) for name in UR_JOINTS)
    links_table = mapping(top["links"], "links")
    only_keys(links_table, "links", UR_LINKS)
    links = {name: _parse_link(links_table[name], f"links.{name}") for name in UR_LINKS}
    return UrModel(
        model=model,
        series=series,
        robot_type=robot_type,
        control_rate_hz=rate,
        kinematics_hash=kinematics_hash,
        dh=dh,
        joints=joints,
        links=types.MappingProxyType(links),
    )


def _parse_joint(name: str, value: Any) -> UrJoint:
    key = f"joints.{name}"
    table = mapping(value, key)
    continuous = table.get("continuous", False)
    if not isinstance(continuous, bool):
        raise BadKey(f"{key}.continuous", f"must be true or false, got {continuous!r}")
    if continuous:
        only_keys(table, key, _RATE_KEYS, ("continuous",))
        lower = upper = None
    else:
        only_keys(table, key, ("min_position", "max_position", *_RATE_KEYS), ("continuous",))
        lower = as_float(table["min_position"], f"{key}.min_position")
        upper = as_float(table["max_position"], f"{key}.max_position")
        if lower >= upper:
            raise BadKey(f"{key}.min_position", f"{lower} must be below max_position {upper}")
    return UrJoint(
        name=name,
        min_position=lower,
        max_position=upper,
        continuous=continuous,
        max_velocity=as_float(table["max_velocity"], f"{key}.max_velocity", positive=True),
        max_effort=as_float(table["max_effort"], f"{key}.max_effort", positive=True),
        max_acceleration=as_float(table["max_acceleration"], f"{key}.max_acceleration", positive=True),
        max_jerk=as_float(table["max_jerk"], f"{key}.max_jerk", positive=True),
    )


def _parse_link(value: Any, key: str) -> LinkInertial:
    table = mapping(value, key)
    only_keys(table, key, ("mass", "center_of_mass", "inertia"), ("center_of_mass_rpy",))
    inertia: tuple[float, ...] | None = None
    if table["inertia"] is not None:
        tensor = mapping(table["inertia"], f"{key}.inertia")
        only_keys(tensor, f"{key}.inertia", INERTIA_KEYS)
        inertia = tuple(as_float(tensor[k], f"{key}.inertia.{k}") for k in INERTIA_KEYS)
    rpy = table.get("center_of_mass_rpy", (0.0, 0.0, 0.0))
    return LinkInertial(
        mass=as_float(table["mass"], f"{key}.mass", nonnegative=True),
        center_of_mass=vec3(table["center_of_mass"], f"{key}.center_of_mass"),
        center_of_mass_rpy=vec3(rpy, f"{key}.center_of_mass_rpy"),
        inertia=inertia,
    )
