"""A UR robot's factory kinematics calibration, and the URDF joint origins it (or the nominal DH) gives.

Calibration file format
-----------------------
A YAML mapping (this is what ``urdaemon calibration`` writes)::

    model: ur10e                     # optional; must equal the robot's model when given
    hash: calib_5119701370761913513  # optional; the controller's kinematics hash
    dh:                              # the calibrated DH, as the controller reports it in KINEMATICS_INFO
      theta: [6 numbers]             # rad
      a:     [6 numbers]             # m
      d:     [6 numbers]             # m
      alpha: [6 numbers]             # rad

Instead of ``dh`` the file may give ``dh_delta`` with the same four lists, which are added to the
model's nominal DH. Exactly one of ``dh`` and ``dh_delta`` must be present; no other keys are
allowed. All values are standard DH in joint order shoulder_pan … wrist_3. As a guard against a
delta given as ``dh`` (or the reverse), every resulting ``alpha`` must lie within 0.1 rad of nominal.

The joint origins
-----------------
Standard DH per joint i: the "active" part A_i = Tz(d_i)·Rz(θ_i), the joint's own rotation
Rz(q_i), then the "passive" part P_i = Tx(a_i)·Rx(α_i); FK = Π A_i·Rz(q_i)·P_i. A calibrated arm has
nearly parallel axes 2–4, so d_2 and d_3 come out hundreds of metres long with opposite signs. The
correction in ``joint_origins`` slides the frames of joints 2 and 3 along their axes back to where
the axis crosses the previous joint's z = 0 plane, which leaves FK unchanged.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from urdaemon.cell.load import load_yaml
from urdaemon.cell.robot_options import Robot
from urdaemon.description._checks import BadKey, mapping, only_keys
from urdaemon.description._transforms import (
    Matrix,
    matrix_of,
    rot_x,
    rot_z,
    rpy_of,
    trans_x,
    trans_z,
    xyz_rpy,
)
from urdaemon.description.frames import IDENTITY, Frame, compose
from urdaemon.description.urmodels import DhParameters, UrModel, load_ur_model, parse_dh
from urdaemon.errors import ConfigError, DescriptionError
from urdaemon.protocols.kinematics_hash import KINEMATICS_HASH_PATTERN

__all__ = [
    "FLANGE_RPY",
    "TOOL0_RPY",
    "Calibration",
    "Origin",
    "UrChain",
    "joint_origins",
    "load_calibration",
    "robot_dh",
]

FLANGE_RPY = (0.0, -math.pi / 2, -math.pi / 2)
"""wrist_3_link → flange rotation after the last passive part (flange: x out of the tool plate)."""
TOOL0_RPY = (math.pi / 2, 0.0, math.pi / 2)
"""flange → tool0 (tool0: z out of the tool plate; base → tool0 equals the DH FK)."""

_HASH = KINEMATICS_HASH_PATTERN
_ALPHA_TOLERANCE = 0.1
# Below this |z_z| the next joint's axis (nearly) lies in the plane and has no single crossing point.
_MIN_AXIS_Z = 1e-6


@dataclass(frozen=True, slots=True)
class Calibration:
    """A loaded calibration: the absolute calibrated DH, the hash if the file gave one, and the file."""

    dh: DhParameters
    hash: str | None
    source: str


@dataclass(frozen=True, slots=True, eq=False)
class Origin:
    """One fixed transform: the 4×4 matrix (rows) and its URDF ``xyz``/``rpy``."""

    matrix: Matrix
    xyz: tuple[float, float, float]
    rpy: tuple[float, float, float]

    @classmethod
    def of(cls, frame: Frame) -> Origin:
        """The origin of ``frame``."""
        m = matrix_of(frame)
        # adding 0.0 turns -0.0 into 0.0, which keeps the URDF text free of "-0.0" noise
        xyz = (frame[9] + 0.0, frame[10] + 0.0, frame[11] + 0.0)
        return cls(matrix=m, xyz=xyz, rpy=rpy_of(m))


@dataclass(frozen=True, slots=True, eq=False)
class UrChain:
    """URDF origins of a UR arm: six joints (parent link → joint frame) and wrist_3_link → flange."""

    joints: tuple[Origin, ...]
    flange: Origin


def load_calibration(path: str | Path, model: UrModel) -> Calibration:
    """Read the calibration file at ``path`` for a robot of ``model``; ConfigError names file, key, reason."""
    source = str(path)
    try:
        text = Path(path).read_text(encoding="utf-8")
    except OSError as err:
        raise ConfigError(f"{source}: cannot read calibration file: {err.strerror or err}") from err
    data = load_yaml(text, source)  # not YAML, a key twice or nested too deep: a ConfigError
    try:
        dh, kinematics_hash = _parse_calibration(data, model)
    except BadKey as err:
        raise ConfigError(f"{source}: {err.key}: {err.reason}") from None
    return Calibration(dh=dh, hash=kinematics_hash, source=source)


def _parse_calibration(data: Any, model: UrModel) -> tuple[DhParameters, str | None]:
    if data is None:
        raise BadKey("(top level)", "the file is empty; it needs 'dh' or 'dh_delta'")
    table = mapping(data, "(top level)")
    only_keys(table, "", (), ("model", "hash", "dh", "dh_delta"))
    if "model" in table and table["model"] != model.model:
        raise BadKey("model", f"the calibration is for {table['model']!r} but the robot is a {model.model}")
    kinematics_hash = table.get("hash")
    if kinematics_hash is not None and (
        not isinstance(kinematics_hash, str) or not _HASH.match(kinematics_hash)
    ):
        raise BadKey("hash", f"must look like calib_<digits>, got {kinematics_hash!r}")
    if ("dh" in table) == ("dh_delta" in table):
        both = "both" if "dh" in table else "neither"
        raise BadKey("dh", f"exactly one of 'dh' and 'dh_delta' must be given, found {both}")
    if "dh" in table:
        key, dh = "dh", parse_dh(table["dh"], "dh")
    else:
        key, dh = "dh_delta", model.dh.plus(parse_dh(table["dh_delta"], "dh_delta"))
    for i, (value, nominal) in enumerate(zip(dh.alpha, model.dh.alpha, strict=True)):
        if abs(value - nominal) > _ALPHA_TOLERANCE:
            raise BadKey(
                f"{key}.alpha[{i}]",
                f"gives alpha {value:.6g} rad, more than {_ALPHA_TOLERANCE} rad from the nominal "
                f"{nominal:.6g}; is this a {'dh_delta' if key == 'dh' else 'dh'} written as {key}?",
            )
    return dh, kinematics_hash


def robot_dh(robot: Robot) -> DhParameters:
    """The DH a UR robot really has: its calibration file's if it has one, else the model's nominal DH."""
    if not robot.is_ur:
        raise DescriptionError(f"robot {robot.name!r}: model 'custom' has no DH parameters")
    model = load_ur_model(robot.model)
    if robot.calibration is None:
        return model.dh
    return load_calibration(robot.calibration, model).dh


def joint_origins(dh: DhParameters, *, correct: bool = True) -> UrChain:
    """The URDF origins of the six joints and the flange for ``dh``, with the calibration correction."""
    theta, a, d, alpha = list(dh.theta), list(dh.a), list(dh.d), list(dh.alpha)
    passive: list[Frame] = [compose(trans_x(a[i]), rot_x(alpha[i])) for i in range(6)]
    if correct:
        for k in (1, 2):
            # Joint k+1's axis seen from joint k's frame (before A_k, at q_k = 0).
            step = compose(compose(trans_z(d[k]), rot_z(theta[k])), passive[k])
            ox, oy, oz = step[9], step[10], step[11]
            zx, zy, zz = step[2], step[5], step[8]
            if abs(zz) < _MIN_AXIS_Z:
                raise DescriptionError(
                    f"DH joint {k + 1}: the next joint's axis is (nearly) perpendicular to this one's; "
                    "these are not UR kinematics"
                )
            t = -oz / zz
            px, py = ox + t * zx, oy + t * zy
            # atan2(-y, -x) is atan2(y, x) - π wrapped into (-π, π]: a nominal arm (p on the
            # negative x axis) keeps θ = 0 rather than turning into -2π.
            new_theta = math.atan2(-py, -px)
            new_a = -math.hypot(px, py)
            passive[k] = compose(compose(trans_x(new_a), rot_z(theta[k] - new_theta)), rot_x(alpha[k]))
            # Joint k+1's own frame stays put: it moved by t along its axis, so d shrinks by t.
            d[k + 1] -= t
            theta[k], a[k], d[k] = new_theta, new_a, 0.0
    joints: list[Origin] = []
    previous: Frame = IDENTITY
    for i in range(6):
        joints.append(Origin.of(compose(compose(previous, trans_z(d[i])), rot_z(theta[i]))))
        previous = passive[i]
    flange = Origin.of(compose(passive[5], xyz_rpy((0.0, 0.0, 0.0), FLANGE_RPY)))
    return UrChain(joints=tuple(joints), flange=flange)
