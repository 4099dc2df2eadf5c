"""Pairing observed stars with the catalogue under an attitude, as compiled kernels.

The verifier's inner loop: project the catalogue stars near each camera's boresight through
the camera model (pinhole + Brown-Conrady), pair them with the observed stars unambiguously,
refit the attitude to the pairs (Wahba, SVD) and pair again while the pairs grow. One kernel
call does what took ~10 numpy calls per camera per iteration.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numba import njit

from .attitude import wahba_kernel
from .types import FloatArray, IntArray


@dataclass(frozen=True)
class RigArrays:
    """Cameras of one frame as plain arrays for the kernels.

    Attributes
    ----------
    mounts : (C, 3, 3) float64
        Body -> camera rotations.
    cams : (C, 5) float64
        ``f_px, cx, cy, width, height`` per camera.
    dist : (C, 5) float64
        Brown-Conrady ``k1, k2, p1, p2, k3`` (zeros: none).
    rows : (N,) int64
        Observed rows grouped by camera; camera ``c`` owns ``rows[row_off[c]:row_off[c + 1]]``.
    row_off : (C + 1,) int64
    """

    mounts: np.ndarray
    cams: np.ndarray
    dist: np.ndarray
    rows: np.ndarray
    row_off: np.ndarray


_CAMERA_ROWS: dict[tuple[Any, ...], tuple[np.ndarray, np.ndarray]] = {}


def _camera_rows(cameras: tuple[Any, ...]) -> tuple[np.ndarray, np.ndarray]:
    """``(cams, dist)`` of :class:`RigArrays` for these cameras, kept per camera set (every
    frame of a camera asks the same; the kernels only read them)."""
    got = _CAMERA_ROWS.get(cameras)
    if got is None:
        if len(cameras) == 1:  # solve()'s camera, seen for the first time: no nested lists
            c = cameras[0]
            cams = np.array((c.f_px, c.cx, c.cy, c.width, c.height), np.float64).reshape(1, 5)
        else:
            cams = np.array([[c.f_px, c.cx, c.cy, c.width, c.height] for c in cameras], dtype=np.float64)
        dist = np.zeros((len(cameras), 5))
        for i, c in enumerate(cameras):
            if c.distortion:
                dist[i, :len(c.distortion)] = c.distortion[:5]
        if len(_CAMERA_ROWS) >= 256:
            _CAMERA_ROWS.clear()
        got = _CAMERA_ROWS[cameras] = (cams, dist)
    return got


IDENTITY_MOUNTING = np.eye(3)
"""The identity mounting :func:`service.core.pipeline.solve` passes for one camera (by identity:
its packed copy below is made once; the kernels only read it)."""
_IDENTITY_MOUNT = IDENTITY_MOUNTING.reshape(1, 3, 3).copy()


FRAME_ROWS_KEPT = 4096
"""Frame sizes whose :func:`frame_rows` are kept (a frame of more stars makes its own)."""
_FRAME_ROWS: dict[int, tuple[np.ndarray, np.ndarray, np.ndarray]] = {}


def frame_rows(n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(zeros(n), arange(n), [0, n])`` int64 for a one-camera frame of ``n`` stars: its
    camera column, its rows and their offsets, kept per ``n`` (every frame of that size asks
    the same; nothing writes to them, and they stay writable: a read-only array would be
    another type for the compiled kernels)."""
    got = _FRAME_ROWS.get(n)
    if got is None:
        got = (np.zeros(n, np.int64), np.arange(n, dtype=np.int64), np.array([0, n], np.int64))
        if n <= FRAME_ROWS_KEPT:
            _FRAME_ROWS[n] = got
    return got


_ONE_CAMERA_ARRAYS: dict[tuple[Any, int], RigArrays] = {}


