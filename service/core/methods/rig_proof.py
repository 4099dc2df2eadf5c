"""Sparse rig frames: one triangle across the cameras, matched to one catalogue triple, proven
with every other star of the frame (``multifov``'s last resort; issue 16, seed 001's point).

A rig frame of 3-8 stars, e.g. (2, 2) or (1, 3) per camera, has too few stars in any one camera
for the master vote, and its few extra stars are too few for the verifier's binomial bound
(one extra star: ``P ~ n_trials * 3e-5``). But the stars of different cameras have known angles
(through the mounting), so a *base triangle* -- two stars ``i``, ``j`` of one camera and a third
``k`` of any camera -- is looked up as a pair ``(I, J)`` in the pair table (angle ``d_ij``) and
every catalogue star ``K`` whose angles to ``I`` and ``J`` match ``d_ik`` and ``d_jk`` (and whose
triangle has the same handedness): :func:`cross_triples`.

The proof generalises :func:`~service.core.sparse_proof.check_unique_triangle` to rigs and to
*free* stars (the frame's stars outside the base triangle, ``m_c`` of them in camera ``c``):

- **Consistent.** A catalogue triple is consistent with the frame when the attitude mapping it
  onto the base triangle explains every free star (a predicted star within the match radius
  ``r``), predicts no star inside any image (at least ``r`` from its edge) that nobody observed,
  and predicts at most ``m_c + 1`` stars anywhere in camera ``c``'s image.
- **Null hypothesis.** The frame is unrelated to the sky. Its base triangle then falls within
  ``delta`` (the match's largest side mismatch, measured) of a consistent catalogue triple with
  probability at most ``E = rho_c (2 delta)^3``, ``rho_c`` the density of consistent triples in
  side space. A free star, unrelated to the sky, lies anywhere in its image: it lands within
  ``r`` of one of the at most ``m_c + 1`` predicted stars with probability at most
  ``(m_c + 1) pi r^2 / area_c``. So a triple counts with weight at most
  ``H = prod_c ((m_c + 1) pi r^2 / area_c)^m_c``, and only if its field predicts no more stars
  than the frame could explain (``n_inside <= m_c`` and ``n_image <= m_c + 1`` per camera).
- **Density.** Every catalogue triple within half-width ``W`` of the observed sides (the match
  left out) is gathered (a random sample of ``SPARSE_MAX_SAMPLE`` when there are more, the
  thinning factor applied); each is fitted to the base triangle (Wahba, three stars) and its
  fields are projected into every camera; ``k`` of them satisfy the field condition. Then
  ``E = thin * k_up * H * (delta / W)^3``, ``k_up`` the Poisson upper bound on ``k`` at
  ``SPARSE_CONFIDENCE``.
- **Acceptance.** The consistent match is the only consistent triple of its base triangle, and
  ``n_looks * E <= max_false_prob`` with ``n_looks`` the number of base triangles the frame
  offers (all of them, not only those tried) times the number of skies and of slacks.
- **Slack.** A frame of 4 or more stars is also tested allowing one star unexplained (a false
  star: ``H`` sums over which free star it is) or one predicted star unseen (a missed detection:
  ``m_c + 2`` predicted stars, and one beyond ``m_c`` inside the images, in the box's test as in
  the match's). Each is a test of its own in ``n_looks``; a looser test is tried only when the
  stricter found no consistent triple.
- **Skies.** "Predicts no unseen star" needs a catalogue no deeper than the camera. The frame's
  limit is unknown, so every test is made against the database's stars to its limit and to
  ``LIMIT_STEPS`` magnitudes brighter (:func:`sky_limits`); each is a test of its own, and all
  count in ``n_looks``. (GF-7's frames to 5.5 Mv on seed 001's 6.5-Mv database: 94.1% -> 99.7%
  of 4+ star frames.)
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
from scipy.special import gammaincinv

from ..attitude import wahba_svd
from ..geometry import angle_between, pairwise_angles
from ..match import _camera_rows
from ..navdb.reader import NavDatabase
from ..skygrid import SkyGrid, build_sky_grid
from ..sparse_others import K_UP_EMPTY, TESTS
from ..sparse_proof import SPARSE_CONFIDENCE, SPARSE_MAX_SAMPLE, field_check_kernel
from ..star_index import FIELD_CELL_DEG, star_vec64
from ..types import FloatArray, IntArray
from ..verify import Verified, Verifier
from ._pairs import same_handedness
from ._rig_third import third_star_candidates

RIG_SPARSE_MAX_STARS = 8
"""Frames of at most this many stars (all cameras) are offered to the proof."""
MAX_BASES = 8
"""Base triangles tried per frame (the most informative first); ``n_looks`` counts all."""
MAX_MATCHES = 64
"""A base triangle with more catalogue triples than this within tolerance is skipped."""
BOX_START, BOX_MAX, BOX_TARGET = 12.0, 160.0, 2000
"""Density box: first and largest half-width ``W`` in pattern tolerances, and the number of
triples aimed at (as ``triangle``'s); ``W`` stays below a quarter of the base pair's side."""
SMALL_BOX_ROOM = 8.0
"""The first box is as narrow as an empty count proving the match this many times over allows."""
LIMIT_STEPS = (0.0, 0.5, 1.0, 1.5)
"""Magnitude limits tried, below the database's faintest star (every one counts in ``n_looks``)."""
THIRD_STAR_REACH_DEG = 1.0
"""The reach (deg) the sky grid a base pair's third stars are gathered from is chosen for (its
smallest cells: a pair's region spans arcseconds to arcminutes)."""
CHUNK = 512
"""Stars per block of the float32 product that finds each first star's ring of third stars."""


@dataclass(frozen=True)
class PairLookup:
    """The pair table as the proof reads it: ``pairs`` ``(P, 2)`` star rows sorted by ``angles``
    ``(P,)`` (radians), and the largest angle it holds (radians)."""

    pairs: np.ndarray
    angles: np.ndarray
    max_angle: float

    def within(self, lo: float, hi: float) -> IntArray:
        """Directed catalogue pairs ``(I, J)`` ``(M, 2)`` whose angle lies in ``[lo, hi]`` rad."""
        s, e = np.searchsorted(self.angles, lo, "left"), np.searchsorted(self.angles, hi, "right")
        p = np.asarray(self.pairs[s:e], np.int64)
        return np.concatenate([p, p[:, ::-1]])


def cross_triples(lookup: PairLookup, vec: FloatArray, v3: FloatArray, tol: tuple[float, float, float],
                  index: IntArray | None = None, grid: SkyGrid | None = None) -> IntArray:
    """Catalogue triples ``(I, J, K)`` ``(K, 3)`` matching the observed body-frame triangle ``v3``
    ``(3, 3)`` (rows ``i, j, k``; ``i``, ``j`` in one camera): ``|ij|`` within ``tol[0]`` (pair
    table), ``|ik|`` within ``tol[1]`` and ``|jk|`` within ``tol[2]`` (every catalogue star
    tested), same handedness. ``vec`` the catalogue's unit vectors; angles in radians. With
    ``grid`` (a :class:`~..skygrid.SkyGrid` over ``vec``), each pair's third stars are gathered
    where they must lie (:func:`~._rig_third.third_star_candidates`); without it, or where a
    pair's region cannot be bounded, from each first star's ring: the same triples either way."""
    d = pairwise_angles(v3)
    ij = lookup.within(d[0, 1] - tol[0], d[0, 1] + tol[0])
    if index is not None:  # the pairs of a sky's stars, as its rows
        ij = index[ij]
        ij = ij[np.all(ij >= 0, axis=1)]
    if len(ij) == 0:
        return np.zeros((0, 3), np.int64)
    lo, hi = math.cos(d[0, 2] + tol[1]) - 1e-6, math.cos(max(d[0, 2] - tol[1], 0.0)) + 1e-6
    lo_j, hi_j = math.cos(d[1, 2] + tol[2]) - 1e-6, math.cos(max(d[1, 2] - tol[2], 0.0)) + 1e-6
    got = None
    side = float(np.sign(np.linalg.det(v3)))
    if grid is not None and side != 0.0:
        ok, pair, ks = third_star_candidates(np.ascontiguousarray(ij, dtype=np.int64), vec, lo, hi, lo_j,
                                             hi_j, side, grid.cell, grid.n_side, grid.keys, grid.starts,
                                             grid.stars, grid.columns)
        got = (pair, ks) if ok else None
    if got is None:
        # every star K at |ik| from each distinct I (a float32 product with the catalogue, in
        # blocks of I), then each pair (I, J) reads its I's ring and keeps the K at |jk| from J
        firsts, which = np.unique(ij[:, 0], return_inverse=True)
        start, ring_k = _rings(np.asarray(vec, np.float32), firsts, lo, hi)
        counts = start[which + 1] - start[which]
        pair = np.repeat(np.arange(len(ij)), counts)
        at = np.repeat(start[which] - np.cumsum(counts) + counts, counts) + np.arange(int(counts.sum()))
        ks = ring_k[at]
    else:
        pair, ks = got
    dj = np.einsum("ij,ij->i", vec[ij[pair, 1]], vec[ks])
    keep = (dj >= lo_j) & (dj <= hi_j)
    pair, ks = pair[keep], ks[keep]
    ok = (np.abs(angle_between(vec[ij[pair, 0]], vec[ks]) - d[0, 2]) <= tol[1]) & \
         (np.abs(angle_between(vec[ij[pair, 1]], vec[ks]) - d[1, 2]) <= tol[2])
    cat = np.column_stack([ij[pair[ok]], ks[ok]])
    cat = cat[(cat[:, 2] != cat[:, 0]) & (cat[:, 2] != cat[:, 1])]
    return cat[same_handedness(vec, v3, cat)] if len(cat) else cat


def _rings(vec32: np.ndarray, firsts: IntArray, lo: float, hi: float) -> tuple[IntArray, IntArray]:
    """The stars whose cosine to star ``firsts[u]`` lies in ``[lo, hi]``, as ``ring[start[u]:
    start[u + 1]]`` (``start``, ``ring``); a float32 product with the catalogue in blocks."""
    rows, ks = [], []
    for s in range(0, len(firsts), CHUNK):
        dots = vec32[firsts[s:s + CHUNK]] @ vec32.T
        r, k = np.nonzero((dots >= lo) & (dots <= hi))
        rows.append(r + s)
        ks.append(k)
    start = np.zeros(len(firsts) + 1, np.int64)
    start[1:] = np.cumsum(np.bincount(np.concatenate(rows), minlength=len(firsts)))
    return start, np.concatenate(ks)


def batch_wahba(obs3: FloatArray, stars: FloatArray, cands: IntArray) -> FloatArray:
    """ICRS -> body rotations ``(K, 3, 3)`` fitting catalogue triples ``cands`` ``(K, 3)`` onto
    the observed rows ``obs3`` ``(3, 3)`` (Wahba's problem by SVD, equal weights)."""
    b = np.einsum("ai,kaj->kij", obs3, stars[cands])  # sum_a o_a c_a^T
    u, _, vt = np.linalg.svd(b)
    sign = np.sign(np.linalg.det(u) * np.linalg.det(vt))
    u[:, :, 2] *= sign[:, None]
    return u @ vt


def field_counts(verifier: Verifier, rs: FloatArray, cands: IntArray, free: IntArray, sky: Sky
                 ) -> tuple[IntArray, IntArray, IntArray, IntArray]:
    """Per attitude ``rs[k]`` (ICRS -> body) with catalogue triple ``cands[k]``, per camera
    ``(K, C)``: predicted stars inside the image at least ``r`` from its edge (``inside``),
    anywhere in the image (``image``), and -- against the observed free stars ``free`` (rows) --
    those of ``inside`` that no free star is within ``r`` of (``unseen``) and the free stars
    explained (``explained``). Stars and ``cands`` are those of ``sky``; the triple's own stars
    are never counted."""
    obs = verifier.obs
    stars = sky.vec
    n_k, n_c = len(rs), len(obs.cameras)
    out = [np.zeros((n_k, n_c), np.int64) for _ in range(4)]
    if n_k == 0:
        return out[0], out[1], out[2], out[3]
    rs = np.ascontiguousarray(rs, dtype=np.float64)
    cands = np.ascontiguousarray(cands, dtype=np.int64)
    cams, dist = _camera_rows(tuple(obs.cameras))
    none = np.zeros((0, 2))
    r_px = float(verifier.match_radius_px)
    for c, cam in enumerate(obs.cameras):
        half = math.radians(cam.diagonal_fov_deg / 2 + 0.2)
        g = sky.grid(math.degrees(half))
        mount = np.ascontiguousarray(obs.mountings[c], dtype=np.float64)
        args = (mount, cams[c], dist[c], stars, 2 * math.sin(half / 2), g.cell, g.n_side, g.keys, g.starts,
                g.stars, g.columns, 96)
        mine = free[obs.camera[free] == c]
        out[0][:, c] = field_check_kernel(rs, cands, *args, none, r_px)[0]
        out[1][:, c] = field_check_kernel(rs, cands, *args, none, 0.0)[0]
        if len(mine):
            xy = np.ascontiguousarray(obs.xy[mine])
            out[2][:, c], out[3][:, c] = field_check_kernel(rs, cands, *args, xy, r_px)
        else:
            out[2][:, c] = out[0][:, c]
    return out[0], out[1], out[2], out[3]


@dataclass(frozen=True)
class Sky:
    """The catalogue stars to a magnitude limit: ``vec`` ``(n, 3)`` their unit vectors, ``index``
    ``(N,)`` each database row's row here (-1: fainter), ``grids`` the field grids by cell."""

    limit: float
    vec: np.ndarray
    index: np.ndarray
    grids: dict[float, SkyGrid]

    def grid(self, radius_deg: float) -> SkyGrid:
        """As :func:`~service.core.star_index.field_grid`: the cell suited to a radius (deg)."""
        cell = max([c for c in FIELD_CELL_DEG if c <= radius_deg / 2.5], default=FIELD_CELL_DEG[0])
        if cell not in self.grids:
            self.grids[cell] = build_sky_grid(self.vec, cell_rad=math.radians(cell))
        return self.grids[cell]


def sky_limits(db: NavDatabase) -> list[Sky]:
    """The skies the proof tries (kept per database): every star of the database, and its stars
    to ``LIMIT_STEPS`` magnitudes brighter than its limit (a camera that sees fewer stars than
    the database holds would otherwise leave predicted stars unseen and be refused)."""
    cache = db.__dict__.setdefault("_cache", {})
    if "rig_skies" not in cache:
        mag = np.asarray(db.stars.mag, np.float64)
        vec = star_vec64(db)
        skies = []
        for step in LIMIT_STEPS:
            keep = mag <= float(db.mag_limit) - step if step else np.ones(len(mag), bool)
            if keep.sum() < 3 or (skies and keep.sum() == len(skies[-1].vec)):
                continue
            index = np.full(len(mag), -1, np.int64)
            index[keep] = np.arange(int(keep.sum()))
            sky_vec = np.ascontiguousarray(vec[keep])
            sky_vec.flags.writeable = False  # as star_vec64's: the kernels' one signature for both
            skies.append(Sky(float(db.mag_limit) - step, sky_vec, index, {}))
        cache["rig_skies"] = skies
    return cache["rig_skies"]


class Slack(NamedTuple):
    """What a consistent match may leave: ``false`` observed stars unexplained (false stars),
    ``missed`` predicted stars inside an image unseen (missed detections)."""

    false: int = 0
    missed: int = 0


SLACKS = (Slack(0, 0), Slack(1, 0), Slack(0, 1))
"""Tests made of a frame of 4 or more stars, in turn (each counts in ``n_looks``)."""


def free_weight(verifier: Verifier, m: IntArray, slack: Slack = Slack()) -> float:
    """The largest chance that ``m_c`` stars scattered at random over camera ``c``'s image land
    within the match radius ``r`` (px) of one of at most ``m_c + 1 + missed`` predicted stars,
    every camera: ``H = prod_c ((m_c + 1 + missed) pi r^2 / area_c)^m_c``; with one star allowed
    to be false, all but one of them (the sum over which one)."""
    f = np.ones(len(m))
    for c, cam in enumerate(verifier.obs.cameras):
        near = math.pi * verifier.match_radius_px ** 2 / (cam.width * cam.height)  # of the image
        f[c] = min(1.0, (m[c] + 1 + slack.missed) * near)
    h = float(np.prod(f ** m))
    if slack.false:
        h = sum(float(m[c]) * h / f[c] for c in range(len(m)) if m[c])
    return min(h, 1.0)


def fits_field(inside: IntArray, image: IntArray, m: IntArray, missed: int = 0) -> np.ndarray:
    """Mask of attitudes whose predicted fields a frame of ``m`` ``(C,)`` free stars per camera
    could explain: at most ``m_c + 1 + missed`` stars in each image, and at most ``missed``
    inside all of them beyond ``m_c`` each."""
    excess = np.maximum(inside - m[None, :], 0).sum(axis=1)
    return (excess <= missed) & np.all(image <= m[None, :] + 1 + missed, axis=1)


def base_triangles(obs_vec: FloatArray, camera: IntArray, by_camera: tuple[IntArray, ...], tol: float,
                   max_angle: float) -> list[tuple[int, int, int]]:
    """Every base triangle ``(i, j, k)`` of the frame (rows): ``i < j`` in one camera, ``4 tol <=
    |ij| <= max_angle - tol`` (radians), ``k`` any other star; the widest pairs first (they bound
    the roll best and allow the widest density box), a third star in another camera first."""
    d = pairwise_angles(obs_vec)
    bases = []
    for rows in by_camera:
        for a, i in enumerate(rows):
            for j in rows[a + 1:]:
                if 4 * tol <= d[i, j] <= max_angle - tol:
                    bases += [(int(i), int(j), k) for k in range(len(obs_vec)) if k not in (i, j)]
    return sorted(bases, key=lambda b: (-round(float(d[b[0], b[1]]), 6), camera[b[2]] == camera[b[0]], b))


def prove_sparse_rig(verifier: Verifier, lookup: PairLookup, tol: float, mount_tol: float,
                     expired: Callable[[], bool] = lambda: False) -> Verified | None:
    """Prove a frame of 3-``RIG_SPARSE_MAX_STARS`` stars by a base triangle matched to one
    consistent catalogue triple (see the module's docstring), against the catalogue to each of
    :func:`sky_limits` in turn; ``tol`` the pattern tolerance and ``mount_tol`` the mounting's,
    radians. Refuses (None) when two base triangles or two triples of one base name different
    skies. ``n_looks`` = base triangles x magnitude limits (the whole database only for 3 stars:
    their bound is within a factor of a few of the threshold, and four limits would cost most of
    them)."""
    obs = verifier.obs
    if not 3 <= len(obs) <= RIG_SPARSE_MAX_STARS:
        return None
    stars = star_vec64(verifier.db)
    bases = base_triangles(obs.vec, obs.camera, obs.by_camera, tol, lookup.max_angle)
    limits = sky_limits(verifier.db)
    skies = limits[:1 if len(obs) == 3 else None]  # no room for 4 limits in 3 stars
    all_stars = limits[0]  # every star of the database, in its rows
    slacks = SLACKS if len(obs) >= 4 else SLACKS[:1]
    n_looks = len(bases) * len(skies) * len(slacks)
    named: dict[int, int] = {}
    for i, j, k in bases[:MAX_BASES]:
        t_k = tol + (mount_tol if obs.camera[k] != obs.camera[i] else 0.0)
        tri = np.array([i, j, k])
        every = cross_triples(lookup, all_stars.vec, obs.vec[tri], (tol, t_k, t_k),  # each sky holds a subset
                              grid=all_stars.grid(THIRD_STAR_REACH_DEG))
        if len(every) == 0 or len(every) > MAX_MATCHES:
            continue
        for sky in skies:
            if expired():
                return None
            fit = _fit_field(verifier, sky, tri, every)
            if fit is None:
                continue
            picks = [_pick(fit, slack) for slack in slacks]
            if picks[0] == "ambiguous":
                return None  # two skies explain the frame (a looser test's two are only skipped)
            usable = [(sl, p) for sl, p in zip(slacks, picks, strict=True) if isinstance(p, int)]
            if not usable:
                continue
            slack, row = usable[0]
            r, cat, m = fit[0][row], fit[1][row], fit[2]
            m_obs, m_cat, _ = verifier._match_all(r)
            if len(m_obs) < len(obs) - slack.false or not np.isin(tri, m_obs).all():
                continue
            pairs = dict(zip(m_obs.tolist(), m_cat.tolist(), strict=True))
            if not _agree(named, pairs):
                return None
            named.update(pairs)
            prob = _bound(verifier, lookup, sky, obs.vec[tri], cat, m, tol, slack, n_looks) * n_looks
            if prob <= verifier.max_false_prob:
                return Verified(m_obs, m_cat, wahba_svd(obs.vec[m_obs], stars[m_cat]), prob, n_looks)
            break  # a shallower sky or a looser test proves these stars no better
    return None


def _agree(a: dict[int, int], b: dict[int, int]) -> bool:
    """True if the pairings ``a`` and ``b`` (observed row -> catalogue row) never give one star
    two partners."""
    if any(a.get(o, c) != c for o, c in b.items()):
        return False
    back = {c: o for o, c in a.items()}
    return all(back.get(c, o) == o for o, c in b.items())


FieldFit = tuple[FloatArray, IntArray, IntArray, np.ndarray, IntArray, IntArray, IntArray, IntArray]


def _fit_field(verifier: Verifier, sky: Sky, tri: IntArray, every: IntArray) -> FieldFit | None:
    """The catalogue triples ``every`` (database rows) of the base triangle ``tri`` whose stars
    ``sky`` holds, as its rows, fitted and projected: ``(rs, cat, m, near, inside, image, unseen,
    explained)`` (see :func:`field_counts`; ``m`` the free stars per camera, ``near`` whether
    the triple's own stars fit within the match radius). None if ``sky`` holds none of them."""
    obs = verifier.obs
    cat = sky.index[every]
    cat = cat[np.all(cat >= 0, axis=1)]
    if len(cat) == 0:
        return None
    free = np.setdiff1d(np.arange(len(obs)), tri)
    m = np.bincount(obs.camera[free], minlength=len(obs.cameras))
    rs = batch_wahba(obs.vec[tri], sky.vec, cat)
    pred = np.einsum("kij,kaj->kai", rs, sky.vec[cat])  # the triple's stars in the body frame
    near = np.linalg.norm(pred - obs.vec[tri][None], axis=2) <= verifier.match_radius_px * obs.pixel_scale_rad
    return (rs, cat, m, near.all(axis=1), *field_counts(verifier, rs, cat, free, sky))


def _pick(fit: FieldFit, slack: Slack) -> int | str | None:
    """The row of the one triple of ``fit`` consistent with the frame under ``slack``; None if
    there is none, ``"ambiguous"`` if there are two."""
    _, _, m, near, inside, image, unseen, explained = fit
    ok = near & fits_field(inside, image, m, slack.missed) & (unseen.sum(axis=1) <= slack.missed) & \
        (explained.sum(axis=1) >= int(m.sum()) - slack.false)
    if ok.sum() > 1:
        return "ambiguous"
    return int(np.flatnonzero(ok)[0]) if ok.any() else None


def _bound(verifier: Verifier, lookup: PairLookup, sky: Sky, v3: FloatArray, match: IntArray,
           m: IntArray, tol: float, slack: Slack = Slack(), n_looks: int = 1) -> float:
    """``E = thin * k_up * H * (delta / W)^3`` for the match ``match`` of the base triangle ``v3``
    with ``m`` free stars per camera, against ``sky`` (see the module's docstring).

    The free stars' weight ``H`` is known before any box is read, so the narrowest box in which an
    empty count would prove the match with ``SMALL_BOX_ROOM`` to spare (for ``n_looks`` looks)
    is read first, where it is narrower than the usual first box: a few triples instead of
    ~2,000. If it proves the match its ``E`` is returned with a factor of ``TESTS`` (two tests
    may be made, as in :mod:`~..sparse_others`); otherwise the box grows as before."""
    stars = sky.vec
    delta = float(np.max(np.abs(pairwise_angles(v3) - pairwise_angles(stars[match]))))
    w_max = float(angle_between(v3[0], v3[1])) / 4
    h = free_weight(verifier, m, slack)
    w = min(BOX_START * tol, w_max)
    room = SMALL_BOX_ROOM * TESTS * K_UP_EMPTY * h * max(n_looks, 1) / verifier.max_false_prob
    w_small = delta * room ** (1 / 3)
    if 0 < w_small < w:
        k_up = _box_bound(verifier, lookup, sky, v3, match, m, slack, w_small)
        e = TESTS * k_up * h * (delta / w_small) ** 3
        if e * n_looks <= verifier.max_false_prob:
            return e
    box = cross_triples(lookup, stars, v3, (w, w, w), sky.index, sky.grid(THIRD_STAR_REACH_DEG))
    if len(box) < BOX_TARGET / 2 and w < w_max:
        w = min(w * (BOX_TARGET / max(len(box), 8)) ** (1 / 3), w_max, BOX_MAX * tol)
        box = None
    return _box_bound(verifier, lookup, sky, v3, match, m, slack, w, box) * h * (delta / w) ** 3


def _box_bound(verifier: Verifier, lookup: PairLookup, sky: Sky, v3: FloatArray, match: IntArray,
               m: IntArray, slack: Slack, w: float, box: IntArray | None = None) -> float:
    """``thin * k_up``: the Poisson upper bound on the triples within half-width ``w`` (rad) of the
    base triangle ``v3``'s sides (the match left out; ``box`` those triples if already read) whose
    fields a frame of ``m`` free stars per camera could explain, with the thinning factor of a
    sampled box."""
    stars = sky.vec
    if box is None:
        box = cross_triples(lookup, stars, v3, (w, w, w), sky.index, sky.grid(THIRD_STAR_REACH_DEG))
    box = box[~np.all(box == match, axis=1)]  # the background around the match, without it
    thin = 1.0
    if len(box) > SPARSE_MAX_SAMPLE:  # a random thinning of a Poisson count is Poisson
        thin = len(box) / SPARSE_MAX_SAMPLE
        box = box[np.random.default_rng(0).choice(len(box), SPARSE_MAX_SAMPLE, replace=False)]
    k = 0
    if len(box):
        rs = batch_wahba(v3, stars, box)
        inside, image, _, _ = field_counts(verifier, rs, box, np.zeros(0, np.int64), sky)
        k = int(np.count_nonzero(fits_field(inside, image, m, slack.missed)))
    return thin * float(gammaincinv(k + 1, SPARSE_CONFIDENCE))


__all__ = ["RIG_SPARSE_MAX_STARS", "PairLookup", "Sky", "base_triangles", "cross_triples", "prove_sparse_rig",
           "sky_limits"]
