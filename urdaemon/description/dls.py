"""Damped least squares on a Jacobian, in plain float math: the per-cycle linear algebra of Cartesian motion.

``singularity(rows)`` is the smallest singular value of a 6 x n Jacobian, ``damped_velocity`` the
joint velocities for a TCP twist (damped near singularities, the law of ``UrKinematics.joint_velocity``)
and ``solve`` a small dense linear solve. No numpy: the serve process runs these every cycle and must
not load it (docs/kinematics.md, "No numpy at run time").

The Jacobian is given as rows (``rows[i][j]``: twist component i, joint j). Its smallest singular
value is the square root of the smallest eigenvalue of the Gram matrix G (J^T J for n < 6, else
J J^T), found by Laguerre's iteration on det(G - x I) from x = 0: every root is real and positive,
so the iterates rise monotonically to the smallest one (cubic convergence), each step a Cholesky
factorisation of G - x I, which also proves x is still below it.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from operator import mul

__all__ = ["cholesky_solve", "damped_velocity", "gram", "singularity", "solve"]

_MAX_STEPS = 30
_RELATIVE = 1e-5
"""Laguerre stops after a step this small relative to the eigenvalue (cubic: the next would be ~1e-15)."""
_FLOOR = 1e-16
"""... or this small relative to the Gram matrix's trace (the eigenvalue is zero to rounding)."""


def solve(a: Sequence[Sequence[float]], b: Sequence[float]) -> list[float]:
    """x with a x = b, for a small square matrix (Gaussian elimination with partial pivoting).

    Raises ZeroDivisionError when ``a`` is singular (a zero pivot)."""
    n = len(b)
    m = [[*map(float, row), float(v)] for row, v in zip(a, b, strict=True)]
    for k in range(n):
        pivot = k
        largest = abs(m[k][k])
        for i in range(k + 1, n):
            if abs(m[i][k]) > largest:
                pivot, largest = i, abs(m[i][k])
        if pivot != k:
            m[k], m[pivot] = m[pivot], m[k]
        row = m[k]
        head = row[k]
        if head == 0.0:
            raise ZeroDivisionError("singular matrix")
        tail = row[k + 1 :]
        for i in range(k + 1, n):
            other = m[i]
            f = other[k] / head
            if f != 0.0:
                other[k + 1 :] = [o - f * r for o, r in zip(other[k + 1 :], tail, strict=True)]
    x = [0.0] * n
    for k in range(n - 1, -1, -1):
        row = m[k]
        x[k] = (row[n] - sum(map(mul, row[k + 1 : n], x[k + 1 :]))) / row[k]
    return x


def cholesky_solve(g: Sequence[Sequence[float]], b: Sequence[float], shift: float = 0.0) -> list[float]:
    """x with (g + shift I) x = b, for a symmetric positive definite g + shift I (Cholesky; half LU's work).

    Raises ZeroDivisionError when g + shift I is not positive definite."""
    n = len(b)
    lower = [[0.0] * n for _ in range(n)]
    y = [0.0] * n
    for i in range(n):
        li, gi = lower[i], g[i]
        # Entries of a row past the one being set are still 0, so whole-row dot products are exact.
        for j in range(i):
            lj = lower[j]
            li[j] = (gi[j] - sum(map(mul, li, lj))) / lj[j]
        d = gi[i] + shift - sum(map(mul, li, li))
        if not d > 0.0:
            raise ZeroDivisionError("not positive definite")
        li[i] = head = math.sqrt(d)
        y[i] = (b[i] - sum(map(mul, li, y))) / head
    x = [0.0] * n
    for i in range(n - 1, -1, -1):
        s = y[i]
        for k in range(i + 1, n):
            s -= lower[k][i] * x[k]
        x[i] = s / lower[i][i]
    return x


def gram(rows: Sequence[Sequence[float]]) -> list[list[float]]:
    """The smaller Gram matrix of J: J^T J (n x n) for n < 6 joints, else J J^T (6 x 6)."""
    vectors = list(zip(*rows, strict=True)) if len(rows[0]) < len(rows) else [tuple(r) for r in rows]
    size = len(vectors)
    g = [[0.0] * size for _ in range(size)]
    for i in range(size):
        vi = vectors[i]
        for j in range(i + 1):
            g[i][j] = g[j][i] = sum(map(mul, vi, vectors[j]))
    return g


