"""The closed-form inverse kinematics of a UR arm on its nominal DH: the first stage of ``UrKinematics``
(ik.py), whose Newton steps then bring each branch onto the calibrated arm.

Branches: bit 2 ``SHOULDER`` (q1 = phi + pi/2 - acos(d4/r) instead of + acos), bit 1 ``WRIST`` (q5 <= 0),
bit 0 ``ELBOW`` (q3 <= 0). At a singular pose two branches coincide; a joint the pose leaves free
(q6 with the wrist straight, q5 = 0 or pi) takes the seed's value. docs/kinematics.md has the details.
"""

from __future__ import annotations

import math

from urdaemon.description.frames import Frame
from urdaemon.description.ik_types import Vector
from urdaemon.description.urmodels import UrModel
from urdaemon.errors import DescriptionError

__all__ = ["ELBOW", "SHOULDER", "WRIST", "UrClosedForm"]

SHOULDER, WRIST, ELBOW = 4, 2, 1

_HALF_PI = 0.5 * math.pi
_NOMINAL_ALPHA = (_HALF_PI, 0.0, 0.0, _HALF_PI, -_HALF_PI, 0.0)
_REACH_SLACK = 0.05
"""How far (cosine units) past the nominal arm's reach a pose is still tried on a calibrated arm (~5 mm)."""
_ROUNDING = 1e-9
"""Cosines this far past +-1 are rounding: clamped, on every arm."""
_NUDGE = 0.1
"""rad off a singularity where a pose just out of the nominal arm's reach starts Newton's steps."""
_WRIST_SINGULAR = 1e-10
"""Below this |sin q5| the wrist is straight: joint 6's axis parallels joints 2-4; q6 takes the seed's."""


def _branch_acos(value: float, negative: bool, slack: float) -> float | None:
    """acos of ``value``, negated for the negative branch; None when outside [-1, 1] by more than ``slack``.

    Rounding past +-1 is clamped. A value further out but within ``slack`` (the nominal arm just
    cannot reach, the calibrated one may) gives an angle ``_NUDGE`` inside the singularity rather than
    on it, so that Newton's steps on the calibrated arm can leave it (at the singularity the missing
    direction is not in the Jacobian)."""
    if value > 1.0:
        angle = 0.0 if value - 1.0 <= _ROUNDING else _NUDGE if value - 1.0 <= slack else None
    elif value < -1.0:
        angle = math.pi if -1.0 - value <= _ROUNDING else math.pi - _NUDGE if -1.0 - value <= slack else None
    else:
        angle = math.acos(value)
    if angle is None:
        return None
    return -angle if negative else angle


