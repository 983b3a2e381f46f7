"""Damped least squares in plain floats (urdaemon.description.dls) against numpy's SVD.

Random 6 x n Jacobians (n = 1 ... 8), some made near or exactly singular, and a UR arm's Jacobians at
regular and singular joints. New module: every test fails on the code before it (no dls.py).
"""

from __future__ import annotations

import math
import subprocess
import sys

import numpy as np
import pytest

from urdaemon.description import UrKinematics, load_ur_model
from urdaemon.description.dls import damped_velocity, singularity, solve

GENERIC_Q = (-1.23, -1.67, 1.42, 1.45, 1.51, -0.11)


def _jacobians(n: int, seed: int) -> list[np.ndarray]:
    """Random 6 x n matrices: generic, with a smallest singular value from 1e-9 to 1, and rank-deficient."""
    rng = np.random.default_rng(seed)
    out = []
    for k in range(60):
        jac = rng.normal(size=(6, n))
        if k % 3 == 1:
            u, s, vt = np.linalg.svd(jac, full_matrices=False)
            s[-1] *= 10.0 ** rng.uniform(-9.0, 0.0)
            jac = (u * s) @ vt
        elif k % 3 == 2 and n > 1:
            jac[:, -1] = jac[:, 0]
        out.append(jac)
    return out


def _reference(jac: np.ndarray, twist: np.ndarray, singular_value: float, max_damping: float) -> np.ndarray:
    """UrKinematics.joint_velocity's law on numpy's SVD, for any n."""
    u, sigma, vt = np.linalg.svd(jac, full_matrices=False)
    smallest = float(sigma[-1]) if jac.shape[1] <= 6 else float(sigma[5])
    damping = 0.0
    if smallest < singular_value:
        damping = (1.0 - (smallest / singular_value) ** 2) * max_damping**2
    with np.errstate(divide="ignore"):
        gain = sigma / (sigma * sigma + damping) if damping > 0.0 else 1.0 / sigma
    return np.asarray(vt.T @ (gain * (u.T @ twist)))


@pytest.mark.parametrize("n", [1, 2, 3, 4, 5, 6, 7, 8])
def test_singularity_is_numpys_smallest_singular_value(n: int) -> None:
    """sigma_min to 1e-8 of the largest singular value (the Gram matrix's rounding), exact zero included."""
    for jac in _jacobians(n, n):
        sigma = np.linalg.svd(jac, compute_uv=False)
        expected = float(sigma[min(n, 6) - 1])
        got = singularity(jac.tolist())
        assert abs(got - expected) <= 1e-8 * float(sigma[0]), (got, expected)
        if expected > 1e-4 * float(sigma[0]):
            assert abs(got - expected) <= 1e-9 * expected * (float(sigma[0]) / expected) ** 2


@pytest.mark.parametrize("n", [2, 5, 6, 7])
def test_damped_velocity_follows_the_joint_velocity_law(n: int) -> None:
    """qd matches the SVD form of the damped law, away from, near and at singularities."""
    rng = np.random.default_rng(40 + n)
    for jac in _jacobians(n, 20 + n):
        twist = rng.normal(size=6)
        sigma_max = float(np.linalg.svd(jac, compute_uv=False)[0])
        qd, sigma = damped_velocity(jac.tolist(), twist.tolist(), singular_value=0.2 * sigma_max)
        expected = _reference(jac, twist, 0.2 * sigma_max, 0.05)
        assert len(qd) == n
        assert math.isclose(sigma, singularity(jac.tolist()), rel_tol=1e-12, abs_tol=1e-300)
        assert np.allclose(qd, expected, rtol=1e-6, atol=1e-6 * float(np.abs(expected).max())), (qd, expected)


def test_damped_velocity_matches_ur_kinematics_near_singularities() -> None:
    """On a UR10e: regular, near-wrist-singular and exactly singular joints give joint_velocity's answer."""
    kin = UrKinematics(load_ur_model("ur10e"))
    twist = (0.05, -0.02, 0.03, 0.1, -0.2, 0.05)
    for q in (
        GENERIC_Q,
        (0.3, -1.2, 1.1, -0.4, 1e-3, 0.2),
        (0.3, -1.2, 1.1, -0.4, 0.0, 0.2),
        (0.1, -1.0, 0.0, 0.5, 1.0, 0.0),
    ):
        rows = kin.jacobian_rows(q)
        assert all(type(v) is float for row in rows for v in row)
        assert np.allclose(np.array(rows), kin.jacobian(q), rtol=0.0, atol=1e-15)
        qd, sigma = damped_velocity(rows, twist)
        expected = kin.joint_velocity(q, twist)
        assert np.allclose(qd, expected, rtol=1e-7, atol=1e-9), (q, qd, expected)
        assert abs(sigma - float(np.linalg.svd(kin.jacobian(q), compute_uv=False)[-1])) < 1e-8


def test_solve_against_numpy() -> None:
    """The pure solve agrees with numpy's on random and badly scaled systems; a singular one raises."""
    rng = np.random.default_rng(7)
    for size in (1, 3, 6):
        for _ in range(50):
            a = rng.normal(size=(size, size)) * 10.0 ** rng.uniform(-3, 3, size=(size, 1))
            b = rng.normal(size=size)
            assert np.allclose(solve(a.tolist(), b.tolist()), np.linalg.solve(a, b), rtol=1e-8, atol=1e-10)
    with pytest.raises(ZeroDivisionError):
        solve([[1.0, 2.0], [2.0, 4.0]], [1.0, 1.0])


def test_dls_loads_no_numpy() -> None:
    """dls runs in the serve process, which must not load numpy."""
    probe = (
        "import sys\nfrom urdaemon.description.dls import damped_velocity\n"
        "damped_velocity([[float(i == j) for j in range(6)] for i in range(6)], [0.1] * 6)\n"
        "print('numpy' in sys.modules)"
    )
    done = subprocess.run(
        [sys.executable, "-c", probe], capture_output=True, text=True, timeout=60, check=True
    )
    assert done.stdout.strip() == "False"
