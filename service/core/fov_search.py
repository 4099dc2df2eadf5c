"""A camera whose field of view is known only roughly: search focal lengths, fit the one the stars say.

The pattern look-ups and the verifier both take the camera's focal length as given: a
pattern's largest edge is part of ``quad``'s key and every predicted star is placed with it.
A field off by 1% moves an 8.6-deg camera's corner stars by ~7 px, past the match radius, and
skews the largest edges past the pattern tolerance: on the default database seed 000's camera
(1 px, 2 false stars) solved 24 of 40 frames with its field 1% too wide and none at 3%, where
tetra3rs, whose keys are edge ratios and which fits the field from the match, solved 38 of 40
at up to 9% (``/work/s25/wrongfov.py``, ``t3_wrongfov.py``). A lens's nominal focal length
and a sensor's nominal pitch are rarely better than 1-2%, and ``skyfix calibrate`` starts
from them. Given ``SolveOptions.fov_max_error_deg``, :func:`solve_uncertain_fov`:

1. solves with the camera as given (with ``auto``: its ``quad`` pass);
2. if that proves nothing, or its answer refitted (step 3) pairs fewer than half the
   centroids (:data:`FEW_PAIRED_SHARE`: then the answer that pairs more stars is kept), solves
   again at focal lengths stepped through the range the error allows, nearest first
   (:func:`focal_ladder`: each step at most one match radius at the image corner, so a step's
   worst focal error moves a corner star by half a radius); then,
   with ``auto``, the camera as given with every method (the fallbacks prove 3-4-star frames;
   run first, with a wrong field they ran a 20-deg camera's frame to the time limit);
3. fits the focal length to the identified stars (:func:`fit_focal`, closed form: the
   projection is linear in it, distortion included) and solves again with the fitted camera,
   so that the answer's stars, attitude and residuals are the fitted camera's;
   ``Solution.fov_deg`` reports its horizontal field.

Every step tests the frame against the catalogue again. The ladder's K steps each accept only
below ``max_false_prob / K`` (Bonferroni), so the chance that any of them names a coincidence
is at most ``max_false_prob``, and with the first solve at most twice that. With ``auto`` the
ladder's steps run ``quad`` alone (the compiled first pass and the next member's ``quad``): a
frame too sparse for it rarely fixes a focal length anyway, and the fallbacks at every step
would cost a frame that no step proves ~50 times their time. The whole search keeps
``timeout_ms``.
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence
from dataclasses import replace

import numpy as np

from .attitude import quat_to_matrix
from .camera import Camera, _distort
from .errors import InvalidInputError
from .geometry import radec_to_vector
from .navdb.reader import NavDatabase, NavDatabaseSet
from .types import Centroids, NoSolutionReason, Solution

MAX_FOV_ERROR_DEG = 30.0
"""Largest ``fov_max_error_deg`` accepted (a wider range is no estimate of the field at all)."""
FOCAL_SIGMAS = 3.0
"""A fitted focal length within this many of its 1-sigma of the camera's is the camera's: the
answer proven with the camera as given is kept (1 px of centroid noise moves the fit of seed
000's camera by ~0.05%: a difference of noise, not of field)."""
OUTLIER_PASSES = 2
"""Refits of the focal length without the pairs that lie beyond ``OUTLIER_SPREADS`` robust
spreads of the rest (a pair made at the wrong focal length: a star far out, paired with another
catalogue star that lay near its wrongly placed position, pulled a 20-deg camera's fit 10 of its
1-sigma toward the wrong focal length)."""
OUTLIER_SPREADS = 4.0
MIN_SPREAD_PX = 0.3
"""The robust spread's floor, px (a handful of stars can agree to a few hundredths of a pixel)."""
FEW_PAIRED_SHARE = 0.5
"""An answer proven with the camera as given that pairs fewer than this share of the frame's
centroids, after its own refit, is checked against the focal ladder: the ladder's answer is
taken where it pairs more stars. A field told 1-2% too wide still proved some frames with the
stars near the centre, whose fit does not fix the scale, and there one star was named after
its neighbour (seed 000's camera at +2%: 6 of 19 centroids paired, one wrong; the true field
pairs 12). Right answers with the true field pair 44-100% of the centroids (median 85%; seeds
000, 001, 004 at 1 px with 2 false stars, 100 frames each; ``/work/s28/fov_frac.py``), with a
field 1% off 13-40%."""
REFIT_ROUNDS = 6
"""Fit-then-solve rounds at most after a step proves the frame: each solve refits the attitude to
the new focal length and pairs more stars. Most frames settle in one or two; a 20-deg camera's
frame found 1.8% off, with one pair the wrong focal length made, took five (-1.76, -1.48,
-1.31, -1.09, -0.32, -0.05%: the wrong pair is left out once the rest agree)."""



def solve_uncertain_fov(centroids: Centroids, camera: Camera, db: NavDatabase | NavDatabaseSet, *,
                        method: str = "auto", hint: tuple[Sequence[float], float] | None = None,
                        options: object) -> Solution:
    """:func:`~service.core.pipeline.solve` for a camera whose horizontal field may be off by up to
    ``options.fov_max_error_deg`` degrees (see the module's docstring). The answer is that of the
    fitted camera, whose horizontal field (deg) is ``Solution.fov_deg``."""
    from .pipeline import _ensure_warm, solve  # (pipeline calls this module)

    _ensure_warm(db)  # once per opened database, not charged to the frame's time limit (as solve does)
    t0 = time.perf_counter()
    error = options.fov_max_error_deg  # type: ignore[attr-defined]
    if not (isinstance(error, int | float) and math.isfinite(error) and 0 < error <= MAX_FOV_ERROR_DEG):
        raise InvalidInputError("fov_max_error_deg",
                                f"must be a number of degrees in (0, {MAX_FOV_ERROR_DEG:g}]")
    plain = replace(options, fov_max_error_deg=None)
    held = db.any_methods if isinstance(db, NavDatabaseSet) else db.methods
    sweep_method = "quad" if method == "auto" and "quad" in held else method
    deadline = t0 + plain.timeout_ms / 1e3
    # the camera as given: its quad pass first (auto's own first pass), its fallbacks last, after
    # the ladder: with a wrong field they are what costs (a 20-deg camera 3% off: maxangle's
    # hypotheses ran to the 500-ms limit and left no time for the ladder)
    first = solve(centroids, camera, db, method=sweep_method, hint=hint, options=plain)
    given = None  # the camera as given's answer, refitted, where it pairs few of the stars
    if first.solved:
        given = _finish(first, centroids, camera, db, method, hint, plain, t0)
        if len(given.stars) >= FEW_PAIRED_SHARE * len(centroids):
            return given
    elif len(centroids) < 3 or first.reason is NoSolutionReason.CAMERA_OUTSIDE_DATABASE:
        return _stamp(first, t0)
    radius = plain.match_radius_px or max(2.5, 3.0 * plain.centroid_sigma_px)
    # (steps of a wider radius, with a wider centroid error, were tried: fewer steps, but each
    # proves less and costs more; seed 000's camera at +1-9%: 37 of 40 frames against 39)
    ladder = focal_ladder(camera, error, radius)
    strict = replace(plain, max_false_prob=plain.max_false_prob / max(len(ladder), 1))
    tried = 0
    for f_px in ladder:
        left_ms = (deadline - time.perf_counter()) * 1e3
        if left_ms <= 0:
            break
        tried += 1
        cam = replace(camera, f_px=float(f_px))
        step = replace(strict, timeout_ms=left_ms)
        sol = solve(centroids, cam, db, method=sweep_method, hint=hint, options=step)
        if sol.solved:
            fitted = _refit(sol, centroids, cam, db, method, hint, strict, radius)
            if fitted is not None and (given is None or len(fitted.stars) > len(given.stars)):
                return _stamp(fitted, t0)
            if fitted is not None:
                break  # a focal length of the range proves no more than the camera as given
    if given is not None:
        return _stamp(given, t0)
    left_ms = (deadline - time.perf_counter()) * 1e3
    if sweep_method != method and left_ms > 0:  # the camera as given, every method (a 3-4-star frame)
        rest = replace(plain, timeout_ms=left_ms)
        first = solve(centroids, camera, db, method=method, hint=hint, options=rest)
        if first.solved:
            return _finish(first, centroids, camera, db, method, hint, plain, t0)
    late = tried < len(ladder) or first.reason is NoSolutionReason.TIME_LIMIT
    why = (f"no focal length proved the frame: the camera as given, then {tried} of {len(ladder)} "
           f"focal lengths within +-{error:g} deg of its {camera.fov_deg:.4g}-deg field"
           + (" before the time limit" if late else ""))
    out = replace(first, reason=NoSolutionReason.TIME_LIMIT if late else first.reason,
                  message=f"{why}; with the camera as given: {first.message}")
    return _stamp(out, t0)


def focal_ladder(camera: Camera, fov_error_deg: float, radius_px: float) -> np.ndarray:
    """Focal lengths (px) to try for a horizontal field of ``camera.fov_deg +- fov_error_deg``,
    nearest to the camera's own first, alternating above and below it, the camera's own left
    out. Consecutive steps differ by ``radius_px`` at the image corner (relative step
    ``radius_px / half-diagonal``), so every focal length of the range is within half a match
    radius at the corner of one step."""
    fov = camera.fov_deg
    lo_fov, hi_fov = max(fov - fov_error_deg, 0.01), min(fov + fov_error_deg, 169.0)
    f_lo, f_hi = (Camera.from_fov(deg, camera.width, camera.height).f_px  # a wider field: a shorter f
                  for deg in (hi_fov, lo_fov))
    step = radius_px / (0.5 * math.hypot(camera.width, camera.height))
    n_up = int(math.floor(math.log(f_hi / camera.f_px) / math.log1p(step)))
    n_down = int(math.floor(math.log(camera.f_px / f_lo) / math.log1p(step)))
    out = []
    for k in range(1, max(n_up, n_down) + 2):
        for sign, n_side, bound in ((1, n_up, f_hi), (-1, n_down, f_lo)):
            if k <= n_side:
                out.append(camera.f_px * (1 + step) ** (sign * k))
            elif k == n_side + 1 and abs(bound / camera.f_px - 1) > 1e-9:
                out.append(bound)  # the range's own end, past the last whole step
    return np.array(out, dtype=np.float64)


def fit_focal(sol: Solution, centroids: Centroids, camera: Camera, rounds: int = 3) -> tuple[float, float]:
    """The focal length (px) that places the identified stars of ``sol`` best, fitted jointly with
    a small rotation of its attitude (Gauss-Newton on ``(f, 3 angles)``; the principal point and
    distortion held). The attitude was fitted with the old focal length: where the stars lie to
    one side of the centre it took up part of the scale error as a tilt, which a fit of ``f``
    alone would leave. ``x = cx + f * distort(xn, yn)``. Pairs far off the rest's fit are left out
    (``OUTLIER_PASSES``). Returns ``(f, its 1-sigma)`` (px; the 1-sigma from the fit's
    residuals), the camera's own ``f`` and an infinite 1-sigma if fewer than 3 stars."""
    if not sol.solved or len(sol.stars) < 3:
        return camera.f_px, math.inf
    rows = np.array([s.centroid for s in sol.stars], dtype=np.int64)
    ra = np.radians([s.ra_deg for s in sol.stars])
    dec = np.radians([s.dec_deg for s in sol.stars])
    d0 = radec_to_vector(ra, dec) @ quat_to_matrix(np.asarray(sol.quaternion, float)).T  # camera frame
    obs = (np.asarray(centroids.xy, float)[rows] - (camera.cx, camera.cy)).T.ravel()  # x..., y...
    dx0, dy0, dz0 = d0.T
    steps = np.array([camera.f_px * 1e-6, 1e-7, 1e-7, 1e-7])

    def predicted(params: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Pixels ``(2n,)`` (x..., y...) at ``params`` and their Jacobian ``(2n, 4)``."""
        trial = np.repeat(params[None, :], 5, axis=0)  # the parameters and each one nudged
        trial[1:] += np.diag(steps)
        a0, a1, a2 = trial[:, 1:2], trial[:, 2:3], trial[:, 3:4]
        dx = dx0 + a1 * dz0 - a2 * dy0  # (I + [a]x) d: small angles
        dy = dy0 + a2 * dx0 - a0 * dz0
        dz = dz0 + a0 * dy0 - a1 * dx0
        xn, yn = dx / dz, dy / dz
        if camera.distortion:
            xn, yn = _distort(xn, yn, camera.distortion)
        pred = trial[:, :1] * np.concatenate([xn, yn], axis=1)
        return pred[0], ((pred[1:] - pred[0]) / steps[:, None]).T

    n = len(rows)
    keep = np.ones(n, dtype=bool)
    params = np.array([camera.f_px, 0.0, 0.0, 0.0])
    for _ in range(OUTLIER_PASSES + 1):
        rows2 = np.concatenate([keep, keep])
        for _ in range(rounds):
            pred, jac = predicted(params)
            normal = jac[rows2].T @ jac[rows2]
            try:
                delta = np.linalg.solve(normal, jac[rows2].T @ (obs - pred)[rows2])
            except np.linalg.LinAlgError:  # (stars that fix no scale: all at one point)
                return camera.f_px, math.inf
            params = params + delta
            if abs(delta[0]) < 1e-6 * camera.f_px:
                break
        pred, jac = predicted(params)
        off = np.hypot(*(obs - pred).reshape(2, n))  # each star's residual, px
        spread = max(1.4826 * float(np.median(off[keep])), MIN_SPREAD_PX)
        within = off <= OUTLIER_SPREADS * spread
        if within.sum() < 4 or np.array_equal(within, keep):
            break
        keep = within  # a pair the wrong focal length made (a star near another's place): left out
    f_px = float(params[0])
    if not (math.isfinite(f_px) and f_px > 0):
        return camera.f_px, math.inf
    rows2 = np.concatenate([keep, keep])
    resid = (obs - pred)[rows2]
    normal = jac[rows2].T @ jac[rows2]
    dof = max(resid.size - 4, 1)
    cov = np.linalg.pinv(normal) * float(resid @ resid) / dof
    return f_px, float(math.sqrt(max(cov[0, 0], 0.0)))


def _finish(sol: Solution, centroids: Centroids, camera: Camera, db: NavDatabase | NavDatabaseSet,
            method: str, hint: tuple[Sequence[float], float] | None, options: object, t0: float) -> Solution:
    """The answer proven with the camera as given, solved again with the focal length its stars
    fit where that differs from the camera's by more than the fit's noise and moves a corner star
    by more than a tenth of a match radius (else as it is); its ``fov_deg`` set."""
    radius = options.match_radius_px or max(2.5, 3.0 * options.centroid_sigma_px)  # type: ignore[attr-defined]
    fitted = _refit(sol, centroids, camera, db, method, hint, options, radius, must=False)
    if fitted is None:  # (the fitted camera proves less: keep the answer proven)
        object.__setattr__(sol, "fov_deg", camera.fov_deg)
        fitted = sol
    return _stamp(fitted, t0)


def _refit(sol: Solution, centroids: Centroids, camera: Camera, db: NavDatabase | NavDatabaseSet, method: str,
           hint: tuple[Sequence[float], float] | None, options: object, radius_px: float, *,
           must: bool = True) -> Solution | None:
    """``sol`` (proven with ``camera``) solved with ``options`` and the focal length its stars fit
    (:func:`fit_focal`), again while that moves a corner star by more than a tenth of
    ``radius_px``; None if the fitted camera proves nothing, or (unless ``must``: the camera as
    given) if the first fit moves it less than that, or less than half a radius and within
    ``FOCAL_SIGMAS`` of its 1-sigma, or within those sigmas without pairing more stars. The
    answer's ``fov_deg`` is set."""
    from .pipeline import solve

    half_diagonal = 0.5 * math.hypot(camera.width, camera.height)
    best: Solution | None = None
    for _ in range(REFIT_ROUNDS):
        f_px, sigma = fit_focal(sol, centroids, camera)
        corner = abs(f_px / camera.f_px - 1) * half_diagonal  # how far the fit moves a corner star, px
        if corner <= 0.1 * radius_px and (best is not None or not must):
            break  # converged, or the camera as given is right
        noise = abs(f_px - camera.f_px) <= FOCAL_SIGMAS * sigma
        if best is None and not must and corner <= 0.5 * radius_px and noise:
            break  # the camera as given, within the fit's noise and pairing as the fit would
        cam = replace(camera, f_px=f_px)
        cam.validate()
        again = solve(centroids, cam, db, method=method, hint=hint, options=options)
        if not again.solved:
            break
        if best is None and not must and noise and len(again.stars) <= len(sol.stars):
            break  # a move within the fit's noise that pairs no more stars: the camera as given
        sol, camera, best = again, cam, again
    if best is not None:
        object.__setattr__(best, "fov_deg", camera.fov_deg)
    return best


def _stamp(sol: Solution, t0: float) -> Solution:
    """``sol`` with the whole search's time in its ``timings_ms["total"]`` (ms)."""
    timings = dict(sol.timings_ms)
    timings["total"] = (time.perf_counter() - t0) * 1e3
    object.__setattr__(sol, "timings_ms", timings)
    return sol


__all__ = ["MAX_FOV_ERROR_DEG", "fit_focal", "focal_ladder", "solve_uncertain_fov"]
