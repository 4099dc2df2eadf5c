"""Attitude: quaternions, Wahba's problem (SVD and QUEST), RA/Dec/roll, residuals, covariance.

A quaternion ``q = [w, x, y, z]`` (scalar first, Hamilton product) gives the matrix ``R(q)``
that rotates ICRS vectors into the camera frame: ``v_cam = R v_icrs``. RA/Dec are those of the
boresight (+z); roll is the position angle of image-up (-y) at the boresight, measured from
celestial north through east, in degrees [0, 360).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit

from .geometry import angle_between, radec_to_vector
from .residual_field import field_inflation
from .types import FloatArray

ARCSEC_PER_RAD = 180.0 / math.pi * 3600.0


def quat_to_matrix(q: FloatArray) -> FloatArray:
    """Rotation matrix ``(3, 3)`` (or ``(..., 3, 3)``) of unit quaternion(s) ``[w, x, y, z]``."""
    q = np.asarray(q, dtype=np.float64)
    if q.shape == (4,):  # one quaternion (every frame's answer and truth): Python floats, ~5x faster
        w, x, y, z = q.tolist()
        n = math.sqrt(w * w + x * x + y * y + z * z)
        w, x, y, z = w / n, x / n, y / n, z / n
        return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                         [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                         [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])
    q = q / np.linalg.norm(q, axis=-1, keepdims=True)
    w, x, y, z = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    r = np.empty(q.shape[:-1] + (3, 3))
    r[..., 0, 0] = 1 - 2 * (y * y + z * z)
    r[..., 0, 1] = 2 * (x * y - w * z)
    r[..., 0, 2] = 2 * (x * z + w * y)
    r[..., 1, 0] = 2 * (x * y + w * z)
    r[..., 1, 1] = 1 - 2 * (x * x + z * z)
    r[..., 1, 2] = 2 * (y * z - w * x)
    r[..., 2, 0] = 2 * (x * z - w * y)
    r[..., 2, 1] = 2 * (y * z + w * x)
    r[..., 2, 2] = 1 - 2 * (x * x + y * y)
    return r


def matrix_to_quat(r: FloatArray) -> FloatArray:
    """Unit quaternion ``[w, x, y, z]`` with ``w >= 0`` of a rotation matrix (Shepperd's method;
    :func:`quaternion_into`)."""
    out = np.empty(7)
    quaternion_into(np.ascontiguousarray(r, dtype=np.float64), out)
    return out[:4]


@njit(cache=True, nogil=True)
def quaternion_into(r: np.ndarray, out: np.ndarray) -> None:
    """``out[0:4]`` = the unit quaternion ``[w, x, y, z]`` (``w >= 0``) of the rotation matrix
    ``r`` (Shepperd's method). Compiled: the answer's columns make it inside their own call."""
    tr = r[0, 0] + r[1, 1] + r[2, 2]
    best = max(tr, r[0, 0], r[1, 1], r[2, 2])
    if best == tr:
        s = math.sqrt(1.0 + tr) * 2
        w, x, y, z = 0.25 * s, (r[2, 1] - r[1, 2]) / s, (r[0, 2] - r[2, 0]) / s, (r[1, 0] - r[0, 1]) / s
    elif best == r[0, 0]:
        s = math.sqrt(1.0 + r[0, 0] - r[1, 1] - r[2, 2]) * 2
        w, x, y, z = (r[2, 1] - r[1, 2]) / s, 0.25 * s, (r[0, 1] + r[1, 0]) / s, (r[0, 2] + r[2, 0]) / s
    elif best == r[1, 1]:
        s = math.sqrt(1.0 + r[1, 1] - r[0, 0] - r[2, 2]) * 2
        w, x, y, z = (r[0, 2] - r[2, 0]) / s, (r[0, 1] + r[1, 0]) / s, 0.25 * s, (r[1, 2] + r[2, 1]) / s
    else:
        s = math.sqrt(1.0 + r[2, 2] - r[0, 0] - r[1, 1]) * 2
        w, x, y, z = (r[1, 0] - r[0, 1]) / s, (r[0, 2] + r[2, 0]) / s, (r[1, 2] + r[2, 1]) / s, 0.25 * s
    norm = math.sqrt(w * w + x * x + y * y + z * z) * (-1.0 if w < 0 else 1.0)
    out[0], out[1], out[2], out[3] = w / norm, x / norm, y / norm, z / norm


def quat_multiply(a: FloatArray, b: FloatArray) -> FloatArray:
    """Hamilton product ``a * b`` (``R(a b) = R(a) R(b)``)."""
    w1, x1, y1, z1 = a
    w2, x2, y2, z2 = b
    return np.array([
        w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2,
        w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2,
        w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2,
        w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2,
    ])


def quat_angle_deg(a: FloatArray, b: FloatArray) -> float:
    """Rotation angle between two attitudes, degrees."""
    d = abs(float(np.dot(np.asarray(a) / np.linalg.norm(a), np.asarray(b) / np.linalg.norm(b))))
    return math.degrees(2 * math.acos(min(1.0, d)))


def random_rotations(n: int, rng: np.random.Generator) -> FloatArray:
    """``n`` quaternions uniform on SO(3) (Shoemake's method), ``w >= 0``."""
    u1, u2, u3 = rng.random((3, n))
    a, b = np.sqrt(1 - u1), np.sqrt(u1)
    q = np.stack([a * np.sin(2 * np.pi * u2), a * np.cos(2 * np.pi * u2),
                  b * np.sin(2 * np.pi * u3), b * np.cos(2 * np.pi * u3)], axis=1)
    q = q[:, [3, 0, 1, 2]]  # any ordering of a uniform quaternion is uniform; make it [w, x, y, z]
    q[q[:, 0] < 0] *= -1
    return q


def matrix_from_radec_roll(ra_deg: float, dec_deg: float, roll_deg: float) -> FloatArray:
    """ICRS -> camera matrix for a boresight at (RA, Dec) and image-up at position angle roll."""
    ra, dec, pa = (math.radians(v) for v in (ra_deg, dec_deg, roll_deg))
    z = radec_to_vector(ra, dec)
    north = np.array([-math.sin(dec) * math.cos(ra), -math.sin(dec) * math.sin(ra), math.cos(dec)])
    east = np.array([-math.sin(ra), math.cos(ra), 0.0])
    up = math.cos(pa) * north + math.sin(pa) * east
    y = -up
    x = np.cross(y, z)
    return np.stack([x, y, z])


def radec_roll(r: FloatArray) -> tuple[float, float, float]:
    """Boresight RA, Dec and roll (degrees) of an ICRS -> camera matrix. RA in [0, 360)
    (:func:`boresight_into`)."""
    out = np.empty(7)
    boresight_into(np.ascontiguousarray(r, dtype=np.float64), out)
    ra, dec, roll = out[4:7].tolist()
    return ra, dec, roll


@njit(cache=True, nogil=True)
def boresight_into(r: np.ndarray, out: np.ndarray) -> None:
    """``out[4:7]`` = boresight RA, Dec and roll (deg; RA in [0, 360); roll: the position angle
    of image-up, -y, from north through east, in [0, 360)) of the ICRS -> camera matrix ``r``."""
    up0, up1, up2 = -r[1, 0], -r[1, 1], -r[1, 2]
    ra = math.atan2(r[2, 1], r[2, 0]) % (2 * math.pi)
    dec = math.asin(max(-1.0, min(1.0, r[2, 2])))
    sd, cd, sr, cr = math.sin(dec), math.cos(dec), math.sin(ra), math.cos(ra)
    north = -sd * cr * up0 - sd * sr * up1 + cd * up2
    east = -sr * up0 + cr * up1
    out[4], out[5], out[6] = math.degrees(ra), math.degrees(dec), math.degrees(math.atan2(east, north)) % 360.0


@njit(cache=True, nogil=True)
def _fit_stats(obs: np.ndarray, ref: np.ndarray, r: np.ndarray,
               sigma_rad: float) -> tuple[np.ndarray, float, np.ndarray]:
    """Compiled body of :func:`estimate`: residuals (arcsec), their RMS, and the 1-sigma
    errors (arcsec) about x, y, z from the information matrix ``sum (I - v v^T)``; a negative
    ``sigma_rad`` means "from the RMS". When the residuals hold a significant low-order field
    (:func:`~.residual_field.field_inflation`), each axis's 1-sigma also holds the attitude error
    that field's estimated bias adds."""
    n = len(obs)
    res = np.empty(n)
    info = np.zeros((3, 3))
    ss = 0.0
    for i in range(n):
        c2 = 0.0
        for a in range(3):
            d = obs[i, a] - (r[a, 0] * ref[i, 0] + r[a, 1] * ref[i, 1] + r[a, 2] * ref[i, 2])
            c2 += d * d
            for b in range(3):
                info[a, b] -= obs[i, a] * obs[i, b]
        res[i] = 2.0 * math.asin(min(math.sqrt(c2) / 2.0, 1.0)) * ARCSEC_PER_RAD
        ss += res[i] * res[i]
    for a in range(3):
        info[a, a] += n
    rms = math.sqrt(ss / n) if n else np.nan
    sig = sigma_rad
    if sig < 0:
        # per-axis error from the residuals: each star gives 2 tangent-plane components, the fit
        # takes 3 degrees of freedom, so E[sum |res|^2] = (2n - 3) sigma^2
        sig = max(math.sqrt(ss / max(2 * n - 3, 1)) / ARCSEC_PER_RAD, 1e-7) if n else 1e-7
    sd = np.full(3, np.inf)
    det = _det3(info)
    if abs(det) > 1e-12:
        cov = inv3(info, det) * sig * sig
        gain = field_inflation(obs, ref, r, sig)
        for a in range(3):
            sd[a] = math.sqrt(max(cov[a, a], 0.0)) * ARCSEC_PER_RAD * gain[a]
    return res, rms, sd


@njit(cache=True, nogil=True)
def pooled_sigma(residuals_arcsec: np.ndarray, sd: np.ndarray, prior_sigma_rad: float,
                 prior_dof: float) -> np.ndarray:
    """``sd`` (the 1-sigma from the residuals alone) rescaled to the pooled per-axis error: the
    residuals' ``sum |res|^2`` over ``2n - 3`` degrees of freedom, joined by the declared error
    ``prior_sigma_rad`` as ``prior_dof`` more (see :func:`estimate`)."""
    n = len(residuals_arcsec)
    if prior_dof <= 0 or n == 0:
        return sd
    ss = 0.0
    for x in residuals_arcsec:
        ss += x * x
    ss /= ARCSEC_PER_RAD * ARCSEC_PER_RAD
    dof = max(2 * n - 3, 1)
    from_residuals = max(math.sqrt(ss / dof), 1e-7)
    pooled = math.sqrt((ss + prior_dof * prior_sigma_rad * prior_sigma_rad) / (dof + prior_dof))
    return sd * (pooled / from_residuals)


def wahba_batch(obs: FloatArray, ref: FloatArray) -> FloatArray:
    """Rotations ``(K, 3, 3)`` best mapping each ``ref[k]`` ``(n, 3)`` onto ``obs`` ``(n, 3)``, or
    onto ``obs[k]`` when ``obs`` is ``(K, n, 3)`` (SVD solution of Wahba's problem, vectorised
    over K; ``n >= 2``)."""
    b = np.einsum("kni,knj->kij", np.broadcast_to(obs, ref.shape), ref)
    u, _, vt = np.linalg.svd(b)
    det = np.sign(np.linalg.det(u) * np.linalg.det(vt))
    u[:, :, 2] *= det[:, None]
    return u @ vt


def wahba_svd(obs: FloatArray, ref: FloatArray, weights: FloatArray | None = None) -> FloatArray:
    """Rotation ``R`` (3, 3) minimising ``sum w_i |obs_i - R ref_i|^2`` (Markley's SVD method).

    Parameters
    ----------
    obs : (N, 3) float64
        Unit vectors measured in the camera frame.
    ref : (N, 3) float64
        The same stars' unit vectors in ICRS.
    weights : (N,) float64, optional
        Non-negative weights (default all ones).
    """
    obs = np.ascontiguousarray(obs, dtype=np.float64).reshape(-1, 3)
    ref = np.ascontiguousarray(ref, dtype=np.float64).reshape(-1, 3)
    w = np.ones(len(obs)) if weights is None else np.ascontiguousarray(weights, dtype=np.float64)
    return wahba_kernel(obs, ref, w)


@njit(cache=True, nogil=True, inline="always")
def _det3(m: np.ndarray) -> float:
    return (m[0, 0] * (m[1, 1] * m[2, 2] - m[1, 2] * m[2, 1]) - m[0, 1] * (m[1, 0] * m[2, 2] - m[1, 2] * m[2, 0])
            + m[0, 2] * (m[1, 0] * m[2, 1] - m[1, 1] * m[2, 0]))


@njit(cache=True, nogil=True)
def inv3(m: np.ndarray, det: float) -> np.ndarray:
    """Inverse of a 3x3 matrix of determinant ``det`` (non-zero) by cofactors (LAPACK's call
    costs ~1 us; this ~20 ns)."""
    out = np.empty((3, 3))
    out[0, 0] = (m[1, 1] * m[2, 2] - m[1, 2] * m[2, 1]) / det
    out[0, 1] = (m[0, 2] * m[2, 1] - m[0, 1] * m[2, 2]) / det
    out[0, 2] = (m[0, 1] * m[1, 2] - m[0, 2] * m[1, 1]) / det
    out[1, 0] = (m[1, 2] * m[2, 0] - m[1, 0] * m[2, 2]) / det
    out[1, 1] = (m[0, 0] * m[2, 2] - m[0, 2] * m[2, 0]) / det
    out[1, 2] = (m[0, 2] * m[1, 0] - m[0, 0] * m[1, 2]) / det
    out[2, 0] = (m[1, 0] * m[2, 1] - m[1, 1] * m[2, 0]) / det
    out[2, 1] = (m[0, 1] * m[2, 0] - m[0, 0] * m[2, 1]) / det
    out[2, 2] = (m[0, 0] * m[1, 1] - m[0, 1] * m[1, 0]) / det
    return out


POLAR_MAX_ITER = 40


@njit(cache=True, nogil=True)
def _polar_rotation(b: np.ndarray) -> tuple[bool, np.ndarray]:
    """The orthogonal factor of ``b = Q H`` by Higham's scaled Newton iteration
    (``X <- (g X + X^-T / g) / 2``), if ``det(b) > 0`` and it converges: then ``Q`` is the
    rotation nearest ``b`` (Wahba's answer) without an SVD. ``(False, b)`` otherwise."""
    scale = 0.0
    for a in range(3):
        for c in range(3):
            scale = max(scale, abs(b[a, c]))
    if scale == 0.0:
        return False, b
    x = b / scale
    det = _det3(x)
    if not det > 1e-9:  # a reflection or (nearly) rank-deficient: the SVD decides
        return False, b
    for _ in range(POLAR_MAX_ITER):
        xi = inv3(x, det)
        nx = 0.0
        ni = 0.0
        for a in range(3):
            for c in range(3):
                nx += x[a, c] * x[a, c]
                ni += xi[a, c] * xi[a, c]
        g = math.sqrt(math.sqrt(ni / nx))
        change = 0.0
        y = np.empty((3, 3))
        for a in range(3):
            for c in range(3):
                y[a, c] = 0.5 * (g * x[a, c] + xi[c, a] / g)
                change += (y[a, c] - x[a, c]) ** 2
        x = y
        det = _det3(x)
        if change < 1e-30:
            return True, x
    return False, b


@njit(cache=True, nogil=True)
def wahba_kernel(obs: np.ndarray, ref: np.ndarray, w: np.ndarray) -> np.ndarray:
    """Compiled body of :func:`wahba_svd`: the polar factor of ``B`` by Newton's iteration
    (~0.2 us), the 3x3 SVD (~3 us in a kernel, ~10 us via numpy) when ``det(B) <= 0``."""
    b = np.zeros((3, 3))
    for i in range(len(obs)):
        for a in range(3):
            for c in range(3):
                b[a, c] += w[i] * obs[i, a] * ref[i, c]
    ok, q = _polar_rotation(b)
    if ok:
        return q
    u, _, vt = np.linalg.svd(b)
    r = u @ vt
    if np.linalg.det(r) < 0:  # a reflection: flip the least significant axis
        u[:, 2] = -u[:, 2]
        r = u @ vt
    return r


def quest(obs: FloatArray, ref: FloatArray, weights: FloatArray | None = None) -> FloatArray:
    """Quaternion ``[w, x, y, z]`` solving Wahba's problem by Davenport's q-method (the exact
    eigenvector QUEST approximates); same arguments as :func:`wahba_svd`."""
    w = np.ones(len(obs)) if weights is None else np.asarray(weights, dtype=np.float64)
    b = (obs * w[:, None]).T @ ref
    s = b + b.T
    sigma = np.trace(b)
    zv = np.array([b[1, 2] - b[2, 1], b[2, 0] - b[0, 2], b[0, 1] - b[1, 0]])
    k = np.empty((4, 4))
    k[0, 0] = sigma
    k[0, 1:] = zv
    k[1:, 0] = zv
    k[1:, 1:] = s - sigma * np.eye(3)
    vals, vecs = np.linalg.eigh(k)
    q = vecs[:, int(np.argmax(vals))]
    # Davenport's q is the frame rotation [w, -axis]; express it as our vector rotation.
    q = np.array([q[0], -q[1], -q[2], -q[3]])
    return -q if q[0] < 0 else q


def residuals_arcsec(obs: FloatArray, ref: FloatArray, r: FloatArray) -> FloatArray:
    """Angle in arcsec between each observed vector and its reference rotated into the camera."""
    return np.asarray(angle_between(obs, ref @ r.T)) * ARCSEC_PER_RAD


@dataclass(frozen=True, slots=True)
class AttitudeEstimate:
    """A fitted attitude with its residuals and 1-sigma errors."""

    matrix: FloatArray
    quaternion: FloatArray
    residuals_arcsec: FloatArray
    rms_arcsec: float
    sigma_arcsec: tuple[float, float, float]


PRIOR_DOF = 8.0
"""Weight of the declared centroid error in the attitude sigma, as degrees of freedom (two
stars' worth of residual components, four stars'); measured by ``python -m bench.bench_sigma``."""


def estimate(
    obs: FloatArray, ref: FloatArray, *, sigma_rad: float | None = None, matrix: FloatArray | None = None,
    prior_sigma_rad: float | None = None, prior_dof: float = PRIOR_DOF,
) -> AttitudeEstimate:
    """Attitude from matched pairs, with residuals and the covariance-derived 1-sigma errors
    about the camera's x, y (cross-boresight) and z (roll) axes.

    ``sigma_rad`` is the per-star, per-axis measurement error; by default it is estimated from
    the fit's residuals (``sum |res|^2 / (2n - 3)``). ``prior_sigma_rad`` (the declared centroid
    error) then joins that estimate as ``prior_dof`` extra degrees of freedom, which keeps
    frames of few stars from an over-confident sigma. ``matrix`` is the least-squares fit to
    these pairs when the caller already has it.
    """
    r = wahba_svd(obs, ref) if matrix is None else np.asarray(matrix, dtype=np.float64)
    res, rms, sd = _fit_stats(np.ascontiguousarray(obs, dtype=np.float64), np.ascontiguousarray(ref, dtype=np.float64),
                              np.ascontiguousarray(r), -1.0 if sigma_rad is None else float(sigma_rad))
    if sigma_rad is None and prior_sigma_rad is not None:
        sd = pooled_sigma(res, sd, float(prior_sigma_rad), float(prior_dof))
    sd = (float(sd[0]), float(sd[1]), float(sd[2]))
    return AttitudeEstimate(r, matrix_to_quat(r), res, float(rms), sd)  # type: ignore[arg-type]
