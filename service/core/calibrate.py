"""Camera calibration from solved frames: focal length, principal point, Brown-Conrady distortion.

Every frame is identified with the current camera model; the identified stars (catalogue
directions, measured pixels) of all frames then fix one camera and one small attitude
correction per frame by least squares (scipy's ``least_squares``, sparse Jacobian: each
frame's residuals depend on the camera and its own three angles only). The improved camera
re-identifies the frames (more stars are paired once the distortion is known) and the fit is
repeated until the camera stops moving.

Frames: camera x = column, y = row (px); camera frame +z boresight; ``v_cam = R(q) v_icrs``.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy.optimize import least_squares
from scipy.sparse import lil_matrix
from scipy.spatial.transform import Rotation

from .attitude import quat_to_matrix
from .camera import Camera, _distort
from .geometry import radec_to_vector
from .pipeline import SolveOptions, solve
from .types import Centroids

PARAMS = ("f_px", "cx", "cy", "k1", "k2", "p1", "p2", "k3")
"""The camera parameters a calibration may fit, in the order of its parameter vector."""
DEFAULT_FIT = ("f_px", "cx", "cy", "k1", "k2", "p1", "p2")


@dataclass(frozen=True)
class Calibration:
    """The fitted camera and how well it is known.

    Attributes
    ----------
    camera : Camera
        The calibrated camera (f_px, cx, cy in px; distortion in OpenCV order k1, k2, p1, p2, k3).
    sigma : dict
        1-sigma of each fitted parameter (px for f_px, cx, cy; unitless for distortion), from the
        Jacobian at the solution scaled by the residuals' variance.
    rms_px_nominal, rms_px : float
        RMS pixel residual of the identified stars with the starting camera (each frame's own
        attitude fit) and with the calibrated camera (joint fit).
    frames_solved : int
        Frames identified with the calibrated camera (of ``frames_total``).
    stars : int
        Identified stars in the final fit.
    history : list of dict
        Per iteration: frames solved, stars, RMS, the camera parameters.
    """

    camera: Camera
    sigma: dict[str, float]
    rms_px_nominal: float
    rms_px: float
    frames_solved: int
    frames_total: int
    stars: int
    history: list[dict[str, Any]] = field(default_factory=list)

    def report(self) -> dict[str, Any]:
        """A JSON-ready summary."""
        values = _camera_vector(self.camera)
        return {
            "camera": self.camera.to_spec(),
            "parameters": {p: {"value": float(values[i]), "sigma": self.sigma.get(p)} for i, p in enumerate(PARAMS)},
            "rms_px_nominal": self.rms_px_nominal,
            "rms_px": self.rms_px,
            "frames_solved": self.frames_solved,
            "frames_total": self.frames_total,
            "stars": self.stars,
            "history": self.history,
        }


@dataclass(frozen=True)
class _Matched:
    """The identified stars of one frame: pixels ``(n, 2)``, ICRS unit vectors ``(n, 3)``, and
    the frame's ICRS -> camera matrix; ``f_px`` the focal length (px) its answer was fitted with
    when the solve searched focal lengths (``SolveOptions.fov_max_error_deg``), else None."""

    xy: np.ndarray
    ref: np.ndarray
    matrix: np.ndarray
    f_px: float | None = None


def _camera_vector(camera: Camera) -> np.ndarray:
    d = list(camera.distortion or ()) + [0.0] * 5
    return np.array([camera.f_px, camera.cx, camera.cy, *d[:5]], dtype=np.float64)


def _camera_from_vector(template: Camera, x: np.ndarray) -> Camera:
    return Camera._make(template.width, template.height, float(x[0]), cx=float(x[1]), cy=float(x[2]),
                        distortion=tuple(float(v) for v in x[3:8]))


def project(camera_vec: np.ndarray, v_cam: np.ndarray) -> np.ndarray:
    """Pixels ``(n, 2)`` of camera-frame vectors ``(n, 3)`` under the camera vector
    ``(f_px, cx, cy, k1, k2, p1, p2, k3)``."""
    xn = v_cam[:, 0] / v_cam[:, 2]
    yn = v_cam[:, 1] / v_cam[:, 2]
    xd, yd = _distort(xn, yn, tuple(camera_vec[3:8]))
    return np.stack([camera_vec[0] * xd + camera_vec[1], camera_vec[0] * yd + camera_vec[2]], axis=1)


def identify(frames: Sequence[Centroids], camera: Camera, db: Any, *, method: str = "auto",
             options: SolveOptions | None = None) -> list[_Matched | None]:
    """Solve every frame with ``camera``; the identified stars of each (None: not solved)."""
    options = options or SolveOptions()
    out: list[_Matched | None] = []
    for cents in frames:
        sol = solve(cents, camera, db, method=method, options=options)
        if not sol.solved or sol.quaternion is None or len(sol.stars) < 4:
            out.append(None)
            continue
        idx = np.array([s.centroid for s in sol.stars])
        ra = np.radians([s.ra_deg for s in sol.stars])
        dec = np.radians([s.dec_deg for s in sol.stars])
        f_px = None if sol.fov_deg is None else Camera.from_fov(sol.fov_deg, camera.width, camera.height).f_px
        out.append(_Matched(np.asarray(cents.xy)[idx], radec_to_vector(ra, dec),
                            quat_to_matrix(np.asarray(sol.quaternion, dtype=np.float64)), f_px))
    return out


def _fit(matched: Sequence[_Matched], start: np.ndarray, fit_mask: np.ndarray
         ) -> tuple[np.ndarray, np.ndarray, float, np.ndarray]:
    """Joint least squares of the camera parameters ``fit_mask`` selects and one rotation vector
    per frame. Returns the camera vector, the 1-sigma of every camera parameter (0 where not
    fitted), the RMS pixel residual and the corrected frame matrices ``(F, 3, 3)``."""
    n_cam = int(fit_mask.sum())
    counts = np.array([len(m.xy) for m in matched])
    offsets = np.concatenate([[0], np.cumsum(2 * counts)])
    xy = np.concatenate([m.xy for m in matched])
    # catalogue vectors already turned into each frame's camera frame by its starting attitude
    v0 = np.concatenate([m.ref @ m.matrix.T for m in matched])
    frame_of = np.repeat(np.arange(len(matched)), counts)

    def unpack(p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        cam = start.copy()
        cam[fit_mask] = p[:n_cam]
        return cam, p[n_cam:].reshape(-1, 3)

    def residuals(p: np.ndarray) -> np.ndarray:
        cam, rotvecs = unpack(p)
        rot = Rotation.from_rotvec(rotvecs).as_matrix()[frame_of]  # (N, 3, 3) small corrections
        v = np.einsum("nij,nj->ni", rot, v0)
        return (project(cam, v) - xy).ravel()

    sparsity = lil_matrix((len(xy) * 2, n_cam + 3 * len(matched)), dtype=np.int8)
    sparsity[:, :n_cam] = 1
    for i in range(len(matched)):
        sparsity[offsets[i]:offsets[i + 1], n_cam + 3 * i:n_cam + 3 * i + 3] = 1
    p0 = np.concatenate([start[fit_mask], np.zeros(3 * len(matched))])
    scale = np.concatenate([np.where(np.arange(8)[fit_mask] < 3, 1.0, 1e-3), np.full(3 * len(matched), 1e-4)])
    res = least_squares(residuals, p0, jac_sparsity=sparsity, x_scale=scale, method="trf", xtol=1e-12,
                        ftol=1e-12, gtol=1e-12, max_nfev=200)
    cam, rotvecs = unpack(res.x)
    dof = max(res.fun.size - res.x.size, 1)
    s2 = float(res.fun @ res.fun) / dof
    jac = res.jac.toarray() if hasattr(res.jac, "toarray") else np.asarray(res.jac)
    cov = np.linalg.pinv(jac.T @ jac) * s2
    sigma = np.zeros(8)
    sigma[fit_mask] = np.sqrt(np.clip(np.diag(cov)[:n_cam], 0, None))
    rms = math.sqrt(float(res.fun @ res.fun) / (res.fun.size / 2))
    corrected = np.array([Rotation.from_rotvec(rv).as_matrix() @ m.matrix for rv, m in zip(rotvecs, matched, strict=True)])
    return cam, sigma, rms, corrected


def _nominal_rms(matched: Sequence[_Matched], camera: Camera) -> float:
    """RMS pixel residual of the identified stars under each frame's own fitted attitude."""
    cam = _camera_vector(camera)
    err = np.concatenate([project(cam, m.ref @ m.matrix.T) - m.xy for m in matched])
    return math.sqrt(float((err**2).sum()) / len(err))


