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

__all__ = ["cholesky_solve", "damped_step6", "damped_velocity", "gram", "singularity", "solve"]

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


def damped_step6(rows: Sequence[Sequence[float]], error: Sequence[float], damping: float) -> list[float]:
    """J^T (J J^T + damping I)^-1 error for a 6 x 6 Jacobian ``rows``: a Levenberg-Marquardt step.

    ``gram`` and ``cholesky_solve`` unrolled on local variables (five times faster in CPython: it is
    the inner step of ``UrKinematics`` and ``ChainKinematics``). Raises ZeroDivisionError when
    J J^T + damping I is not positive definite."""
    x = _cholesky_solve6(_gram6(rows, damping), error)
    return [sum(map(mul, column, x)) for column in zip(*rows, strict=True)]


def _gram6(rows: Sequence[Sequence[float]], shift: float) -> tuple[float, ...]:
    """The lower triangle of J J^T + shift I, row by row (g00, g10, g11, g20, ...)."""
    r0, r1, r2, r3, r4, r5 = rows
    j00, j01, j02, j03, j04, j05 = r0
    j10, j11, j12, j13, j14, j15 = r1
    j20, j21, j22, j23, j24, j25 = r2
    j30, j31, j32, j33, j34, j35 = r3
    j40, j41, j42, j43, j44, j45 = r4
    j50, j51, j52, j53, j54, j55 = r5
    g00 = j00 * j00 + j01 * j01 + j02 * j02 + j03 * j03 + j04 * j04 + j05 * j05 + shift
    g10 = j10 * j00 + j11 * j01 + j12 * j02 + j13 * j03 + j14 * j04 + j15 * j05
    g11 = j10 * j10 + j11 * j11 + j12 * j12 + j13 * j13 + j14 * j14 + j15 * j15 + shift
    g20 = j20 * j00 + j21 * j01 + j22 * j02 + j23 * j03 + j24 * j04 + j25 * j05
    g21 = j20 * j10 + j21 * j11 + j22 * j12 + j23 * j13 + j24 * j14 + j25 * j15
    g22 = j20 * j20 + j21 * j21 + j22 * j22 + j23 * j23 + j24 * j24 + j25 * j25 + shift
    g30 = j30 * j00 + j31 * j01 + j32 * j02 + j33 * j03 + j34 * j04 + j35 * j05
    g31 = j30 * j10 + j31 * j11 + j32 * j12 + j33 * j13 + j34 * j14 + j35 * j15
    g32 = j30 * j20 + j31 * j21 + j32 * j22 + j33 * j23 + j34 * j24 + j35 * j25
    g33 = j30 * j30 + j31 * j31 + j32 * j32 + j33 * j33 + j34 * j34 + j35 * j35 + shift
    g40 = j40 * j00 + j41 * j01 + j42 * j02 + j43 * j03 + j44 * j04 + j45 * j05
    g41 = j40 * j10 + j41 * j11 + j42 * j12 + j43 * j13 + j44 * j14 + j45 * j15
    g42 = j40 * j20 + j41 * j21 + j42 * j22 + j43 * j23 + j44 * j24 + j45 * j25
    g43 = j40 * j30 + j41 * j31 + j42 * j32 + j43 * j33 + j44 * j34 + j45 * j35
    g44 = j40 * j40 + j41 * j41 + j42 * j42 + j43 * j43 + j44 * j44 + j45 * j45 + shift
    g50 = j50 * j00 + j51 * j01 + j52 * j02 + j53 * j03 + j54 * j04 + j55 * j05
    g51 = j50 * j10 + j51 * j11 + j52 * j12 + j53 * j13 + j54 * j14 + j55 * j15
    g52 = j50 * j20 + j51 * j21 + j52 * j22 + j53 * j23 + j54 * j24 + j55 * j25
    g53 = j50 * j30 + j51 * j31 + j52 * j32 + j53 * j33 + j54 * j34 + j55 * j35
    g54 = j50 * j40 + j51 * j41 + j52 * j42 + j53 * j43 + j54 * j44 + j55 * j45
    g55 = j50 * j50 + j51 * j51 + j52 * j52 + j53 * j53 + j54 * j54 + j55 * j55 + shift
    return (
        g00,
        g10,
        g11,
        g20,
        g21,
        g22,
        g30,
        g31,
        g32,
        g33,
        g40,
        g41,
        g42,
        g43,
        g44,
        g50,
        g51,
        g52,
        g53,
        g54,
        g55,
    )


