"""The real images' reference attitudes, and the same reference with its roll made rigid.

truth.json's quaternion is astrometry.net's WCS turned into a rotation: its camera +x axis is
the WCS *column* axis at the image centre (checked: fitting the WCS's own predicted star
pixels, matches.json ``pred_x``/``pred_y``, leaves the column axis within a few arcsec of the
quaternion's x on every image). The WCS's CD matrix also has a skew, a free parameter of
astrometry.net's fit (a camera with square pixels has none; on the eight frames of one camera
it takes both signs, from -93" to +78"), so the row axis is off the quaternion's -y by the skew.
A rigid camera's best rotation lies half-way: the orthogonal (polar) factor of the WCS's linear
map. :func:`rigid_reference` gives that rotation: the truth.json quaternion turned about the
boresight by the polar factor's angle; the boresight is unchanged.

Frames: pixels x = column, y = row with the image centre at (W/2, H/2) (matches.json's corner
convention); camera +x right, +y down, +z boresight; ``v_cam = R v_icrs``.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from service.core.attitude import matrix_to_quat, quat_to_matrix
from service.core.catalog import load_hipparcos, propagate

MATCHES_EPOCH = 2024.0
"""Epoch of the catalogue positions matches.json's predictions were made from (its ``_about``)."""


@dataclass(frozen=True)
class RigidReference:
    """One image's reference, rigid.

    Attributes
    ----------
    quaternion : list of float
        ``[w, x, y, z]``, the truth.json quaternion turned about +z by ``roll_arcsec``.
    roll_arcsec : float
        The polar factor's angle: how far the rigid reference's roll is from truth.json's.
    skew_arcsec : float
        The WCS linear map's skew: angle between its row axis and the perpendicular to its column axis.
    centre_px : tuple of float
        Pixel offset of the quaternion's boresight from (W/2, H/2) in the fitted map (0 when the
        centre conventions agree).
    """

    quaternion: list[float]
    roll_arcsec: float
    skew_arcsec: float
    centre_px: tuple[float, float]


def _linear_map(tangent: np.ndarray, offsets: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Least-squares map ``offsets ~ c + M t + quadratic(t)`` (quadratic and cubic terms when
    there are enough stars, as the WCS's SIP polynomial); returns ``c`` (px) and ``M`` (px/rad)."""
    u, v = tangent[:, 0], tangent[:, 1]
    cols = [np.ones(len(u)), u, v]
    if len(u) >= 10:
        cols += [u * u, u * v, v * v]
    if len(u) >= 16:
        cols += [u**3, u * u * v, u * v * v, v**3]
    coef, *_ = np.linalg.lstsq(np.stack(cols, axis=1), offsets, rcond=None)
    return coef[0], coef[1:3].T


def rigid_reference(truth: dict, matches: list[dict]) -> RigidReference:
    """The rigid reference of one image from its truth.json entry and matches.json rows."""
    cat = load_hipparcos()
    index = {int(h): i for i, h in enumerate(cat.hip)}
    vec = propagate(cat, MATCHES_EPOCH)
    rows = [m for m in matches if int(m["hip"]) in index]
    r = quat_to_matrix(np.asarray(truth["quaternion_icrs_to_camera_wxyz"], float))
    cam = np.array([vec[index[int(m["hip"])]] for m in rows]) @ r.T
    tangent = cam[:, :2] / cam[:, 2:3]
    offsets = np.array([[m["pred_x"] - truth["width"] / 2, m["pred_y"] - truth["height"] / 2] for m in rows])
    centre, lin = _linear_map(tangent, offsets)
    u, _, vt = np.linalg.svd(lin)
    polar = u @ vt
    theta = math.atan2(polar[1, 0], polar[0, 0])
    col = math.atan2(lin[1, 0], lin[0, 0])
    row = math.atan2(-lin[0, 1], lin[1, 1])
    c, s_ = math.cos(theta), math.sin(theta)
    turn = np.array([[c, -s_, 0.0], [s_, c, 0.0], [0.0, 0.0, 1.0]])
    q = matrix_to_quat(turn @ r)
    arcsec = math.degrees(1.0) * 3600.0
    return RigidReference([float(x) for x in q], theta * arcsec, (col - row) * arcsec,
                          (float(centre[0]), float(centre[1])))


def rigid_references(directory: Path) -> dict[str, RigidReference]:
    """:func:`rigid_reference` of every image in ``directory`` (truth.json, matches.json)."""
    truth = json.loads((directory / "truth.json").read_text())["images"]
    matches = json.loads((directory / "matches.json").read_text())["images"]
    return {name: rigid_reference(truth[name], matches[name]["matches"]) for name in sorted(truth)}