def rig_arrays(cameras: Sequence[Any], mountings: Sequence[np.ndarray], by_camera: Sequence[np.ndarray]) -> RigArrays:
    """Pack cameras (:class:`~service.core.camera.Camera`), their mountings and their observed
    rows for the kernels."""
    cameras = tuple(cameras)
    if len(by_camera) == 1:  # one camera, every frame: skip the general packing (~20 us)
        rows = np.asarray(by_camera[0], np.int64)
        m = mountings[0]
        n = len(rows)
        if m is IDENTITY_MOUNTING and rows is _FRAME_ROWS.get(n, (None, None))[1]:
            # solve()'s frame (identity mounting, rows 0..n-1): the same arrays every time (~1.3 us)
            key = (cameras, n)
            got = _ONE_CAMERA_ARRAYS.get(key)
            if got is None:
                cams, dist = _camera_rows(cameras)
                if len(_ONE_CAMERA_ARRAYS) >= 4096:
                    _ONE_CAMERA_ARRAYS.clear()
                got = _ONE_CAMERA_ARRAYS[key] = RigArrays(_IDENTITY_MOUNT, cams, dist, rows, frame_rows(n)[2])
            return got
        cams, dist = _camera_rows(cameras)
        mount = _IDENTITY_MOUNT if m is IDENTITY_MOUNTING else np.array(m, dtype=np.float64).reshape(1, 3, 3)
        return RigArrays(mount, cams, dist, rows, np.array([0, n], np.int64))
    cams, dist = _camera_rows(cameras)
    off = np.zeros(len(by_camera) + 1, np.int64)
    off[1:] = np.cumsum([len(r) for r in by_camera])
    rows = np.concatenate([np.asarray(r, np.int64) for r in by_camera]) if by_camera else np.zeros(0, np.int64)
    mounts = np.ascontiguousarray(np.stack([np.asarray(m, np.float64) for m in mountings]))
    return RigArrays(mounts, cams, dist, rows, off)


def match_rig(r_body: FloatArray, obs_xy: FloatArray, star_vec: FloatArray, near: IntArray, near_off: IntArray,
              rig: RigArrays, radius_px: float, *, crowd: float = 2.0) -> tuple[IntArray, IntArray, float]:
    """Pair observed stars (pixel positions ``obs_xy``) with the catalogue stars ``near``
    (rows of ``star_vec``; camera ``c``'s are ``near[near_off[c]:near_off[c + 1]]``) projected
    under the ICRS -> body rotation ``r_body``.

    A pair is kept only when unambiguous: within ``radius_px``, and no other candidate on
    either side within ``crowd`` times that (a false star beside a real one, a catalogue
    double, or a noisy star nearer its neighbour's prediction than its own proves nothing;
    ``crowd = 1`` keeps pairs that are alone within the radius itself). Returns
    ``(obs_rows, star_rows, p)`` with ``p`` the fraction of the image area within
    ``radius_px`` of a predicted star (the chance a random point matches).
    """
    return _match_rig(np.ascontiguousarray(r_body, dtype=np.float64), obs_xy, star_vec, near, near_off,
                      rig.mounts, rig.cams, rig.dist, rig.rows, rig.row_off, float(radius_px), float(crowd))


def refine(obs_vec: FloatArray, obs_xy: FloatArray, star_vec: FloatArray, hyp_obs: IntArray, hyp_cat: IntArray,
           r0: FloatArray, quick_tol: float, near: IntArray, near_off: IntArray, rig: RigArrays, radius_px: float,
           *, max_refits: int = 4) -> tuple[bool, IntArray, IntArray, float, FloatArray]:
    """From a hypothesis (observed rows ``hyp_obs`` are catalogue rows ``hyp_cat``, attitude
    ``r0`` fitted to them) to all the pairs it implies.

    Refused at once (``ok`` False) when a hypothesis star lies farther than ``quick_tol``
    (unit-vector distance, ~radians) from its prediction, or when fewer pairs than
    ``max(len(hyp_obs), 3)`` are found. Otherwise the attitude is refitted (Wahba, SVD) to
    every pair and the pairing redone while the pairs grow (at most ``max_refits`` times; not once
    every observed star is paired).
    Returns ``(ok, obs_rows, star_rows, p, r)`` (see :func:`match_rig`), ``r`` fitted to the
    pairs returned.
    """
    # the hypothesis as writable copies (a few rows): a read-only view (multifov's) would be a
    # second compiled signature of the whole kernel
    return _refine(obs_vec, obs_xy, star_vec, np.array(hyp_obs, dtype=np.int64), np.array(hyp_cat, dtype=np.int64),
                   np.ascontiguousarray(r0, dtype=np.float64),
                   float(quick_tol), near, near_off, rig.mounts, rig.cams, rig.dist, rig.rows, rig.row_off,
                   float(radius_px), int(max_refits))