def _cholesky_solve6(g: tuple[float, ...], b: Sequence[float]) -> list[float]:
    """x with G x = b, G given as ``_gram6``'s lower triangle (Cholesky on local variables)."""
    g00, g10, g11, g20, g21, g22, g30, g31, g32, g33 = g[:10]
    g40, g41, g42, g43, g44, g50, g51, g52, g53, g54, g55 = g[10:]
    b0, b1, b2, b3, b4, b5 = b
    l00 = _root(g00)
    l10 = (g10) / l00
    l11 = _root(g11 - l10 * l10)
    l20 = (g20) / l00
    l21 = (g21 - l20 * l10) / l11
    l22 = _root(g22 - l20 * l20 - l21 * l21)
    l30 = (g30) / l00
    l31 = (g31 - l30 * l10) / l11
    l32 = (g32 - l30 * l20 - l31 * l21) / l22
    l33 = _root(g33 - l30 * l30 - l31 * l31 - l32 * l32)
    l40 = (g40) / l00
    l41 = (g41 - l40 * l10) / l11
    l42 = (g42 - l40 * l20 - l41 * l21) / l22
    l43 = (g43 - l40 * l30 - l41 * l31 - l42 * l32) / l33
    l44 = _root(g44 - l40 * l40 - l41 * l41 - l42 * l42 - l43 * l43)
    l50 = (g50) / l00
    l51 = (g51 - l50 * l10) / l11
    l52 = (g52 - l50 * l20 - l51 * l21) / l22
    l53 = (g53 - l50 * l30 - l51 * l31 - l52 * l32) / l33
    l54 = (g54 - l50 * l40 - l51 * l41 - l52 * l42 - l53 * l43) / l44
    l55 = _root(g55 - l50 * l50 - l51 * l51 - l52 * l52 - l53 * l53 - l54 * l54)
    y0 = (b0) / l00
    y1 = (b1 - l10 * y0) / l11
    y2 = (b2 - l20 * y0 - l21 * y1) / l22
    y3 = (b3 - l30 * y0 - l31 * y1 - l32 * y2) / l33
    y4 = (b4 - l40 * y0 - l41 * y1 - l42 * y2 - l43 * y3) / l44
    y5 = (b5 - l50 * y0 - l51 * y1 - l52 * y2 - l53 * y3 - l54 * y4) / l55
    x5 = (y5) / l55
    x4 = (y4 - l54 * x5) / l44
    x3 = (y3 - l43 * x4 - l53 * x5) / l33
    x2 = (y2 - l32 * x3 - l42 * x4 - l52 * x5) / l22
    x1 = (y1 - l21 * x2 - l31 * x3 - l41 * x4 - l51 * x5) / l11
    x0 = (y0 - l10 * x1 - l20 * x2 - l30 * x3 - l40 * x4 - l50 * x5) / l00
    return [x0, x1, x2, x3, x4, x5]


def _root(d: float) -> float:
    """sqrt of a Cholesky pivot; ZeroDivisionError when it is not positive."""
    if not d > 0.0:
        raise ZeroDivisionError("not positive definite")
    return math.sqrt(d)


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


