"""From a verified identification to the answer, on the general path (any number of cameras).

``auto``'s first pass does these steps compiled for one camera (:mod:`service.core.first_pass`);
an answer found anywhere else comes here (:func:`solution`): a fit pulled off by a few wrong
pairs is trimmed (:mod:`service.core.trimmed`), the blobs of close doubles are named and the
implausible pairs dropped (:func:`checked_pairs`; :func:`service.core.answer.compiled_checks`
for one camera), the catalogue's directions are moved to the frame's epoch and aberrated, and
the attitude is fitted to them.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np

from .answer import compiled_checks, pair_offsets, repaired
from .apparent import aberrate, apparent_directions
from .attitude import ARCSEC_PER_RAD, estimate
from .blends import dominant_pairs
from .hidden import hidden_kernel, hidden_neighbours
from .match import CROWD, EDGE_CROWDS
from .navdb.reader import NavDatabase
from .photometry import (
    FAINT_GATE_MAG,
    beyond_completeness,
    faintest_inverted_among,
    faintest_past_missed,
    too_bright,
)
from .residuals import distant_pairs
from .solution import answer
from .star_index import star_tree
from .trimmed import trimmed_basin
from .types import Solution
from .verify import Observation, Verified

if TYPE_CHECKING:
    from .pipeline import SolveOptions


def apparent(db: NavDatabase, cat: np.ndarray, options: SolveOptions) -> tuple[np.ndarray, np.ndarray]:
    """Directions of catalogue rows ``cat``: astrometric at the frame's epoch (reported per
    star) and apparent (also aberrated; what the attitude is fitted to)."""
    ref = np.asarray(db.stars.vec[cat])
    dt = 0.0 if options.epoch is None else options.epoch - db.epoch
    if dt != 0.0 and db.stars.pm is not None:
        ref = apparent_directions(ref, pm_mas_yr=np.asarray(db.stars.pm[cat]), dt_years=dt)
    seen = ref if options.observer_velocity_km_s is None else aberrate(ref, np.asarray(options.observer_velocity_km_s))
    return ref, seen


FieldStars = list[tuple[np.ndarray, np.ndarray]]
"""Per camera: the catalogue rows predicted inside its image, and their pixel positions."""


def _implausible_pairs(obs: Observation, db: NavDatabase, v: Verified, near: FieldStars, radius_px: float,
                       sigma_px: float = 0.0) -> np.ndarray:
    """Pairs whose observed star is far brighter than its catalogue star, whose catalogue star
    is fainter than the frame's completeness or past unseen stars (see
    :mod:`service.core.photometry`), that lie
    too far from it for the frame's noise (:mod:`service.core.residuals`; a star predicted just
    past the image's edge, among ``near``'s, is held closer), or near a star the member left out
    (:mod:`service.core.hidden`)."""
    pair_mag = np.asarray(db.stars.mag[v.cat], dtype=np.float64)
    d_near = np.full(len(v.obs), np.nan)
    outside = np.zeros(len(v.obs), bool)
    field_rows = []  # per camera, the catalogue rows predicted inside its image
    for c, (rows, pxy) in enumerate(near):
        inside = obs.cameras[c].contains(pxy)
        field_rows.append(rows[inside])
        mine = np.flatnonzero(obs.camera[v.obs] == c)
        if len(mine) and len(rows):
            d_near[mine], outside[mine] = pair_offsets(obs.xy, v.obs[mine], v.cat[mine], rows, pxy, inside)
    d = np.where(outside, np.nan, d_near)  # the pairs inside, as the checks below take them
    bad = distant_pairs(d_near, pair_mag, sigma_px, outside)
    hidden, limits = hidden_neighbours(db)
    for c, cam in enumerate(obs.cameras):
        mine = np.flatnonzero(obs.camera[v.obs] == c)
        bad[mine] |= hidden_kernel(v.cat[mine], d[mine], pair_mag[mine], hidden, limits, cam.pixel_scale_rad,
                                   CROWD * radius_px)
    if obs.flux is not None:
        bad |= too_bright(obs.flux[v.obs], pair_mag)
    rows = np.unique(np.concatenate(field_rows)) if field_rows else np.zeros(0, np.int64)
    field_paired = _member(rows, v.cat)
    if len(pair_mag) >= 3 and pair_mag.max() > np.median(pair_mag) + FAINT_GATE_MAG:
        bad |= beyond_completeness(pair_mag, db.stars.mag[rows], field_paired)
    if obs.flux is not None:  # then the faintest pair against the pairs the others keep
        bad |= faintest_inverted_among(obs.flux[v.obs], pair_mag, bad)
    return bad | faintest_past_missed(pair_mag, db.stars.mag[rows], field_paired, bad)


def _member(rows: np.ndarray, of: np.ndarray) -> np.ndarray:
    """``np.isin(rows, of)`` for the few dozen rows of a frame (a set: ~10x faster here)."""
    s = set(of.tolist())
    return np.fromiter((r in s for r in rows.tolist()), dtype=bool, count=len(rows))


def _blend_pairs(obs: Observation, db: NavDatabase, v: Verified, radius_px: float,
                 field: FieldStars) -> Verified | None:
    """``v`` with the blobs of close doubles named as their dominant star (see
    :mod:`service.core.blends`), or None when there are none."""
    free = np.ones(len(obs), dtype=bool)
    free[v.obs] = False
    if not free.any():
        return None
    add_o, add_c = [], []
    faintest = float(np.max(db.stars.mag[v.cat]))
    for c, (rows, pxy) in enumerate(field):
        mine = np.flatnonzero((obs.camera == c) & free)
        unpaired = ~_member(rows, v.cat)
        if len(mine) == 0 or not unpaired.any():
            continue
        cand, cxy = rows[unpaired], pxy[unpaired]
        mag = np.asarray(db.stars.mag[cand], np.float64)
        # a blob is as bright as the stars already named, not a faint catalogue star's neighbour;
        # a star just past the edge crowds it but is never named (match.EDGE_CROWDS)
        o, p = dominant_pairs(obs.xy, mine, cxy, mag, (mag <= faintest + 0.5) & obs.cameras[c].contains(cxy),
                              radius_px, CROWD)
        add_o.append(o)
        add_c.append(cand[p])
    if not add_o or sum(len(o) for o in add_o) == 0:
        return None
    return Verified(np.concatenate([v.obs, *add_o]), np.concatenate([v.cat, *add_c]), v.matrix, v.false_prob,
                    v.n_trials)


def stars_in_field(obs: Observation, db: NavDatabase, r_body: np.ndarray, margin_px: float = 0.0) -> FieldStars:
    """Per camera, the catalogue rows predicted inside its image under the ICRS -> body
    ``r_body`` (or outside it within ``margin_px`` of its edge), with their pixel positions."""
    tree = star_tree(db)
    out: FieldStars = []
    for cam, mount in zip(obs.cameras, obs.mountings, strict=True):
        r_cam = mount @ r_body
        half = math.radians(cam.diagonal_fov_deg / 2 + 0.1)
        near = np.asarray(tree.query_ball_point(r_cam[2], 2 * math.sin(half / 2)), dtype=np.int64)
        if len(near):
            pxy, inside = cam.vector_to_pixel(np.asarray(db.stars.vec[near]) @ r_cam.T)
            if margin_px > 0:
                inside = cam.contains(pxy, -margin_px)  # NaN (behind the camera) compares False
            out.append((near[inside], pxy[inside]))
        else:
            out.append((near, np.zeros((0, 2))))
    return out


def checked_pairs(obs: Observation, db: NavDatabase, v: Verified, radius_px: float,
                  sigma_px: float = 0.0) -> tuple[Verified, bool]:
    """``v`` after the checks of a proven answer, and whether its pairs changed: the blobs of
    close doubles named as their dominant star, then the implausible pairs dropped (far too
    bright for their catalogue star, or fainter than the frame's completeness). Any number of
    cameras; :func:`service.core.answer.compiled_checks` is the same for one camera, compiled."""
    moved = False
    # the field's stars and those just past the image's edge (match.EDGE_CROWDS), once for both checks
    near = stars_in_field(obs, db, v.matrix, CROWD * radius_px if EDGE_CROWDS else 0.0)
    blended = _blend_pairs(obs, db, v, radius_px, near)
    if blended is not None:
        v, moved = blended, True
    implausible = _implausible_pairs(obs, db, v, near, radius_px, sigma_px)  # also judges the blends just named
    if implausible.any():  # false detections paired with faint catalogue stars by position alone
        v = Verified(v.obs[~implausible], v.cat[~implausible], v.matrix, v.false_prob, v.n_trials)
        moved = True
    return v, moved


def solution(obs: Observation, db: NavDatabase, v: Verified, method: str, sigma_rad: float,
              options: SolveOptions) -> Solution:
    """The answer of the verified identification ``v`` (found by ``method``; ``sigma_rad`` the
    declared centroid error): a fit pulled off by a few wrong pairs trimmed, the pairs checked
    (:func:`checked_pairs`, compiled for one camera), the catalogue's directions made apparent
    (epoch, aberration) and the attitude fitted to them; a one-camera answer with a pair past the
    match radius under that fit is paired again from it (:func:`~.answer.repaired`)."""
    moved = options.epoch is not None or options.observer_velocity_km_s is not None
    radius = options.match_radius_px or max(2.5, 3.0 * sigma_rad / obs.pixel_scale_rad)
    sigma_px = sigma_rad / obs.pixel_scale_rad
    trimmed = trimmed_basin(obs, db, v, radius, sigma_px)  # a fit pulled off by a few wrong pairs
    if trimmed is not None:
        v, moved = trimmed, True
    checked = compiled_checks(obs, db, v.obs, v.cat, v.matrix, radius, sigma_px)  # one camera: compiled
    if checked is None:
        v, changed = checked_pairs(obs, db, v, radius, sigma_px)
    else:
        changed = checked[2]
        if changed:
            v = Verified(checked[0], checked[1], v.matrix, v.false_prob, v.n_trials)
    moved = moved or changed
    ref, seen = apparent(db, v.cat, options)
    fit = estimate(obs.vec[v.obs], seen, matrix=None if moved else v.matrix, prior_sigma_rad=sigma_rad)
    if len(v.obs) >= 3 and np.max(fit.residuals_arcsec) > radius * obs.pixel_scale_rad * ARCSEC_PER_RAD:
        # a pair past the match radius under the final fit: paired again from it (answer.repair_kernel)
        again = repaired(obs, db, v.obs, v.cat, fit.matrix, radius, sigma_px)
        if again is not None:
            v = Verified(again[0], again[1], fit.matrix, v.false_prob, v.n_trials)
            ref, seen = apparent(db, v.cat, options)
            fit = estimate(obs.vec[v.obs], seen, prior_sigma_rad=sigma_rad)
    return answer(obs, db, v.obs, v.cat, ref, fit.matrix, fit.residuals_arcsec, fit.rms_arcsec, fit.sigma_arcsec,
                   v.false_prob, method)