MAX_BUCKETS = 2048
"""Most x buckets the pairing sorts a camera's predictions into."""
EDGE_CROWDS = True
"""A catalogue star predicted outside the image, within the crowding reach of its edge, crowds
the observed stars near it as one inside would (it is not paired itself): centroid noise and the
attitude's own error put a star's blob on either side of the edge. Without it, a blob whose star
lay a fraction of a pixel outside was named after a neighbour inside, 3-4 px away (seed 003 and
004 at 2 px, ``python -m bench.bench_wrong --frames 100000 --seed 4`` and ``--seed 9``). The
close-double pairing of a proven answer (:func:`service.core.answer.answer_kernel`,
:func:`service.core.finish.checked_pairs`) follows the same rule: the blob of epsilon-1 and -2
Lyrae, the brighter predicted 0.25 px outside, was named after the fainter (``--seed 13``)."""


@njit(cache=True, nogil=True)
def _project_and_pair(cam_vec: np.ndarray, f: float, cx: float, cy: float, w: int, h: int, dist: np.ndarray,
                      obs_xy: np.ndarray, radius: float, crowd: float) -> tuple[np.ndarray, np.ndarray, int]:
    n_pred = len(cam_vec)
    pxy = np.empty((n_pred, 2))
    keep = np.empty(n_pred, np.int64)
    inside = np.empty(n_pred, np.bool_)
    n_in = 0  # predictions inside the image
    n_near = 0  # and within the crowding reach outside it (EDGE_CROWDS)
    margin = crowd * radius if EDGE_CROWDS else 0.0
    k1, k2, p1, p2, k3 = dist[0], dist[1], dist[2], dist[3], dist[4]
    for j in range(n_pred):
        z = cam_vec[j, 2]
        if z <= 1e-9:
            continue
        xn = cam_vec[j, 0] / z
        yn = cam_vec[j, 1] / z
        r2 = xn * xn + yn * yn
        radial = 1.0 + k1 * r2 + k2 * r2 * r2 + k3 * r2 * r2 * r2
        xd = xn * radial + 2 * p1 * xn * yn + p2 * (r2 + 2 * xn * xn)
        yd = yn * radial + p1 * (r2 + 2 * yn * yn) + 2 * p2 * xn * yn
        x = f * xd + cx
        y = f * yd + cy
        if x < -0.5 - margin or x > w - 0.5 + margin or y < -0.5 - margin or y > h - 0.5 + margin:
            continue
        pxy[n_near, 0] = x
        pxy[n_near, 1] = y
        keep[n_near] = j
        inside[n_near] = not (x < -0.5 or x > w - 0.5 or y < -0.5 or y > h - 0.5)
        n_in += inside[n_near]
        n_near += 1
    n_obs = len(obs_xy)
    rad2 = radius * radius
    reach = crowd * radius
    crowd2 = reach * reach
    # the predictions bucketed by x (counting sort, buckets at least `reach` wide): each observed
    # star looks at the few predictions of the buckets its reach spans, not at all of them
    width = max(reach, (w + 1.0) / MAX_BUCKETS)
    n_b = int((w + 1.0) / width) + 1
    start = np.zeros(n_b + 1, np.int64)
    bucket = np.empty(n_near, np.int64)
    for j in range(n_near):
        b = min(max(int((pxy[j, 0] + 0.5) / width), 0), n_b - 1)
        bucket[j] = b
        start[b + 1] += 1
    for b in range(n_b):
        start[b + 1] += start[b]
    fill = start[:n_b].copy()
    by_x = np.empty(n_near, np.int64)
    for j in range(n_near):
        by_x[fill[bucket[j]]] = j
        fill[bucket[j]] += 1
    row_cnt = np.zeros(n_obs, np.int64)
    col_cnt = np.zeros(n_near, np.int64)
    row_last = np.full(n_obs, -1, np.int64)
    for i in range(n_obs):
        x0 = obs_xy[i, 0] + 0.5
        b0 = max(int(math.floor((x0 - reach) / width)), 0)
        b1 = min(int(math.floor((x0 + reach) / width)), n_b - 1)
        for b in range(b0, b1 + 1):
            for k in range(start[b], start[b + 1]):
                j = by_x[k]
                dx = obs_xy[i, 0] - pxy[j, 0]
                dy = obs_xy[i, 1] - pxy[j, 1]
                if dx * dx + dy * dy <= crowd2:
                    row_cnt[i] += 1
                    col_cnt[j] += 1
                    row_last[i] = j
    out_obs = np.empty(n_obs, np.int64)
    out_pred = np.empty(n_obs, np.int64)
    n_out = 0
    for i in range(n_obs):
        j = row_last[i]
        if row_cnt[i] != 1 or col_cnt[j] != 1 or not inside[j]:
            continue
        dx = obs_xy[i, 0] - pxy[j, 0]
        dy = obs_xy[i, 1] - pxy[j, 1]
        if dx * dx + dy * dy <= rad2:
            out_obs[n_out] = i
            out_pred[n_out] = keep[j]
            n_out += 1
    return out_obs[:n_out].copy(), out_pred[:n_out].copy(), n_in


