"""Does a fit's residual hold a low-order field, and how much attitude error can it hide?

An unmodelled lens distortion or focal-length error moves every star by a smooth function of
its position in the field. The rigid attitude fit absorbs the part of that field that looks
like a rotation (an error that does not average down as ``1/sqrt(n)``) and leaves the rest in
the residuals. This module fits the residual vectors with the rotation plus a low-order field
in the camera's tangent plane (focal scale, two linear shears, the six quadratic terms), tests
the field's significance against the frame's own remaining scatter (an F test, Paulson's
normal approximation), and when the field is significant returns, per camera axis, the factor
by which the 1-sigma grows when the field is left free: ``sqrt(C_joint / C_rigid)``.

Frames: camera x = column, y = row, +z boresight; ``v_cam = R v_icrs``. All vectors are unit
vectors; residuals are in radians.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

FIELD_Z = 2.33
"""One-sided significance (standard normal deviate, p = 0.01) the field must pass before the
sigma is widened: white-noise frames are judged systematic about once in a hundred (and then
widened only by what their estimated bias exceeds)."""
TERMS_MANY = 9
"""Field terms (scale, two shears, six quadratic) when the frame has ``MIN_STARS_MANY`` stars."""
TERMS_FEW = 3
"""Field terms (scale, two shears) when it has ``MIN_STARS_FEW``."""
MIN_STARS_MANY = 11
MIN_STARS_FEW = 6


@njit(cache=True, nogil=True)
def paulson_z(f: float, d1: float, d2: float) -> float:
    """Standard normal deviate of an F(d1, d2) statistic ``f`` (Paulson's approximation)."""
    a = 2.0 / (9.0 * d1)
    b = 2.0 / (9.0 * d2)
    c = max(f, 0.0) ** (1.0 / 3.0)
    return ((1.0 - b) * c - (1.0 - a)) / math.sqrt(a + b * c * c)


@njit(cache=True, nogil=True)
def _cholesky(m: np.ndarray) -> tuple[bool, np.ndarray]:
    """``(ok, L)``: the lower Cholesky factor of symmetric ``m`` (its lower triangle is read);
    ``ok`` False when a pivot falls below 1e-12 of the largest diagonal element (a degenerate
    design)."""
    k = m.shape[0]
    top = 0.0
    for i in range(k):
        top = max(top, m[i, i])
    low = np.zeros((k, k))
    for j in range(k):
        s = m[j, j]
        for p in range(j):
            s -= low[j, p] * low[j, p]
        if not s > 1e-12 * top:
            return False, low
        low[j, j] = math.sqrt(s)
        for i in range(j + 1, k):
            t = m[i, j]
            for p in range(j):
                t -= low[i, p] * low[j, p]
            low[i, j] = t / low[j, j]
    return True, low


@njit(cache=True, nogil=True)
def _spd_inverse(m: np.ndarray) -> tuple[bool, np.ndarray]:
    """Inverse of a symmetric positive-definite matrix by Cholesky; ``(False, m)`` when a pivot
    falls below 1e-12 of the largest diagonal element (a degenerate design)."""
    k = m.shape[0]
    ok, low = _cholesky(m)
    if not ok:
        return False, m
    inv_low = np.zeros((k, k))  # L^-1 by forward substitution
    for c in range(k):
        inv_low[c, c] = 1.0 / low[c, c]
        for i in range(c + 1, k):
            t = 0.0
            for p in range(c, i):
                t -= low[i, p] * inv_low[p, c]
            inv_low[i, c] = t / low[i, i]
    out = np.zeros((k, k))
    for i in range(k):
        for j in range(k):
            t = 0.0
            for p in range(max(i, j), k):
                t += inv_low[p, i] * inv_low[p, j]
            out[i, j] = t
    return True, out


@njit(cache=True, nogil=True)
def _design(a: np.ndarray, m: np.ndarray, rho: float, k: int) -> None:
    """Fill ``a`` ``(3, 3 + k)`` with the columns of one star at camera-frame unit vector ``m``:
    the three small rotations about x, y, z, then ``k`` field terms (tangent-plane
    displacements, normalised field radius ``rho``), each projected perpendicular to ``m``."""
    a[0, 0], a[1, 0], a[2, 0] = 0.0, -m[2], m[1]
    a[0, 1], a[1, 1], a[2, 1] = m[2], 0.0, -m[0]
    a[0, 2], a[1, 2], a[2, 2] = -m[1], m[0], 0.0
    x = m[0] / m[2] / rho
    y = m[1] / m[2] / rho
    gx = (x, x, y, x * x, x * y, y * y, 0.0, 0.0, 0.0)
    gy = (y, -y, x, 0.0, 0.0, 0.0, x * x, x * y, y * y)
    for t in range(k):
        along = gx[t] * m[0] + gy[t] * m[1]
        a[0, 3 + t] = gx[t] - along * m[0]
        a[1, 3 + t] = gy[t] - along * m[1]
        a[2, 3 + t] = -along * m[2]


@njit(cache=True, nogil=True)
def _predicted(ref: np.ndarray, r: np.ndarray) -> tuple[np.ndarray, float]:
    """The catalogue directions ``r @ ref`` in the camera frame ``(n, 3)`` and the largest
    tangent-plane radius among them (the field terms' normalisation); radius 0 when a star lies
    behind the camera (``z <= 1e-6``), as the fits refuse then."""
    n = len(ref)
    m = np.empty((n, 3))
    rho = 0.0
    for i in range(n):
        for a in range(3):
            m[i, a] = r[a, 0] * ref[i, 0] + r[a, 1] * ref[i, 1] + r[a, 2] * ref[i, 2]
        if not m[i, 2] > 1e-6:
            return m, 0.0
        rho = max(rho, math.hypot(m[i, 0] / m[i, 2], m[i, 1] / m[i, 2]))
    return m, rho


@njit(cache=True, nogil=True)
def field_fit(obs: np.ndarray, ref: np.ndarray, r: np.ndarray
              ) -> tuple[bool, int, np.ndarray, np.ndarray, np.ndarray, np.ndarray, float, float]:
    """Rigid and joint (rotation + field) least squares of the residuals of ``obs``
    (camera-frame unit vectors ``(n, 3)``) against ``r @ ref`` (ICRS unit vectors, ``r`` the
    ICRS -> camera matrix).

    Returns ``(ok, k, theta_rigid, theta_joint, cov_rigid, cov_joint, ss_rigid, ss_joint)``:
    ``k`` field terms (0 and ``ok`` False when there are too few stars or the design is
    degenerate); the small rotations (rad, about camera x, y, z; the joint one's first three
    entries), their covariances per unit star variance (``(3, 3)`` and ``(3 + k, 3 + k)``), and
    the residual sums of squares (rad^2) of both fits.
    """
    n = len(obs)
    k = TERMS_MANY if n >= MIN_STARS_MANY else (TERMS_FEW if n >= MIN_STARS_FEW else 0)
    none = (False, 0, np.zeros(3), np.zeros(3), np.zeros((3, 3)), np.zeros((3, 3)), 0.0, 0.0)
    if k == 0:
        return none
    m, rho = _predicted(ref, r)
    if not rho > 0.0:
        return none
    size = 3 + k
    design = np.empty((3 * n, size))  # the stacked design, so the normal equations are one BLAS
    resid = np.empty(3 * n)  # product each (the loop over star x term pairs took ~4 us of 5.4)
    for i in range(n):
        _design(design[3 * i:3 * i + 3], m[i], rho, k)
        for c in range(3):
            resid[3 * i + c] = obs[i, c] - m[i, c]
    normal = design.T @ design
    rhs = design.T @ resid
    ss = resid @ resid
    ok_j, cov_j = _spd_inverse(normal)
    ok_r, cov_r = _spd_inverse(normal[:3, :3].copy())
    if not (ok_j and ok_r):
        return none
    theta_j = cov_j @ rhs
    theta_r = cov_r @ rhs[:3]
    return True, k, theta_r, theta_j, cov_r, cov_j, ss - rhs[:3] @ theta_r, ss - rhs @ theta_j


@njit(cache=True, nogil=True)
def field_inflation(obs: np.ndarray, ref: np.ndarray, r: np.ndarray, sigma_rad: float) -> np.ndarray:
    """Per-axis factors (x, y, z; >= 1) by which a rigid fit's 1-sigma grows for the attitude
    error a significant residual field can hide.

    Arguments as :func:`field_fit`; ``sigma_rad`` is the per-axis star error the rigid 1-sigma
    was computed with. The fit with the field left free moves the attitude by ``delta``; under
    white noise ``delta`` has variance ``(C_joint - C_rigid) s^2`` (``s^2`` the scatter left
    after the field), so ``b^2 = max(0, delta^2 - (C_joint - C_rigid) s^2)`` estimates the
    rigid fit's squared bias. The variance becomes ``C_rigid s^2 + b^2`` (the white part from
    the scatter the field leaves), never less than before:
    ``gain^2 = max(1, (C_rigid s^2 + b^2) / (C_rigid sigma^2))``. Ones when the field is not
    significant (``FIELD_Z``), or the frame has too few stars to tell.

    The same figures as :func:`field_fit` gives (its tests compare them), from one Cholesky
    factor ``L`` of the joint normal matrix: the rigid fit's is its leading 3 x 3 block, the
    sums of squares are ``ss - |L^-1 rhs|^2`` over all or the first three entries, and the
    covariances' diagonals are asked only of a significant field. No BLAS call and no full
    inverse: ~1-2.5 us for 10-19 stars, against 4.6-9.3 for :func:`field_fit` (every answer
    takes this).
    """
    gain = np.ones(3)
    n = len(obs)
    k = TERMS_MANY if n >= MIN_STARS_MANY else (TERMS_FEW if n >= MIN_STARS_FEW else 0)
    if k == 0 or not sigma_rad > 0.0:
        return gain
    size = 3 + k
    ok, low, y, ss = _field_normal_factor(obs, ref, r, k)
    if not ok:
        return gain
    ss_r = 0.0
    for a in range(3):
        ss_r += y[a] * y[a]
    ss_f = 0.0
    for a in range(3, size):
        ss_f += y[a] * y[a]
    ss_rigid = ss - ss_r
    ss_joint = ss_rigid - ss_f
    if not ss_joint > 0.0:
        return gain
    dof = 2 * n - 3 - k
    s2 = ss_joint / dof
    f = (ss_f / k) / s2
    if paulson_z(f, float(k), float(dof)) > FIELD_Z:
        theta_j = _back_solve(low, y, size)
        theta_r = _back_solve(low, y, 3)
        diag_j = _inverse_diagonal(low, size)
        diag_r = _inverse_diagonal(low, 3)
        for a in range(3):
            delta = theta_j[a] - theta_r[a]
            bias2 = max(delta * delta - (diag_j[a] - diag_r[a]) * s2, 0.0)
            gain[a] = math.sqrt(max((diag_r[a] * s2 + bias2) / (diag_r[a] * sigma_rad * sigma_rad), 1.0))
    return gain


@njit(cache=True, nogil=True)
def _field_normal_factor(obs: np.ndarray, ref: np.ndarray, r: np.ndarray, k: int
                         ) -> tuple[bool, np.ndarray, np.ndarray, float]:
    """``(ok, L, y, ss)`` of :func:`field_fit`'s joint design with ``k`` field terms: ``L`` the
    Cholesky factor of its normal matrix (lower, ``(3 + k, 3 + k)``), ``y = L^-1 rhs`` and the
    residuals' sum of squares (rad^2); ``ok`` False as :func:`field_fit` refuses (a star behind
    the camera, a degenerate design: a pivot below 1e-12 of the largest diagonal element). The
    normal matrix is dot products of the design's columns (:func:`_gram`)."""
    n = len(obs)
    size = 3 + k
    normal = np.zeros((size, size))
    rhs = np.zeros(size)
    none = (False, normal, rhs, 0.0)
    m, rho = _predicted(ref, r)
    if not rho > 0.0:
        return none
    design = np.empty((size, 3 * n))  # column by column: the normal matrix is dot products
    resid = np.empty(3 * n)
    gx = np.zeros(TERMS_MANY)
    gy = np.zeros(TERMS_MANY)
    ss = 0.0
    for i in range(n):
        m0, m1, m2 = m[i, 0], m[i, 1], m[i, 2]
        _field_terms(m0 / m2 / rho, m1 / m2 / rho, k, gx, gy)
        j = 3 * i
        design[0, j], design[0, j + 1], design[0, j + 2] = 0.0, -m2, m1
        design[1, j], design[1, j + 1], design[1, j + 2] = m2, 0.0, -m0
        design[2, j], design[2, j + 1], design[2, j + 2] = -m1, m0, 0.0
        for t in range(k):
            along = gx[t] * m0 + gy[t] * m1
            design[3 + t, j] = gx[t] - along * m0
            design[3 + t, j + 1] = gy[t] - along * m1
            design[3 + t, j + 2] = -along * m2
        for c in range(3):
            resid[j + c] = obs[i, c] - m[i, c]
            ss += resid[j + c] * resid[j + c]
    _gram(design, resid, normal, rhs)
    ok, low = _cholesky(normal)
    if not ok:
        return none
    y = np.empty(size)
    for i in range(size):
        t = rhs[i]
        for p in range(i):
            t -= low[i, p] * y[p]
        y[i] = t / low[i, i]
    return True, low, y, ss


@njit(cache=True, nogil=True)
def _field_terms(x: float, y: float, k: int, gx: np.ndarray, gy: np.ndarray) -> None:
    """The first ``k`` field terms' x and y displacements at normalised field position ``(x,
    y)`` into ``gx``, ``gy`` (:func:`_design`'s: scale, two shears, six quadratic)."""
    gx[0], gx[1], gx[2] = x, x, y
    gy[0], gy[1], gy[2] = y, -y, x
    if k > 3:
        gx[3], gx[4], gx[5], gx[6], gx[7], gx[8] = x * x, x * y, y * y, 0.0, 0.0, 0.0
        gy[3], gy[4], gy[5], gy[6], gy[7], gy[8] = 0.0, 0.0, 0.0, x * x, x * y, y * y


@njit(cache=True, nogil=True, fastmath={"reassoc", "contract"})
def _gram(design: np.ndarray, resid: np.ndarray, normal: np.ndarray, rhs: np.ndarray) -> None:
    """``normal = design design^T`` (each pair once) and ``rhs = design resid`` (``design``
    one column of the least squares a row). Sums may be reordered (SIMD, ~2x faster; the
    result moves by ~1e-16 relative); no NaN or sign assumptions."""
    size, length = design.shape
    for p in range(size):
        t = 0.0
        for j in range(length):
            t += design[p, j] * resid[j]
        rhs[p] = t
        for q in range(p, size):
            t = 0.0
            for j in range(length):
                t += design[p, j] * design[q, j]
            normal[p, q] = normal[q, p] = t


@njit(cache=True, nogil=True)
def _back_solve(low: np.ndarray, y: np.ndarray, size: int) -> np.ndarray:
    """``x`` solving ``L[:size, :size]^T x = y[:size]``."""
    x = np.empty(size)
    for i in range(size - 1, -1, -1):
        t = y[i]
        for p in range(i + 1, size):
            t -= low[p, i] * x[p]
        x[i] = t / low[i, i]
    return x


@njit(cache=True, nogil=True)
def _inverse_diagonal(low: np.ndarray, size: int) -> np.ndarray:
    """The first three diagonal elements of ``(L L^T)^-1`` for ``L = low[:size, :size]``: the
    squared norms of the first three columns of ``L^-1``."""
    out = np.zeros(3)
    col = np.empty(size)
    for c in range(3):
        for i in range(size):
            if i < c:
                col[i] = 0.0
                continue
            t = 1.0 if i == c else 0.0
            for p in range(c, i):
                t -= low[i, p] * col[p]
            col[i] = t / low[i, i]
            out[c] += col[i] * col[i]
    return out