def _inverse_columns(g: list[list[float]], shift: float) -> list[list[float]] | None:
    """Columns of L^-1, L L^T = g - shift I (Cholesky); None when g - shift I is not positive definite."""
    n = len(g)
    lower = [[0.0] * n for _ in range(n)]
    columns = [[0.0] * n for _ in range(n)]
    for i in range(n):
        li, gi = lower[i], g[i]
        # Entries of a row past the one being set are still 0, so whole-row dot products are exact.
        for j in range(i):
            lj = lower[j]
            li[j] = (gi[j] - sum(map(mul, li, lj))) / lj[j]
        d = gi[i] - shift - sum(map(mul, li, li))
        if not d > 0.0:
            return None
        li[i] = math.sqrt(d)
        head = 1.0 / li[i]
        columns[i][i] = head
        for j in range(i):
            columns[j][i] = -sum(map(mul, li, columns[j])) * head
    return columns


def _smallest_eigenvalue(g: list[list[float]]) -> float:
    """The smallest eigenvalue of the positive semi-definite ``g`` (0.0 when singular to rounding)."""
    n = len(g)
    scale = sum(g[i][i] for i in range(n))
    if not scale > 0.0:
        return 0.0
    x = 0.0
    for _ in range(_MAX_STEPS):
        columns = _inverse_columns(g, x)
        if columns is None:
            return x  # rounding put x on the eigenvalue: it is as good as the arithmetic allows
        # (G - x)^-1 = M^T M (M = L^-1): sum 1/(l_i - x) is its trace, sum 1/(l_i - x)^2 that of its
        # square, the sum of squares of M^T M's entries (dot products of M's columns).
        s1 = 0.0
        s2 = 0.0
        for i in range(n):
            ci = columns[i]
            e = sum(map(mul, ci, ci))
            s1 += e
            s2 += e * e
            for j in range(i):
                e = sum(map(mul, ci, columns[j]))
                s2 += 2.0 * e * e
        step = n / (s1 + math.sqrt(max(0.0, (n - 1) * (n * s2 - s1 * s1))))
        x += step
        # Cubic convergence: a step this small leaves an error far below rounding.
        if step <= _RELATIVE * x or step <= _FLOOR * scale:
            break
    return x


def singularity(rows: Sequence[Sequence[float]]) -> float:
    """The smallest singular value of the 6 x n Jacobian ``rows`` (0.0 at an exact singularity)."""
    return math.sqrt(_smallest_eigenvalue(gram(rows)))


def damped_velocity(
    rows: Sequence[Sequence[float]],
    twist: Sequence[float],
    *,
    singular_value: float = 0.05,
    max_damping: float = 0.05,
) -> tuple[tuple[float, ...], float]:
    """Joint velocities giving ``twist`` with Jacobian ``rows``, damped near singularities; and sigma_min.

    qd = J^T (J J^T + l^2 I)^-1 twist (n >= 6) or (J^T J + l^2 I)^-1 J^T twist (n < 6: the least-squares
    twist), with l^2 = (1 - (sigma_min / singular_value)^2) max_damping^2 below ``singular_value`` and 0
    above it (the exact inverse away from singularities): ``UrKinematics.joint_velocity``'s law."""
    n = len(rows[0])
    g = gram(rows)
    sigma = math.sqrt(_smallest_eigenvalue(g))
    damping = 0.0
    if sigma < singular_value:
        damping = (1.0 - (sigma / singular_value) ** 2) * max_damping * max_damping
    v = [float(t) for t in twist]
    if n == 6 and damping == 0.0:
        return tuple(solve(rows, v)), sigma
    if n < 6:
        jt_v = [sum(rows[k][j] * v[k] for k in range(6)) for j in range(n)]
        return tuple(cholesky_solve(g, jt_v, damping)), sigma
    y = cholesky_solve(g, v, damping)
    return tuple(sum(rows[k][j] * y[k] for k in range(6)) for j in range(n)), sigma