@njit(cache=True, nogil=True)
def binomial_tail(n: int, k: int, p: float) -> float:
    """``P[Binomial(n, p) >= k]`` (= the regularised incomplete beta ``I_p(k, n - k + 1)``)."""
    if k <= 0:
        return 1.0
    if k > n or p <= 0.0:
        return 0.0
    if p >= 1.0:
        return 1.0
    lp, lq = math.log(p), math.log1p(-p)
    base = math.lgamma(n + 1.0)
    total = 0.0
    for j in range(k, n + 1):
        total += math.exp(base - math.lgamma(j + 1.0) - math.lgamma(n - j + 1.0) + j * lp + (n - j) * lq)
    return min(total, 1.0)


@njit(cache=True, nogil=True)
def least_extras(n_free: int, pair_p: float, trials: int, max_false_prob: float, min_matches: int) -> int:
    """The fewest extra pairs (stars beyond a hypothesis, of ``n_free`` observed ones) with which
    a check after ``trials`` hypotheses could still pass the coincidence bound; ``n_free + 1``
    if none could. A check's answer holds ``m >= max(min_matches, k)`` pairs, each a prediction
    inside the image, so its ``p`` is at least ``m * pair_p`` (``pair_p``: one match disc's
    share of the image area) and its bound at least ``P[Binomial(n_free, p) >= k] * trials``
    (:meth:`~service.core.verify.Verifier.check`, :func:`verify_pairs`)."""
    t = max(trials, 1)
    for k in range(1, n_free + 1):
        if binomial_tail(n_free, k, min(1.0, max(min_matches, k) * pair_p)) * t <= max_false_prob:
            return k
    return n_free + 1


MIN_MATCHES = np.int64(4)
"""The verifier's ``min_matches`` (``Verifier.min_matches``) as the compiled searches pass it to
:func:`needed_hits` and ``screen.could_pass_bound``: an int64, as the Python path passes it (a
literal ``4`` in a compiled call is typed ``Literal[int]``, and the callee compiled again)."""

NEED_MAX_UNSCREENED = 2
""":func:`needed_hits` asks its hits only of frames with at most this many stars beyond those the
screen looks at: on a bigger frame the stars it skips could supply the extra pairs, and the
bound's sum (~1.5 us on 27 free stars) would be paid on every screened candidate. A bigger
frame's candidate that passed the screen is asked instead, just before its check, whether all
its stars could supply them (:func:`~service.core.screen.could_pass_bound`, since session 28)."""


@njit(cache=True, nogil=True)
def needed_hits(n_obs: int, n_hyp: int, n_screened: int, radius_px: float, area_px: float, trials: int,
                max_false_prob: float, min_matches: int) -> int:
    """The screen hits a hypothesis of ``n_hyp`` stars needs before it is checked: the extra pairs
    a check after ``trials`` hypotheses would need to pass the bound (:func:`least_extras`, one
    match disc of ``radius_px`` in ``area_px`` of image), less the frame's stars past the
    ``n_screened`` the screen looked at; 0 (no demand) on a frame of more than
    :data:`NEED_MAX_UNSCREENED` such stars or none beyond the hypothesis. Shared by the
    verifier's loop, ``maxangle``'s compiled search and ``quad``'s kernel (see
    ``verify.NEED_SCREEN_FACTOR`` for the wide screen that must agree)."""
    if n_obs <= n_hyp or n_obs > n_screened + NEED_MAX_UNSCREENED:
        return 0
    pair_p = math.pi * radius_px * radius_px / max(area_px, 1.0)
    return least_extras(n_obs - n_hyp, pair_p, trials, max_false_prob, min_matches) - (n_obs - n_screened)


CROWD = 2.0
"""No other candidate within this many match radii, on either side, for a pair to count."""


