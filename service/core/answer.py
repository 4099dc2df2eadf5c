"""The checks of a proven answer as one compiled call (one camera).

What :func:`service.core.finish.solution` does to a verified identification before the final
fit, for a single camera: project the catalogue stars of the field under the answer's attitude,
name the blobs of close doubles as their dominant star (:func:`~service.core.blends.dominant_kernel`),
and drop the pairs whose observed star is far too bright for its catalogue star
(:func:`~service.core.photometry.too_bright_kernel`; the faintest of the pairs the other checks
keep: :func:`~service.core.photometry.faintest_inverted_among_kernel`), whose catalogue star is fainter than the
frame's completeness (:func:`~service.core.photometry.completeness_kernel`; the faintest pair past unseen
stars: :func:`~service.core.photometry.faintest_past_missed_kernel`) or that lie too far
from their catalogue star for the frame's noise (:func:`~service.core.residuals.distant_kernel`). The same kernels as
the Python path, without its k-d tree query and its per-camera numpy calls (rigs keep the Python
path). An answer whose final fit puts a pair past the match radius is paired again from that
fit and checked again (:func:`repair_kernel`).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from numba import njit

from .blends import MIN_DELTA_MAG, dominant_kernel
from .camera import project_rows
from .check_kernel import recheck_pairs
from .hidden import hidden_kernel, hidden_neighbours
from .match import CROWD, EDGE_CROWDS, _refine
from .medians import median
from .navdb.reader import NavDatabase
from .photometry import (
    FAINT_GATE_MAG,
    MIN_PAIRS,
    THRESHOLD_MAG,
    completeness_kernel,
    faintest_inverted_among_kernel,
    faintest_past_missed_kernel,
    too_bright_kernel,
)
from .residuals import distant_kernel
from .skygrid import collect_within
from .star_index import field_grid, star_vec64
from .types import IntArray
from .verify import NEAR_MARGIN_DEG

FIELD_MARGIN_DEG = 0.1
"""The field's stars are gathered this far beyond the image's half-diagonal."""


def star_mags(db: NavDatabase) -> np.ndarray:
    """The star magnitudes as float64 (once per opened database)."""
    cache = db.__dict__.setdefault("_cache", {})
    if "mag64" not in cache:
        cache["mag64"] = np.asarray(db.stars.mag, dtype=np.float64)
    return cache["mag64"]


def _field_args(obs, db: NavDatabase) -> tuple[Any, Any, float, np.ndarray]:
    """A one-camera frame's kernel arrays, the field grid of ``db`` over its image, that grid's
    chord and the fluxes (empty when the frame has none)."""
    radius_deg = obs.cameras[0].diagonal_fov_deg / 2 + FIELD_MARGIN_DEG
    chord = 2 * math.sin(math.radians(radius_deg) / 2)
    flux = obs.flux if obs.flux is not None else np.zeros(0)
    return obs.kernel_arrays, field_grid(db, radius_deg), chord, flux


def compiled_checks(obs, db: NavDatabase, m_obs: IntArray, m_cat: IntArray, r: np.ndarray,
                    radius_px: float, sigma_px: float = 0.0) -> tuple[IntArray, IntArray, bool] | None:
    """The pairs of a one-camera answer after the blend and plausibility checks, and whether
    they changed; None for a rig (several cameras: the Python path). ``sigma_px``: the declared
    centroid error per axis (px; 0: the frame's measured one alone)."""
    if len(obs.cameras) != 1:
        return None
    k, g, chord, flux = _field_args(obs, db)
    o, c, moved = answer_kernel(obs.xy, flux, obs.flux is not None, m_obs, m_cat, np.ascontiguousarray(r),
                                star_vec64(db), star_mags(db),
                                g.cell, g.n_side, g.keys, g.starts, g.stars, g.columns, chord, k.mounts[0],
                                k.cams[0], k.dist[0], float(radius_px), float(sigma_px), *hidden_neighbours(db))
    return o, c, moved


def repaired(obs, db: NavDatabase, m_obs: IntArray, m_cat: IntArray, r: np.ndarray, radius_px: float,
             sigma_px: float = 0.0) -> tuple[IntArray, IntArray] | None:
    """:func:`repair_kernel` of a one-camera answer (pairs ``m_obs`` -> ``m_cat`` under their
    final fit ``r``, ICRS -> body): the new pairs, or None where they are no more than the old
    (or for a rig)."""
    if len(obs.cameras) != 1:
        return None
    k, g, chord, flux = _field_args(obs, db)
    o, c, grew = repair_kernel(obs.vec, obs.xy, flux, obs.flux is not None, np.asarray(m_obs, np.int64),
                               np.asarray(m_cat, np.int64), np.ascontiguousarray(r), star_vec64(db), star_mags(db),
                               g.cell, g.n_side, g.keys, g.starts, g.stars, g.columns, chord, k.mounts, k.cams,
                               k.dist, k.rows, k.row_off, float(radius_px), float(radius_px), float(sigma_px),
                               *hidden_neighbours(db))
    return (o, c) if grew else None


def recheck(obs, db: NavDatabase, obs_idx: IntArray, cat_idx: IntArray, n_trials: int, radius_px: float
            ) -> tuple[bool, IntArray, IntArray, np.ndarray, float] | None:
    """:meth:`~service.core.verify.Verifier.check` of the pairs ``obs_idx`` -> ``cat_idx`` in
    ``db`` (one camera) as one compiled call: ``(ok, obs rows, catalogue rows, ICRS -> body
    matrix, false-match bound with n_trials hypotheses)``; None for a rig (the Python path)."""
    if len(obs.cameras) != 1:
        return None
    cam = obs.cameras[0]
    k = obs.kernel_arrays
    radius_deg = cam.diagonal_fov_deg / 2 + NEAR_MARGIN_DEG
    g = field_grid(db, radius_deg)
    near_chord = 2 * math.sin(math.radians(radius_deg) / 2)
    ok, m_obs, m_cat, r, prob = recheck_pairs(
        obs.vec, obs.xy, star_vec64(db), np.array(obs_idx, dtype=np.int64),  # copies (writable): one signature
        np.array(cat_idx, dtype=np.int64), g.cell, g.n_side, g.keys, g.starts, g.stars, g.columns,
        near_chord, k.mounts, k.cams, k.dist, k.rows, k.row_off, float(radius_px), float(obs.pixel_scale_rad),
        int(n_trials))
    return bool(ok), m_obs, m_cat, r, float(prob)


@njit(cache=True, nogil=True)
def field_stars_near(r_cam: np.ndarray, chord: float, cell: float, n_side: int, keys: np.ndarray,
                     starts: np.ndarray, stars: np.ndarray, columns: np.ndarray, star_vec: np.ndarray,
                     cam: np.ndarray, dist: np.ndarray, margin_px: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Catalogue rows predicted inside the image under ``r_cam`` (ICRS -> camera) or outside it
    within ``margin_px`` of its edge, their pixel positions (pinhole + Brown-Conrady, as
    :meth:`~service.core.camera.Camera.vector_to_pixel`) and whether each is inside."""
    buf = np.empty(len(star_vec), np.int64)
    n = collect_within(r_cam[2, 0], r_cam[2, 1], r_cam[2, 2], chord, cell, n_side, keys, starts, stars, star_vec,
                       columns, buf)
    xy = np.full((n, 2), np.nan)  # NaN (behind the camera: not written) is never near
    inside = project_rows(r_cam, star_vec, buf[:n], cam, dist, xy)
    x_lo, y_lo = -0.5 - margin_px, -0.5 - margin_px
    x_hi, y_hi = cam[3] - 0.5 + margin_px, cam[4] - 0.5 + margin_px
    rows = np.empty(n, np.int64)
    pxy = np.empty((n, 2))
    flags = np.empty(n, np.bool_)
    m = 0
    for i in range(n):
        x, y = xy[i, 0], xy[i, 1]
        if inside[i] or (x >= x_lo and x <= x_hi and y >= y_lo and y <= y_hi):
            rows[m] = buf[i]
            pxy[m, 0] = x
            pxy[m, 1] = y
            flags[m] = inside[i]
            m += 1
    return rows[:m].copy(), pxy[:m].copy(), flags[:m].copy()


@njit(cache=True, nogil=True)
def field_stars(r_cam: np.ndarray, chord: float, cell: float, n_side: int, keys: np.ndarray, starts: np.ndarray,
                stars: np.ndarray, columns: np.ndarray, star_vec: np.ndarray, cam: np.ndarray,
                dist: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Catalogue rows predicted inside the image under ``r_cam`` (ICRS -> camera) and their
    pixel positions (:func:`field_stars_near` without a margin)."""
    rows, pxy, _ = field_stars_near(r_cam, chord, cell, n_side, keys, starts, stars, columns, star_vec, cam, dist, 0.0)
    return rows, pxy


@njit(cache=True, nogil=True)
def pair_offsets(obs_xy: np.ndarray, m_obs: np.ndarray, m_cat: np.ndarray, rows: np.ndarray, pxy: np.ndarray,
                 inside: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Distance (px) of each pair's observed star from its catalogue star's predicted position
    (``rows``, predicted inside the image or just past its edge, ``inside`` says which, and their
    pixels ``pxy``; NaN for a catalogue star not among ``rows``), and whether that catalogue star
    is one past the edge."""
    d = np.full(len(m_obs), np.nan)
    outside = np.zeros(len(m_obs), np.bool_)
    for i in range(len(m_obs)):
        for j in range(len(rows)):
            if rows[j] == m_cat[i]:
                d[i] = math.hypot(obs_xy[m_obs[i], 0] - pxy[j, 0], obs_xy[m_obs[i], 1] - pxy[j, 1])
                outside[i] = not inside[j]
                break
    return d, outside


@njit(cache=True, nogil=True)
def _member(rows: np.ndarray, of: np.ndarray) -> np.ndarray:
    out = np.zeros(len(rows), np.bool_)
    for i in range(len(rows)):
        for j in range(len(of)):
            if rows[i] == of[j]:
                out[i] = True
                break
    return out


_MIN_PAIRS = np.int64(MIN_PAIRS)
"""``photometry.MIN_PAIRS`` as an int64, as the Python path passes it (a module's int in a compiled
call is typed ``Literal[int]``: ``too_bright_kernel`` compiled a second time)."""


@njit(cache=True, nogil=True)
def answer_kernel(obs_xy, flux, has_flux, m_obs, m_cat, r, star_vec, star_mag, cell, n_side, keys, starts, stars,
                  columns, chord, mount, cam, dist, radius_px, sigma_px, hidden_sep, hidden_limits):
    """``(obs rows, catalogue rows, changed)`` of an answer after the checks of
    :func:`service.core.finish.solution` (blends named, implausible pairs dropped; ``cam[0]``
    is the focal length, px, and ``hidden_sep, hidden_limits`` :func:`~service.core.hidden.hidden_neighbours`)."""
    r_cam = mount @ r
    # the field's stars, and those just past the image's edge, which crowd a blob as one inside
    # would but are never named (match.EDGE_CROWDS)
    near_rows, near_pxy, near_in = field_stars_near(r_cam, chord, cell, n_side, keys, starts, stars, columns,
                                                    star_vec, cam, dist, CROWD * radius_px if EDGE_CROWDS else 0.0)
    rows = near_rows[near_in]
    moved = False
    # blends: the free observed stars against the unpaired catalogue stars of the field
    taken = np.zeros(len(obs_xy), np.bool_)
    for i in m_obs:
        taken[i] = True
    n_free = len(obs_xy) - np.count_nonzero(taken)
    if n_free > 0:
        unpaired = ~_member(near_rows, m_cat)
        if unpaired.any():
            mine = np.flatnonzero(~taken)
            cand = near_rows[unpaired]
            mag = star_mag[cand]
            faintest = star_mag[m_cat].max()
            o, p, n = dominant_kernel(obs_xy, mine, near_pxy[unpaired], mag,
                                      (mag <= faintest + 0.5) & near_in[unpaired], radius_px, CROWD, MIN_DELTA_MAG)
            if n > 0:
                m_obs = np.concatenate((m_obs, o[:n]))
                m_cat = np.concatenate((m_cat, cand[p[:n]]))
                moved = True
    # plausibility: too bright for its catalogue star, fainter than the frame's completeness, or
    # too far from it for the frame's noise
    pair_mag = star_mag[m_cat]
    d_near, outside = pair_offsets(obs_xy, m_obs, m_cat, near_rows, near_pxy, near_in)
    d = np.where(outside, np.nan, d_near)  # the pairs inside, as the checks below take them
    bad = distant_kernel(d_near, pair_mag, sigma_px, outside)
    bad |= hidden_kernel(m_cat, d, pair_mag, hidden_sep, hidden_limits, 1.0 / cam[0], CROWD * radius_px)  # left out
    if has_flux:
        bad |= too_bright_kernel(flux[m_obs], pair_mag, THRESHOLD_MAG, _MIN_PAIRS)
    field = np.unique(rows)
    field_paired = _member(field, m_cat)
    if len(pair_mag) >= 3 and pair_mag.max() > median(pair_mag) + FAINT_GATE_MAG:
        bad |= completeness_kernel(pair_mag, star_mag[field], field_paired)
    if has_flux:  # then the faintest pair against the pairs the others keep
        bad |= faintest_inverted_among_kernel(flux[m_obs], pair_mag, bad)
    bad |= faintest_past_missed_kernel(pair_mag, star_mag[field], field_paired, bad)
    if bad.any():
        m_obs, m_cat = m_obs[~bad], m_cat[~bad]
        moved = True
    return m_obs, m_cat, moved


REPAIR_REFITS = np.int64(4)
"""Refits of :func:`repair_kernel`'s pairing (``match._refine``'s growth loop, as the verifier's
check runs it)."""


@njit(cache=True, nogil=True)
def repair_kernel(obs_vec, obs_xy, flux, has_flux, m_obs, m_cat, r, star_vec, star_mag, cell, n_side, keys, starts,
                  stars, columns, chord, mounts, cams, dist, cam_rows, row_off, radius_px, answer_radius, sigma_px,
                  hidden_sep, hidden_limits):
    """``(obs rows, catalogue rows, grew)``: the pairs ``m_obs`` -> ``m_cat`` of an answer whose
    final fit ``r`` (ICRS -> body; one camera) puts a pair past the match radius, paired again
    from that fit (``match._refine``) and checked again (:func:`answer_kernel`); the new pairs
    where they are more than the old, else the old.

    The verifier's pairing grows with its refits and stops after ``match._refine``'s last one:
    a pairing still growing then ends with its last refit unpaired, and a wrong pair that pulled
    the earlier fits stays in it past the radius while the stars the pull moved away stay out.
    A seed 000 frame at 2 px (``python -m bench.bench_wrong --frames 100000 --seed 12``) was
    answered with 9 of its 14 stars and a false one 7 px (220") off its catalogue star under the
    final fit; paired again from that fit, the 14 real stars and no false one."""
    r_cam = mounts[0] @ r
    field, _ = field_stars(r_cam, chord, cell, n_side, keys, starts, stars, columns, star_vec, cams[0], dist[0])
    near_off = np.array([0, len(field)], np.int64)
    ok, g_obs, g_cat, _, g_r = _refine(obs_vec, obs_xy, star_vec, m_obs[:0], m_cat[:0], r, 1.0, field, near_off,
                                       mounts, cams, dist, cam_rows, row_off, radius_px, REPAIR_REFITS)
    if not ok or len(g_obs) <= len(m_obs):
        return m_obs, m_cat, False
    c_obs, c_cat, _ = answer_kernel(obs_xy, flux, has_flux, g_obs, g_cat, g_r, star_vec, star_mag, cell, n_side,
                                    keys, starts, stars, columns, chord, mounts[0], cams[0], dist[0], answer_radius,
                                    sigma_px, hidden_sep, hidden_limits)
    if len(c_obs) <= len(m_obs):
        return m_obs, m_cat, False
    return c_obs, c_cat, True
