"""Helpers for the description tests: an independent DH forward kinematics, cells, calibrations."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np
import yaml
from numpy.typing import NDArray

from urdaemon.cell import Cell
from urdaemon.description import DhParameters

__all__ = [
    "DATA",
    "REAL_UR10E",
    "dh_fk",
    "make_cell",
    "quat_matrix",
    "random_calibration",
    "write_calibration",
]

DATA = Path(__file__).resolve().parent / "data"

REAL_UR10E = DhParameters(
    # A real UR10e's calibrated DH as its controller reported it; published in the documentation of
    # UR's ROS 2 driver (ur_calibration, "Calibration correction algorithm").
    theta=(-2.4147806894359e-07, 1.60233952386695, -1.68607190752171, 0.0837331147700119,
           -1.01260355871158e-07, 3.91986209186124e-08),
    a=(2.12234865571206e-05, 0.0193171326277006, -0.569251663611088, -4.61409023720934e-05,
       -6.39280053471802e-05, 0.0),
    d=(0.180539811714259, 439.140974079901, -446.027059806332, 7.0603368964236, 0.119811341150314,
       0.115670917257426),
    alpha=(1.57014608044242, 0.0013941666682559, 0.00693818880325995, 1.56998468543761,
           -1.57038520649543, 0.0),
)  # fmt: skip

Matrix = NDArray[np.float64]


def _tz(d: float) -> Matrix:
    m = np.eye(4)
    m[2, 3] = d
    return m


def _tx(a: float) -> Matrix:
    m = np.eye(4)
    m[0, 3] = a
    return m


def _rz(angle: float) -> Matrix:
    c, s = math.cos(angle), math.sin(angle)
    return np.array([[c, -s, 0.0, 0.0], [s, c, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0], [0.0, 0.0, 0.0, 1.0]])


def _rx(angle: float) -> Matrix:
    c, s = math.cos(angle), math.sin(angle)
    return np.array([[1.0, 0.0, 0.0, 0.0], [0.0, c, -s, 0.0], [0.0, s, c, 0.0], [0.0, 0.0, 0.0, 1.0]])


def dh_fk(dh: DhParameters, q: Any) -> Matrix:
    """Tool frame in the DH base frame: Π Tz(d)·Rz(θ)·Rz(q)·Tx(a)·Rx(α)."""
    t = np.eye(4)
    for i in range(6):
        t = t @ _tz(dh.d[i]) @ _rz(dh.theta[i]) @ _rz(float(q[i])) @ _tx(dh.a[i]) @ _rx(dh.alpha[i])
    return t


def quat_matrix(x: float, y: float, z: float, w: float) -> Matrix:
    """Rotation matrix of a unit quaternion (x, y, z, w)."""
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )


def random_calibration(nominal: DhParameters, rng: np.random.Generator) -> DhParameters:
    """Small random deltas on all four lists, plus huge opposite d2/d3 that d4 compensates."""
    d2 = 439.2 + rng.uniform(-1.0, 1.0)
    d3 = -446.3 + rng.uniform(-1.0, 1.0)
    big = np.array([0.0, d2, d3, -(d2 + d3), 0.0, 0.0])
    # Tiny alphas: with a 440 m lever, 1e-5 rad already moves the arm by 4 mm.
    return DhParameters(
        theta=tuple(float(v) for v in np.array(nominal.theta) + rng.uniform(-0.01, 0.01, 6)),
        a=tuple(float(v) for v in np.array(nominal.a) + rng.uniform(-1e-3, 1e-3, 6)),
        d=tuple(float(v) for v in np.array(nominal.d) + rng.uniform(-1e-3, 1e-3, 6) + big),
        alpha=tuple(float(v) for v in np.array(nominal.alpha) + rng.uniform(-1e-5, 1e-5, 6)),
    )


def write_calibration(
    path: Path, dh: DhParameters, *, nominal: DhParameters | None = None, **extra: Any
) -> Path:
    """Write ``dh`` as a calibration file: absolute, or as ``dh_delta`` from ``nominal`` when given."""
    lists = {k: list(getattr(dh, k)) for k in ("theta", "a", "d", "alpha")}
    if nominal is None:
        body: dict[str, Any] = {**extra, "dh": lists}
    else:
        delta = {k: [v - n for v, n in zip(lists[k], getattr(nominal, k), strict=True)] for k in lists}
        body = {**extra, "dh_delta": delta}
    path.write_text(yaml.safe_dump(body), encoding="utf-8")
    return path


def make_cell(tmp_path: Path, *robots: dict[str, Any], name: str = "testcell") -> Cell:
    """A validated cell with ``robots`` (backend defaults to mock), paths relative to ``tmp_path``."""
    entries = [{"backend": "mock", **robot} for robot in robots]
    return Cell.model_validate({"cell": name, "robots": entries}, context={"base_dir": tmp_path})