@njit(cache=True, nogil=True)
def _wahba_pairs(obs_vec: np.ndarray, star_vec: np.ndarray, o_idx: np.ndarray, c_idx: np.ndarray) -> np.ndarray:
    """Rotation ICRS -> body best mapping ``star_vec[c_idx]`` onto ``obs_vec[o_idx]``."""
    return wahba_kernel(obs_vec[o_idx], star_vec[c_idx], np.ones(len(o_idx)))


@njit(cache=True, nogil=True)
def _match_rig(r_body: np.ndarray, obs_xy: np.ndarray, star_vec: np.ndarray, near: np.ndarray,
               near_off: np.ndarray, mounts: np.ndarray, cams: np.ndarray, dist: np.ndarray, rows: np.ndarray,
               row_off: np.ndarray, radius: float, crowd: float) -> tuple[np.ndarray, np.ndarray, float]:
    """Pairs (observed row, star row) in every camera under ``r_body``, and the fraction of
    the image area within ``radius`` of a predicted star."""
    n_total = len(rows)
    m_obs = np.empty(n_total, np.int64)
    m_cat = np.empty(n_total, np.int64)
    n_m = 0
    area = 0.0
    covered = 0.0
    for c in range(len(mounts)):
        r_cam = mounts[c] @ r_body
        lo, hi = near_off[c], near_off[c + 1]
        cam_vec = np.empty((hi - lo, 3))
        for j in range(lo, hi):
            v = star_vec[near[j]]
            for a in range(3):
                cam_vec[j - lo, a] = r_cam[a, 0] * v[0] + r_cam[a, 1] * v[1] + r_cam[a, 2] * v[2]
        cam_rows = rows[row_off[c]:row_off[c + 1]]
        po, pc, n_in = _project_and_pair(cam_vec, cams[c, 0], cams[c, 1], cams[c, 2], int(cams[c, 3]),
                                         int(cams[c, 4]), dist[c], obs_xy[cam_rows], radius, crowd)
        area += cams[c, 3] * cams[c, 4]
        covered += n_in * math.pi * radius * radius
        for k in range(len(po)):
            m_obs[n_m] = cam_rows[po[k]]
            m_cat[n_m] = near[lo + pc[k]]
            n_m += 1
    return m_obs[:n_m].copy(), m_cat[:n_m].copy(), covered / max(area, 1.0)


@njit(cache=True, nogil=True)
def _refine(obs_vec: np.ndarray, obs_xy: np.ndarray, star_vec: np.ndarray, hyp_obs: np.ndarray,
            hyp_cat: np.ndarray, r0: np.ndarray, quick_tol: float, near: np.ndarray, near_off: np.ndarray,
            mounts: np.ndarray, cams: np.ndarray, dist: np.ndarray, rows: np.ndarray, row_off: np.ndarray,
            radius: float, max_refits: int) -> tuple[bool, np.ndarray, np.ndarray, float, np.ndarray]:
    for i in range(len(hyp_obs)):  # quick reject: the hypothesis' own stars must fit
        v, o = star_vec[hyp_cat[i]], obs_vec[hyp_obs[i]]
        e2 = 0.0
        for a in range(3):
            d = r0[a, 0] * v[0] + r0[a, 1] * v[1] + r0[a, 2] * v[2] - o[a]
            e2 += d * d
        if e2 > quick_tol * quick_tol:
            return False, hyp_obs[:0].copy(), hyp_cat[:0].copy(), 1.0, r0
    m_obs, m_cat, p_single = _match_rig(r0, obs_xy, star_vec, near, near_off, mounts, cams, dist, rows, row_off,
                                        radius, CROWD)
    if len(m_obs) < max(len(hyp_obs), 3):
        return False, m_obs, m_cat, p_single, r0
    r = r0
    grew = True
    for _ in range(max_refits):
        r = _wahba_pairs(obs_vec, star_vec, m_obs, m_cat)
        if len(m_obs) >= len(rows):  # every observed star is paired: the pairing cannot grow
            grew = False
            break
        g_obs, g_cat, g_p = _match_rig(r, obs_xy, star_vec, near, near_off, mounts, cams, dist, rows, row_off,
                                       radius, CROWD)
        if len(g_obs) <= len(m_obs):
            grew = False
            break
        m_obs, m_cat, p_single = g_obs, g_cat, g_p
    if grew:
        r = _wahba_pairs(obs_vec, star_vec, m_obs, m_cat)
    return True, m_obs, m_cat, p_single, r