class UrClosedForm:
    """Up to eight branches of a pose on a UR model's nominal DH, as (branch bits, joints).

    ``calibrated``: the arm's real DH differs from the nominal one, so a pose up to ``_REACH_SLACK``
    past the nominal arm's reach is still tried (from just inside the singularity, for Newton's steps
    on the calibrated arm to finish). Raises DescriptionError for a nominal DH without the UR arm's
    structure."""

    __slots__ = ("_a2", "_a3", "_d1", "_d4", "_d5", "_d6", "_slack")

    def __init__(self, model: UrModel, calibrated: bool) -> None:
        nominal = model.dh
        structure_ok = (
            all(abs(t) < 1e-12 for t in nominal.theta)
            and all(abs(nominal.a[i]) < 1e-12 for i in (0, 3, 4, 5))
            and all(abs(nominal.d[i]) < 1e-12 for i in (1, 2))
            and all(abs(x - y) < 1e-12 for x, y in zip(nominal.alpha, _NOMINAL_ALPHA, strict=True))
            and nominal.a[1] != 0.0
            and nominal.a[2] != 0.0
            and nominal.d[3] != 0.0
        )
        if not structure_ok:
            raise DescriptionError(
                f"model {model.model!r}: the nominal DH does not have the UR arm's structure"
            )
        self._a2, self._a3 = nominal.a[1], nominal.a[2]
        self._d1, self._d4, self._d5, self._d6 = nominal.d[0], nominal.d[3], nominal.d[4], nominal.d[5]
        self._slack = _REACH_SLACK if calibrated else 0.0

    def branches(self, f: Frame, seed: Vector) -> list[tuple[int, list[float]]]:
        """The closed-form solutions on the nominal DH, as (branch, joints); unreachable branches left out."""
        r00, r01, r02, r10, r11, r12, _, _, _, px, py, _ = f
        d4, d6 = self._d4, self._d6
        wx, wy = px - d6 * r02, py - d6 * r12
        radius = math.hypot(wx, wy)
        # Joint 2's axis z1 = (sin q1, -cos q1, 0); the wrist centre lies d4 along it: w . z1 = d4.
        if not radius > 0.0:
            return []
        phi = math.atan2(wy, wx) + _HALF_PI
        slack = self._slack
        found: list[tuple[int, list[float]]] = []
        for shoulder in (0, SHOULDER):
            spread = _branch_acos(d4 / radius, shoulder != 0, slack)
            if spread is None:
                return []
            q1 = phi + spread
            s1, c1 = math.sin(q1), math.cos(q1)
            # The tool z axis against z1 is cos q5; its x and y axes against z1 give q6.
            c5 = min(1.0, max(-1.0, r02 * s1 - r12 * c1))
            for wrist in (0, WRIST):
                q5 = math.acos(c5) if wrist == 0 else -math.acos(c5)
                s5 = math.sin(q5)
                if abs(s5) < _WRIST_SINGULAR:
                    q6 = float(seed[5])
                else:
                    q6 = math.atan2((r11 * c1 - r01 * s1) / s5, (r00 * s1 - r10 * c1) / s5)
                self._arm_plane(found, shoulder | wrist, f, q1, q5, q6, seed)
        return found

    def _arm_plane(
        self,
        found: list[tuple[int, list[float]]],
        branch: int,
        f: Frame,
        q1: float,
        q5: float,
        q6: float,
        seed: Vector,
    ) -> None:
        """Joints 2-4 (parallel axes) for given q1, q5, q6: both elbow branches, appended to ``found``."""
        r00, r01, r02, r10, r11, r12, r20, r21, r22, px, py, pz = f
        a2, a3, d5, d6 = self._a2, self._a3, self._d5, self._d6
        s1, c1 = math.sin(q1), math.cos(q1)
        s5, c5, s6, c6 = math.sin(q5), math.cos(q5), math.sin(q6), math.cos(q6)
        # Frame 4 from the tool: z4 = -s6 n - c6 o, x4 = c5 c6 n - c5 s6 o - s5 a (n, o, a: tool axes).
        o4x = px - d6 * r02 + d5 * (s6 * r00 + c6 * r01)
        o4y = py - d6 * r12 + d5 * (s6 * r10 + c6 * r11)
        o4z = pz - d6 * r22 + d5 * (s6 * r20 + c6 * r21)
        x4x = c5 * c6 * r00 - c5 * s6 * r01 - s5 * r02
        x4y = c5 * c6 * r10 - c5 * s6 * r11 - s5 * r12
        x4z = c5 * c6 * r20 - c5 * s6 * r21 - s5 * r22
        # In joint 2's plane (x1 = (c1, s1, 0), y1 = base z, origin at height d1) joints 2-4 are planar.
        x = c1 * o4x + s1 * o4y
        y = o4z - self._d1
        angle234 = math.atan2(x4z, c1 * x4x + s1 * x4y)
        cosine = (x * x + y * y - a2 * a2 - a3 * a3) / (2.0 * a2 * a3)
        reach = math.atan2(y, x) if x * x + y * y > 0.0 else float(seed[1])
        for bit in (0, ELBOW):
            q3 = _branch_acos(cosine, bit != 0, self._slack)
            if q3 is None:
                return
            q2 = reach - math.atan2(a3 * math.sin(q3), a2 + a3 * math.cos(q3))
            found.append((branch | bit, [q1, q2, q3, angle234 - q2 - q3, q5, q6]))