def calibrate(
    frames: Sequence[Centroids],
    camera: Camera,
    db: Any,
    *,
    fit: Sequence[str] = DEFAULT_FIT,
    iterations: int = 4,
    method: str = "auto",
    options: SolveOptions | None = None,
    progress: Callable[[str], None] | None = None,
) -> Calibration:
    """Calibrate ``camera`` (the nominal model: the starting point) from many frames.

    Parameters
    ----------
    frames : sequence of Centroids
        Star centroids (px) of frames taken with the camera, at any attitudes.
    camera : Camera
        Nominal camera: size, focal length, and any known distortion.
    db : NavDatabase or NavDatabaseSet
    fit : names from ``PARAMS``
        The parameters to fit; the others keep the nominal camera's values.
    iterations : int
        Identify-then-fit rounds at most (stops early once the camera moves by less than 0.1 of
        its 1-sigma).
    options : SolveOptions, optional
        The solves' options. With ``fov_max_error_deg`` a nominal focal length a few percent off
        still identifies the frames (each searched over focal lengths), and the first fit starts
        from the median of the focal lengths they fitted.
    """
    unknown = set(fit) - set(PARAMS)
    if unknown:
        raise ValueError(f"unknown calibration parameters {sorted(unknown)}; choose from {PARAMS}")
    fit_mask = np.array([p in fit for p in PARAMS])
    say = progress or (lambda _msg: None)
    current = camera
    history: list[dict[str, Any]] = []
    nominal_rms = math.nan
    sigma = np.zeros(8)
    rms = math.nan
    matched: list[_Matched] = []
    for it in range(max(1, iterations)):
        found = identify(frames, current, db, method=method, options=options)
        matched = [m for m in found if m is not None]
        if not matched:
            raise ValueError(f"none of the {len(frames)} frames identified: nothing to calibrate from")
        if it == 0:
            nominal_rms = _nominal_rms(matched, camera)
        before = _camera_vector(current)
        searched = [m.f_px for m in matched if m.f_px is not None]
        if it == 0 and searched and fit_mask[0]:
            # a nominal camera of uncertain field (options.fov_max_error_deg): the fit starts from the
            # frames' own fitted focal lengths, whose attitudes were fitted with them
            before[0] = float(np.median(searched))
        vec, sigma, rms, _ = _fit(matched, before, fit_mask)
        current = _camera_from_vector(camera, vec)
        step = np.abs(vec - before)[fit_mask] / np.maximum(sigma[fit_mask], 1e-12)
        history.append({"iteration": it + 1, "frames_solved": len(matched), "stars": int(sum(len(m.xy) for m in matched)),
                        "rms_px": rms, "camera": current.to_spec()})
        say(f"iteration {it + 1}: {len(matched)}/{len(frames)} frames, {history[-1]['stars']} stars, "
            f"RMS {rms:.3f} px, f {vec[0]:.2f} px")
        if it > 0 and float(step.max()) < 0.1:
            break
    return Calibration(
        camera=current,
        sigma={p: float(sigma[i]) for i, p in enumerate(PARAMS) if fit_mask[i]},
        rms_px_nominal=nominal_rms,
        rms_px=rms,
        frames_solved=len(matched),
        frames_total=len(frames),
        stars=int(sum(len(m.xy) for m in matched)),
        history=history,
    )


__all__ = ["Calibration", "DEFAULT_FIT", "PARAMS", "calibrate", "identify", "project"]