def _factor6(g: tuple[float, ...], shift: float) -> tuple[float, ...]:
    """The Cholesky factor of G - shift I (lower triangles, ``_gram6``'s order); ZeroDivisionError if
    G - shift I is not positive definite."""
    g00, g10, g11, g20, g21, g22, g30, g31, g32, g33 = g[:10]
    g40, g41, g42, g43, g44, g50, g51, g52, g53, g54, g55 = g[10:]
    l00 = _root(g00 - shift)
    l10 = (g10) / l00
    l11 = _root(g11 - l10 * l10 - shift)
    l20 = (g20) / l00
    l21 = (g21 - l20 * l10) / l11
    l22 = _root(g22 - l20 * l20 - l21 * l21 - shift)
    l30 = (g30) / l00
    l31 = (g31 - l30 * l10) / l11
    l32 = (g32 - l30 * l20 - l31 * l21) / l22
    l33 = _root(g33 - l30 * l30 - l31 * l31 - l32 * l32 - shift)
    l40 = (g40) / l00
    l41 = (g41 - l40 * l10) / l11
    l42 = (g42 - l40 * l20 - l41 * l21) / l22
    l43 = (g43 - l40 * l30 - l41 * l31 - l42 * l32) / l33
    l44 = _root(g44 - l40 * l40 - l41 * l41 - l42 * l42 - l43 * l43 - shift)
    l50 = (g50) / l00
    l51 = (g51 - l50 * l10) / l11
    l52 = (g52 - l50 * l20 - l51 * l21) / l22
    l53 = (g53 - l50 * l30 - l51 * l31 - l52 * l32) / l33
    l54 = (g54 - l50 * l40 - l51 * l41 - l52 * l42 - l53 * l43) / l44
    l55 = _root(g55 - l50 * l50 - l51 * l51 - l52 * l52 - l53 * l53 - l54 * l54 - shift)
    return (
        l00,
        l10,
        l11,
        l20,
        l21,
        l22,
        l30,
        l31,
        l32,
        l33,
        l40,
        l41,
        l42,
        l43,
        l44,
        l50,
        l51,
        l52,
        l53,
        l54,
        l55,
    )


def _laguerre_sums6(factor: tuple[float, ...]) -> tuple[float, float]:
    """trace((G - x)^-1) and trace((G - x)^-2) from the Cholesky factor L of G - x: with M = L^-1,
    (G - x)^-1 = M^T M, whose trace is the sum of M's squares and whose square's trace is the sum of
    the squared dot products of M's columns."""
    m = _inverse6(factor)
    m00, m10, m11, m20, m21, m22, m30, m31, m32, m33 = m[:10]
    m40, m41, m42, m43, m44, m50, m51, m52, m53, m54, m55 = m[10:]
    s1 = math.fsum(v * v for v in m)
    c00 = m00 * m00 + m10 * m10 + m20 * m20 + m30 * m30 + m40 * m40 + m50 * m50
    c10 = m11 * m10 + m21 * m20 + m31 * m30 + m41 * m40 + m51 * m50
    c11 = m11 * m11 + m21 * m21 + m31 * m31 + m41 * m41 + m51 * m51
    c20 = m22 * m20 + m32 * m30 + m42 * m40 + m52 * m50
    c21 = m22 * m21 + m32 * m31 + m42 * m41 + m52 * m51
    c22 = m22 * m22 + m32 * m32 + m42 * m42 + m52 * m52
    c30 = m33 * m30 + m43 * m40 + m53 * m50
    c31 = m33 * m31 + m43 * m41 + m53 * m51
    c32 = m33 * m32 + m43 * m42 + m53 * m52
    c33 = m33 * m33 + m43 * m43 + m53 * m53
    c40 = m44 * m40 + m54 * m50
    c41 = m44 * m41 + m54 * m51
    c42 = m44 * m42 + m54 * m52
    c43 = m44 * m43 + m54 * m53
    c44 = m44 * m44 + m54 * m54
    c50 = m55 * m50
    c51 = m55 * m51
    c52 = m55 * m52
    c53 = m55 * m53
    c54 = m55 * m54
    c55 = m55 * m55
    s2 = c00 * c00 + c11 * c11 + c22 * c22 + c33 * c33 + c44 * c44 + c55 * c55
    s2 += 2.0 * (c10 * c10 + c20 * c20 + c21 * c21 + c30 * c30 + c31 * c31)
    s2 += 2.0 * (c32 * c32 + c40 * c40 + c41 * c41 + c42 * c42 + c43 * c43)
    s2 += 2.0 * (c50 * c50 + c51 * c51 + c52 * c52 + c53 * c53 + c54 * c54)
    return s1, s2


