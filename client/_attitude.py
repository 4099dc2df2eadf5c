"""Quaternion arithmetic on plain tuples (no numpy), enough to score attitudes against truth.

Quaternions are scalar first ``(w, x, y, z)``, Hamilton product, and rotate vectors:
``v_cam = R(q) v_icrs`` (the skyfix convention, docs/conventions.md).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import NamedTuple

__all__ = ["AttitudeError", "attitude_error", "quat_conj", "quat_mul", "quat_normalize", "quat_rotate",
           "quat_to_matrix"]

Quat = tuple[float, float, float, float]
Vec = tuple[float, float, float]
RAD_TO_ARCSEC = 180.0 / math.pi * 3600.0


def quat_normalize(q: Sequence[float]) -> Quat:
    w, x, y, z = (float(c) for c in q)
    n = math.sqrt(w * w + x * x + y * y + z * z)
    if not n > 0.0 or not math.isfinite(n):
        raise ValueError("quaternion must be finite and non-zero")
    return (w / n, x / n, y / n, z / n)


def quat_conj(q: Sequence[float]) -> Quat:
    w, x, y, z = q
    return (w, -x, -y, -z)


def quat_mul(a: Sequence[float], b: Sequence[float]) -> Quat:
    """Hamilton product ``a ⊗ b``; ``R(a ⊗ b) = R(a) R(b)``."""
    aw, ax, ay, az = a
    bw, bx, by, bz = b
    return (
        aw * bw - ax * bx - ay * by - az * bz,
        aw * bx + ax * bw + ay * bz - az * by,
        aw * by - ax * bz + ay * bw + az * bx,
        aw * bz + ax * by - ay * bx + az * bw,
    )


def quat_rotate(q: Sequence[float], v: Sequence[float]) -> Vec:
    """``R(q) v`` for a unit quaternion."""
    w, x, y, z = q
    vx, vy, vz = v
    # t = 2 (q_vec × v); v' = v + w t + q_vec × t
    tx = 2.0 * (y * vz - z * vy)
    ty = 2.0 * (z * vx - x * vz)
    tz = 2.0 * (x * vy - y * vx)
    return (vx + w * tx + (y * tz - z * ty),
            vy + w * ty + (z * tx - x * tz),
            vz + w * tz + (x * ty - y * tx))


def quat_to_matrix(q: Sequence[float]) -> list[list[float]]:
    """The 3x3 rotation matrix ``R(q)`` (rows), for a unit quaternion."""
    w, x, y, z = q
    return [
        [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
        [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
        [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
    ]


class AttitudeError(NamedTuple):
    """How far a solved attitude is from the truth, in the camera frame, arcseconds."""

    cross_boresight_arcsec: float
    """Angle between the solved and the true boresight (camera +z)."""
    roll_arcsec: float
    """Signed rotation about the boresight (right-handed about +z), in (-648000, 648000]."""
    total_arcsec: float
    """Angle of the whole error rotation."""


def attitude_error(q_solved: Sequence[float], q_truth: Sequence[float]) -> AttitudeError:
    """Error of ``q_solved`` against ``q_truth`` (both ICRS -> camera, ``[w, x, y, z]``).

    The error rotation is ``R_err = R_solved R_truthᵀ``: it takes the true camera frame to the
    solved one, so it is expressed in the camera frame. Cross-boresight error is the angle by
    which ``R_err`` moves the boresight ``+z``; roll is the twist of ``R_err`` about ``+z`` in
    its swing-twist decomposition ``R_err = R_swing R_twist`` (twist about z first, then the
    swing that tilts z), ``2 atan2(q_z, q_w)`` of ``q_err``.
    """
    q_err = quat_mul(quat_normalize(q_solved), quat_conj(quat_normalize(q_truth)))
    w, x, y, z = q_err
    bx, by, bz = quat_rotate(q_err, (0.0, 0.0, 1.0))
    cross = math.atan2(math.hypot(bx, by), bz)
    roll = 2.0 * math.atan2(z, w)
    if roll > math.pi:
        roll -= 2.0 * math.pi
    elif roll <= -math.pi:
        roll += 2.0 * math.pi
    total = 2.0 * math.atan2(math.sqrt(x * x + y * y + z * z), abs(w))
    return AttitudeError(cross * RAD_TO_ARCSEC, roll * RAD_TO_ARCSEC, total * RAD_TO_ARCSEC)
