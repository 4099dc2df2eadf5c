"""Small vectorised geometry kernels on unit vectors (radians inside the engine)."""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from .types import FloatArray


def radec_to_vector(ra_rad: FloatArray | float, dec_rad: FloatArray | float) -> FloatArray:
    """ICRS unit vectors ``(..., 3)`` from right ascension and declination in radians."""
    ra = np.asarray(ra_rad, dtype=np.float64)
    dec = np.asarray(dec_rad, dtype=np.float64)
    cd = np.cos(dec)
    return np.stack([cd * np.cos(ra), cd * np.sin(ra), np.sin(dec)], axis=-1)


def vector_to_radec(v: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Right ascension in [0, 2 pi) and declination in radians of vectors ``(..., 3)``."""
    v = np.asarray(v, dtype=np.float64)
    ra = np.mod(np.arctan2(v[..., 1], v[..., 0]), 2 * np.pi)
    dec = np.arctan2(v[..., 2], np.hypot(v[..., 0], v[..., 1]))
    return ra, dec


def normalize(v: FloatArray) -> FloatArray:
    """Unit vectors along the last axis."""
    v = np.asarray(v, dtype=np.float64)
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def angle_between(a: FloatArray, b: FloatArray) -> FloatArray:
    """Angle in radians between unit vectors, accurate at small angles (``2 asin(|a-b|/2)``)."""
    chord = np.linalg.norm(np.asarray(a) - np.asarray(b), axis=-1)
    return 2.0 * np.arcsin(np.clip(chord / 2.0, 0.0, 1.0))


def chord_from_angle(theta_rad: FloatArray | float) -> FloatArray:
    """Chord length ``|a - b|`` of unit vectors separated by ``theta_rad``."""
    return 2.0 * np.sin(np.asarray(theta_rad, dtype=np.float64) / 2.0)


def pairwise_angles(v: FloatArray) -> FloatArray:
    """``(N, N)`` matrix of angles in radians between the rows of ``v`` ``(N, 3)``
    (``2 asin(|a - b| / 2)``; one compiled call: numpy's steps cost ~10 us on a handful of
    stars, which the matchers ask for on every triangle)."""
    return pairwise_angles_kernel(np.ascontiguousarray(v, dtype=np.float64))


@njit(cache=True, nogil=True)
def pairwise_angles_kernel(v: np.ndarray) -> np.ndarray:
    """:func:`pairwise_angles` of contiguous float64 ``v`` ``(N, 3)``."""
    n = len(v)
    d = np.zeros((n, n))
    for i in range(n):
        for j in range(i + 1, n):
            s = 0.0
            for a in range(3):
                x = v[i, a] - v[j, a]
                s += x * x
            d[i, j] = d[j, i] = 2.0 * math.asin(min(math.sqrt(s) / 2.0, 1.0))
    return d


def cross(a: FloatArray, b: FloatArray) -> FloatArray:
    """Row-wise cross product of ``(..., 3)`` arrays (``np.cross`` without its overhead)."""
    out = np.empty(np.broadcast_shapes(a.shape, b.shape))
    out[..., 0] = a[..., 1] * b[..., 2] - a[..., 2] * b[..., 1]
    out[..., 1] = a[..., 2] * b[..., 0] - a[..., 0] * b[..., 2]
    out[..., 2] = a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]
    return out