def _inverse6(factor: tuple[float, ...]) -> tuple[float, ...]:
    """L^-1 of a lower-triangular 6 x 6 L (both as lower triangles in ``_gram6``'s order)."""
    l00, l10, l11, l20, l21, l22, l30, l31, l32, l33 = factor[:10]
    l40, l41, l42, l43, l44, l50, l51, l52, l53, l54, l55 = factor[10:]
    m00 = 1.0 / l00
    m11 = 1.0 / l11
    m10 = -(l10 * m00) * m11
    m22 = 1.0 / l22
    m20 = -(l20 * m00 + l21 * m10) * m22
    m21 = -(l21 * m11) * m22
    m33 = 1.0 / l33
    m30 = -(l30 * m00 + l31 * m10 + l32 * m20) * m33
    m31 = -(l31 * m11 + l32 * m21) * m33
    m32 = -(l32 * m22) * m33
    m44 = 1.0 / l44
    m40 = -(l40 * m00 + l41 * m10 + l42 * m20 + l43 * m30) * m44
    m41 = -(l41 * m11 + l42 * m21 + l43 * m31) * m44
    m42 = -(l42 * m22 + l43 * m32) * m44
    m43 = -(l43 * m33) * m44
    m55 = 1.0 / l55
    m50 = -(l50 * m00 + l51 * m10 + l52 * m20 + l53 * m30 + l54 * m40) * m55
    m51 = -(l51 * m11 + l52 * m21 + l53 * m31 + l54 * m41) * m55
    m52 = -(l52 * m22 + l53 * m32 + l54 * m42) * m55
    m53 = -(l53 * m33 + l54 * m43) * m55
    m54 = -(l54 * m44) * m55
    return (
        m00,
        m10,
        m11,
        m20,
        m21,
        m22,
        m30,
        m31,
        m32,
        m33,
        m40,
        m41,
        m42,
        m43,
        m44,
        m50,
        m51,
        m52,
        m53,
        m54,
        m55,
    )


def _smallest_eigenvalue6(g: tuple[float, ...]) -> float:
    """``_smallest_eigenvalue`` for a 6 x 6 G given as ``_gram6``'s lower triangle, unrolled."""
    scale = g[0] + g[2] + g[5] + g[9] + g[14] + g[20]
    if not scale > 0.0:
        return 0.0
    x = 0.0
    for _ in range(_MAX_STEPS):
        try:
            s1, s2 = _laguerre_sums6(_factor6(g, x))
        except ZeroDivisionError:
            return x  # rounding put x on the eigenvalue: it is as good as the arithmetic allows
        step = 6.0 / (s1 + math.sqrt(max(0.0, 5.0 * (6.0 * s2 - s1 * s1))))
        x += step
        if step <= _RELATIVE * x or step <= _FLOOR * scale:
            break
    return x


def singularity(rows: Sequence[Sequence[float]]) -> float:
    """The smallest singular value of the 6 x n Jacobian ``rows`` (0.0 at an exact singularity)."""
    if len(rows[0]) == 6:
        return math.sqrt(_smallest_eigenvalue6(_gram6(rows, 0.0)))
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
    v = [float(t) for t in twist]
    if n == 6:
        sigma = math.sqrt(_smallest_eigenvalue6(_gram6(rows, 0.0)))
        return tuple(damped_step6(rows, v, _damping(sigma, singular_value, max_damping))), sigma
    g = gram(rows)
    sigma = math.sqrt(_smallest_eigenvalue(g))
    damping = _damping(sigma, singular_value, max_damping)
    if n < 6:
        jt_v = [sum(rows[k][j] * v[k] for k in range(6)) for j in range(n)]
        return tuple(cholesky_solve(g, jt_v, damping)), sigma
    y = cholesky_solve(g, v, damping)
    return tuple(sum(rows[k][j] * y[k] for k in range(6)) for j in range(n)), sigma


def _damping(sigma: float, singular_value: float, max_damping: float) -> float:
    """l^2 of the damped law: (1 - (sigma / singular_value)^2) max_damping^2 below singular_value, else 0."""
    if sigma < singular_value:
        return (1.0 - (sigma / singular_value) ** 2) * max_damping * max_damping
    return 0.0
