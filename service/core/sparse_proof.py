"""Sparse fields: a uniquely matched triangle as its own proof.

For frames of 3-4 stars, which have no fourth star to confirm a triangle
(:func:`check_unique_triangle`, called by ``triangle``). It reads the
:class:`~service.core.verify.Verifier` (``obs``, ``db``, ``match_radius_px``, ``max_false_prob``,
``_match_all``). The field test of every candidate attitude (the match and up to
``SPARSE_MAX_SAMPLE`` catalogue triples of its density box) is one compiled call per camera
(:func:`field_check_kernel`): the vectorised version queried a k-d tree for the 96 nearest
stars of every attitude and compared ``K x 96`` predictions with every observed star (~5 ms
for 3,000 attitudes).
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np
from numba import njit
from scipy.special import gammaincinv

from .attitude import wahba_kernel, wahba_svd
from .camera import Camera, project_rows
from .geometry import pairwise_angles_kernel
from .match import _camera_rows
from .navdb.reader import NavDatabase
from .prefetch import prefetch
from .screen import frame_columns
from .skygrid import ball_cells, collect_within
from .skymask import may_hold_star
from .sparse_others import K_UP_EMPTY, SPARSE_CONFIDENCE, prove_with_others
from .star_index import field_grid, sky_grid, sky_mask, star_neighbours, star_vec64
from .types import Centroids, FloatArray, IntArray
from .verify import Verified, Verifier

SPARSE_MAX_SAMPLE = 3000
"""At most this many catalogue triples of the density box are projected (a random sample)."""


def check_unique_triangle(
    verifier: Verifier,
    obs_idx: IntArray,
    cat_idx: IntArray,
    *,
    density_box: Callable[[Callable[[float], bool]], tuple[IntArray, float] | None],
    n_looks: int,
    unique_within_rad: float | None = None,
    sample_box: Callable[[float], IntArray] | None = None,
    max_width_rad: float = math.inf,
) -> Verified | None:
    """Prove a frame too sparse for a fourth star by a triangle that matched one catalogue triple.

    Null hypothesis: the observed triangle is unrelated to the sky (false stars, a planet, a
    star missing from the database). Its chance to fall within ``delta`` (the largest of the
    three side mismatches, measured on this match) of some catalogue triangle that would
    produce this frame is at most the expected count of such triangles in the box
    ``|d_cat - d_obs| <= delta`` on all three sides: ``E = rho (2 delta)^3``. A catalogue
    triangle *would produce this frame* when the attitude mapping it onto the observed stars
    predicts no further catalogue star inside the image that nobody observed. The density
    ``rho`` is estimated from the database: ``density_box(worth)`` gives all catalogue triples
    (same vertex order and handedness) within a half-width W of the observed sides, and W
    (radians; called only once the match itself passes, as gathering the box costs
    milliseconds), or None where ``worth(W)`` says no box of that width could prove the match
    (the bound at ``k = 0`` already exceeds ``max_false_prob``: ``density_box`` asks before each
    gathering, and the box is projected only when the bound at its own width and thinning
    passes); with ``k`` of
    them (the match itself left out: given a point of a Poisson process, the others are still
    Poisson) consistent with the frame, ``E = k_up (delta / W)^3``, ``k_up`` the Poisson upper
    bound on ``k`` at ``SPARSE_CONFIDENCE``. Accepted when the match is unique (the caller's
    duty), its own field is consistent, and ``n_looks * E <= max_false_prob``, ``n_looks`` being
    the number of observed triangles the method could have tried.

    Where the match explains another observed star and the caller says the match was alone
    within ``unique_within_rad`` (rad) on all three sides, the shortcut
    :func:`~.sparse_others.prove_with_others` is tried first: that star's binomial tail in
    place of the box's count of triangles explaining it (``sample_box(W)``, the catalogue
    triples within ``W``; ``max_width_rad`` the widest it reads).

    Returns the proven match (``false_prob = n_looks * E``), or None.
    """
    obs = verifier.obs
    stars = star_vec64(verifier.db)
    obs_idx = np.asarray(obs_idx, dtype=np.int64)
    cat_idx = np.asarray(cat_idx, dtype=np.int64)
    if len(obs_idx) != 3 or len(set(cat_idx.tolist())) != 3:  # (np.unique: ~3 us, a set ~0.3)
        return None
    ok, r, delta = _triangle_fit(np.ascontiguousarray(obs.vec, dtype=np.float64), stars, obs_idx, cat_idx,
                                 verifier.match_radius_px * obs.pixel_scale_rad)
    if not ok:
        return None
    unseen, explained = _field_check(verifier, r[None], cat_idx[None], obs_idx)
    if unseen[0] > 0:
        return None
    looks = max(n_looks, 1)
    pairing = None
    if explained[0] > 0 and unique_within_rad is not None:
        pairing = verifier._match_all(r)  # kept for the full proof below
        found = prove_with_others(verifier, r, obs_idx, cat_idx, delta, looks, unique_within_rad, sample_box,
                                  max_width_rad, pairing)
        if found is not None:
            return found

    def worth(width: float, thin: float = 1.0) -> bool:
        """Could a box of half-width ``width`` (rad) prove the match? Its best case, k = 0."""
        return thin * K_UP_EMPTY * (delta / width) ** 3 * looks <= verifier.max_false_prob

    got = density_box(worth)
    if got is None:
        return None
    box_cands, box_halfwidth_rad = got
    box = np.asarray(box_cands, dtype=np.int64).reshape(-1, 3)
    box = _without_triple(np.ascontiguousarray(box), int(cat_idx[0]), int(cat_idx[1]), int(cat_idx[2]))
    thin = 1.0
    if len(box) > SPARSE_MAX_SAMPLE:  # a random thinning of a Poisson count is Poisson
        thin = len(box) / SPARSE_MAX_SAMPLE
        box = box[np.lexsort(box.T[::-1])]  # by (a, b, c): the sample does not depend on the join's order
        box = box[np.random.default_rng(0).choice(len(box), SPARSE_MAX_SAMPLE, replace=False)]
    if not worth(box_halfwidth_rad, thin):
        return None  # the box's projections could only raise the bound
    k = 0
    if len(box) and explained[0] > 0:
        # a box attitude counts only if it explains as many other stars as the match: a cheap
        # necessary test first (each other star looked up in the sky at a wider radius), the
        # field check on the few that pass (the same count: ~0.9 us an attitude went to
        # gathering its field)
        box = box[_could_explain(verifier, box, obs_idx) >= explained[0]]
    elif len(box):
        # a box attitude counts only if every catalogue star in its image is observed, so one
        # well inside it and away from every other observed star rules it out (_star_in_view)
        box = box[~_star_in_view(verifier, box, obs_idx)]
    if len(box):
        rs = _sparse_attitudes(obs.vec[obs_idx], star_vec64(verifier.db), box)
        box_unseen, box_explained = _field_check(verifier, rs, box, obs_idx)
        k = int(np.count_nonzero((box_unseen == 0) & (box_explained >= explained[0])))
    expected = thin * float(gammaincinv(k + 1, SPARSE_CONFIDENCE)) * (delta / box_halfwidth_rad) ** 3
    prob = min(1.0, expected * looks)
    if prob > verifier.max_false_prob:
        return None
    # the pairing last: it decides nothing the steps above read (~28 us, and it refused none of
    # seed 002's 1,104 unique triangles whose field held no unseen star, session 30)
    m_obs, m_cat, _ = verifier._match_all(r) if pairing is None else pairing
    if not set(obs_idx.tolist()) <= set(m_obs.tolist()):  # every star of the triangle paired
        return None
    return Verified(m_obs, m_cat, wahba_svd(obs.vec[m_obs], stars[m_cat]), prob, looks)


@njit(cache=True, nogil=True, inline="always")
def _triangle_rows(obs_vec: np.ndarray, star_vec: np.ndarray, obs_idx: np.ndarray,
                   cat_idx: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The observed rows ``obs_idx`` and catalogue rows ``cat_idx`` of a matched triangle, (3, 3) each."""
    o = np.empty((3, 3))
    c = np.empty((3, 3))
    for i in range(3):
        for a in range(3):
            o[i, a] = obs_vec[obs_idx[i], a]
            c[i, a] = star_vec[cat_idx[i], a]
    return o, c


@njit(cache=True, nogil=True)
def _triangle_fit(obs_vec: np.ndarray, star_vec: np.ndarray, obs_idx: np.ndarray, cat_idx: np.ndarray,
                  radius: float) -> tuple[bool, np.ndarray, float]:
    """The matched triangle's own test, one compiled call: the attitude of catalogue rows
    ``cat_idx`` onto observed rows ``obs_idx`` (Wahba, ICRS -> body), whether each of the three
    stars lies within ``radius`` (rad, chord) of its prediction, and ``delta``, the largest of
    the three side mismatches (rad). As :func:`~.attitude.wahba_svd`, ``np.linalg.norm`` and
    :func:`~.geometry.pairwise_angles` computed them (the numpy steps took ~35 us a triangle)."""
    o, c = _triangle_rows(obs_vec, star_vec, obs_idx, cat_idx)
    r = wahba_kernel(o, c, np.ones(3))
    ok = True
    for i in range(3):
        s = 0.0
        for a in range(3):
            d = c[i, 0] * r[a, 0] + c[i, 1] * r[a, 1] + c[i, 2] * r[a, 2] - o[i, a]
            s += d * d
        if math.sqrt(s) > radius:
            ok = False
    return ok, r, _mismatch(o, c)


@njit(cache=True, nogil=True, inline="always")
def _mismatch(o: np.ndarray, c: np.ndarray) -> float:
    """The largest of the three side mismatches (rad) of the triangles of rows ``o`` and ``c``
    (3, 3), each side as :func:`~.geometry.pairwise_angles` measures it."""
    d_obs = pairwise_angles_kernel(o)
    d_cat = pairwise_angles_kernel(c)
    delta = 0.0
    for i in range(3):
        for j in range(3):
            delta = max(delta, abs(d_obs[i, j] - d_cat[i, j]))
    return delta


@njit(cache=True, nogil=True)
def triangle_mismatch(obs_vec: np.ndarray, star_vec: np.ndarray, obs_idx: np.ndarray, cat_idx: np.ndarray) -> float:
    """The largest side mismatch (rad) of observed rows ``obs_idx`` against catalogue rows
    ``cat_idx`` (the ``delta`` of :func:`check_unique_triangle`; numpy's steps took ~8 us)."""
    o, c = _triangle_rows(obs_vec, star_vec, obs_idx, cat_idx)
    return _mismatch(o, c)


@njit(cache=True, nogil=True)
def _without_triple(box: np.ndarray, a: int, b: int, c: int) -> np.ndarray:
    """The rows of ``box`` (K, 3) other than ``(a, b, c)``, in order: the boolean mask of three
    column comparisons took ~55 us on a density box of ~1,900 triples, this ~5."""
    keep = 0
    out = np.empty_like(box)
    for i in range(len(box)):
        if box[i, 0] != a or box[i, 1] != b or box[i, 2] != c:
            out[keep, 0], out[keep, 1], out[keep, 2] = box[i, 0], box[i, 1], box[i, 2]
            keep += 1
    return out[:keep]


def _rows_but(groups: tuple[IntArray, ...], n: int, taken: IntArray) -> IntArray:
    """The rows of ``groups`` (sorted, distinct, each below ``n``) not in ``taken``, sorted:
    ``np.setdiff1d`` of their union, without its sorts (~15 us on a handful of rows)."""
    keep = np.zeros(n, dtype=bool)
    for g in groups:
        keep[g] = True
    keep[taken] = False
    return np.flatnonzero(keep)


def _sparse_attitudes(obs_vec: FloatArray, stars: FloatArray, cands: IntArray) -> FloatArray:
    """ICRS -> body rotations ``(K, 3, 3)`` mapping each catalogue triple onto the observed
    triangle (TRIAD on its first two stars; ``stars`` as :func:`~.star_index.star_vec64` gives
    them). One compiled call: the numpy steps took ~70 us however few the triples."""
    return _sparse_attitudes_kernel(np.ascontiguousarray(obs_vec, dtype=np.float64), stars,
                                    np.ascontiguousarray(cands, dtype=np.int64).reshape(-1, 3))


@njit(cache=True, nogil=True, inline="always")
def _triad_columns(a: np.ndarray, b: np.ndarray, out: np.ndarray) -> None:
    """Columns of ``out`` (3, 3): ``a`` normalised, ``a x b`` normalised, their cross product.
    (:func:`~.screen.frame_columns` crosses the normalised ``a`` instead: the same frame, other
    bits; this is the arithmetic the proofs' attitudes have always had.)"""
    n = math.sqrt(a[0] * a[0] + a[1] * a[1] + a[2] * a[2])
    t10, t11, t12 = a[0] / n, a[1] / n, a[2] / n
    c0 = a[1] * b[2] - a[2] * b[1]
    c1 = a[2] * b[0] - a[0] * b[2]
    c2 = a[0] * b[1] - a[1] * b[0]
    m = math.sqrt(c0 * c0 + c1 * c1 + c2 * c2)
    t20, t21, t22 = c0 / m, c1 / m, c2 / m
    out[0, 0], out[1, 0], out[2, 0] = t10, t11, t12
    out[0, 1], out[1, 1], out[2, 1] = t20, t21, t22
    out[0, 2] = t11 * t22 - t12 * t21
    out[1, 2] = t12 * t20 - t10 * t22
    out[2, 2] = t10 * t21 - t11 * t20


@njit(cache=True, nogil=True)
def _sparse_attitudes_kernel(obs_vec: np.ndarray, stars: np.ndarray, cands: np.ndarray) -> np.ndarray:
    """:func:`_sparse_attitudes`: ``R = O C^T``, each element summed in the order numpy's
    ``einsum`` summed it until session 22 (terms 0 and 2, then 1), so the rotations are the
    same to the bit and so are the proofs."""
    o = np.empty((3, 3))
    c = np.empty((3, 3))
    _triad_columns(obs_vec[0], obs_vec[1], o)
    out = np.empty((len(cands), 3, 3))
    for k in range(len(cands)):
        _triad_columns(stars[cands[k, 0]], stars[cands[k, 1]], c)
        for i in range(3):
            for m in range(3):
                out[k, i, m] = (o[i, 0] * c[m, 0] + o[i, 2] * c[m, 2]) + o[i, 1] * c[m, 1]
    return out


EXPLAIN_SLACK = 1.5
""":func:`_could_explain` looks this many match radii (at the coarsest pixel scale) around each
observed star: an angle of one pixel anywhere in a pinhole image is at most the pixel scale at its
centre, and the slack covers a distortion that stretches the local scale by up to a third."""


def _could_explain(verifier: Verifier, cands: IntArray, obs_idx: IntArray) -> IntArray:
    """For each catalogue triple ``cands[k]`` matched to the observed rows ``obs_idx`` (under
    the attitude :func:`_sparse_attitudes` gives it): how many other observed stars have a
    catalogue star (not of the triple) within ``EXPLAIN_SLACK`` match radii of their ICRS
    direction. At least the ``explained`` count of :func:`_field_check`, which counts the same
    stars at the match radius in pixels among fewer catalogue stars, so a test on it never drops
    a triple that the field check keeps."""
    obs = verifier.obs
    others = _rows_but(obs.by_camera, len(obs), obs_idx)
    g = sky_grid(verifier.db)
    chord = EXPLAIN_SLACK * verifier.match_radius_px * obs.pixel_scale_rad
    mask = sky_mask(verifier.db, chord)
    return _box_kernel(np.ascontiguousarray(obs.vec[obs_idx], dtype=np.float64),
                       np.ascontiguousarray(obs.vec[others], dtype=np.float64), _NO_POINTS,
                       np.ascontiguousarray(cands, dtype=np.int64), float(chord), 0.0, g.cell, g.n_side, g.keys,
                       g.starts, g.stars, g.vec, g.columns, mask.n, mask.words, _NO_NEIGHBOURS)


_NO_POINTS = np.zeros((0, 3))
_NO_NEIGHBOURS = np.zeros((0, 1), np.int32)
_NO_NEIGHBOURS.flags.writeable = False  # as star_neighbours' own: one compiled signature
_NO_MASK = np.zeros(1, np.uint64)


@njit(cache=True, nogil=True)
def _box_kernel(tri_vec: np.ndarray, points: np.ndarray, away: np.ndarray, cands: np.ndarray, chord: float,
                away_chord: float, cell: float, n_side: int, keys: np.ndarray, starts: np.ndarray,
                stars: np.ndarray, star_vec: np.ndarray, columns: np.ndarray, mask_n: int, mask_words: np.ndarray,
                neighbours: np.ndarray) -> np.ndarray:
    """Per triple ``cands[k]``: how many of ``points`` (body) have a catalogue star other than
    the triple within ``chord`` and farther than ``away_chord`` from every point of ``away``
    (body), under the TRIAD attitude of the observed ``tri_vec`` onto the triple (the frames of
    :func:`_sparse_attitudes`: body -> ICRS is ``C O^T``).

    Two short cuts, neither of which changes a count: a sky mask (``mask_n`` cells a side, 0 for
    none; reach at least ``chord``) whose clear bit proves no star near a point; and the triple's
    stars' ``neighbours`` (rows of :func:`~.star_index.star_neighbours`, or none), each tested
    first as the scan would test it: near a wide point (the in-view test's boresight), the
    first qualifying star is almost always one of them (99.6% of seed 002's 3-star boxes). The
    reads of the triples ahead are requested (:func:`_request_triple`)."""
    out = np.zeros(len(cands), np.int64)
    fo = np.empty((3, 3))
    fc = np.empty((3, 3))
    frame_columns(tri_vec[0, 0], tri_vec[0, 1], tri_vec[0, 2], tri_vec[1], fo)
    n_p, n_a = len(points), len(away)
    local = np.empty((n_p + n_a, 3))  # O^T v of every point, then of every away point
    for j in range(n_p + n_a):
        v = points[j] if j < n_p else away[j - n_p]
        for i in range(3):
            local[j, i] = fo[0, i] * v[0] + fo[1, i] * v[1] + fo[2, i] * v[2]
    icrs = np.empty((n_p + n_a, 3))
    r2 = chord * chord
    a2 = away_chord * away_chord
    vec_flat = star_vec.reshape(-1)
    nb_flat = neighbours.reshape(-1)
    n_nb = neighbours.shape[1] if len(neighbours) else 0
    n_k = len(cands)
    for k in range(n_k):
        _request_triple(cands, k + 2 * _AHEAD, n_k, vec_flat, nb_flat, n_nb, neighbours, False)
        _request_triple(cands, k + _AHEAD, n_k, vec_flat, nb_flat, n_nb, neighbours, True)
        c0, c1, c2 = cands[k, 0], cands[k, 1], cands[k, 2]
        a = star_vec[c0]
        frame_columns(a[0], a[1], a[2], star_vec[c1], fc)
        for j in range(n_p + n_a):
            for i in range(3):
                icrs[j, i] = fc[i, 0] * local[j, 0] + fc[i, 1] * local[j, 1] + fc[i, 2] * local[j, 2]
        for j in range(n_p):
            px, py, pz = icrs[j, 0], icrs[j, 1], icrs[j, 2]
            if mask_n > 0 and not may_hold_star(px, py, pz, mask_n, mask_words):
                continue
            # The tests of skygrid.has_star_within_away and star_qualifies written out: inlined
            # here, they took and gave back a reference count for each array they take at every
            # point of every triple (~17% of a 3-star proof; `python -m bench.nrt_loops --kernel
            # service.core.sparse_proof:_box_kernel`)
            hit = False
            for t in range(3 * n_nb):  # the triple's neighbours first
                own = c0 if t < n_nb else (c1 if t < 2 * n_nb else c2)
                row = neighbours[own, t % n_nb]
                if row < 0 or row == c0 or row == c1 or row == c2:
                    continue
                sx, sy, sz = star_vec[row, 0], star_vec[row, 1], star_vec[row, 2]
                if _d2(sx, sy, sz, px, py, pz) <= r2 and _clear_of(sx, sy, sz, icrs, n_p, a2):
                    hit = True
                    break
            if not hit:  # the grid's cells the ball overlaps
                lo_x, hi_x, lo_y, hi_y, lo_z, hi_z = ball_cells(px, py, pz, chord, cell, n_side)
                for q in range((hi_x - lo_x + 1) * (hi_y - lo_y + 1)):
                    col = (lo_x + q // (hi_y - lo_y + 1)) * n_side + lo_y + q % (hi_y - lo_y + 1)
                    for pos in range(columns[col], columns[col + 1]):
                        iz = keys[pos] - col * n_side
                        if iz < lo_z:
                            continue
                        if iz > hi_z:
                            break
                        for st in range(starts[pos], starts[pos + 1]):
                            row = stars[st]
                            if row == c0 or row == c1 or row == c2:
                                continue
                            sx, sy, sz = star_vec[row, 0], star_vec[row, 1], star_vec[row, 2]
                            if _d2(sx, sy, sz, px, py, pz) <= r2 and _clear_of(sx, sy, sz, icrs, n_p, a2):
                                hit = True
                                break
                        if hit:
                            break
                    if hit:
                        break
            if hit:
                out[k] += 1
    return out


_AHEAD = 4
""":func:`_box_kernel` requests the stars (and their neighbour rows) of the triple this many ahead,
and the neighbours' own vectors of the triple this many ahead again: the triples' stars lie all
over the sky, so each triple's reads are cache misses that would otherwise follow one another."""


@njit(cache=True, nogil=True, inline="always")
def _d2(ax: float, ay: float, az: float, bx: float, by: float, bz: float) -> float:
    """Squared distance of two points (unit-vector chords squared)."""
    return (ax - bx) ** 2 + (ay - by) ** 2 + (az - bz) ** 2


@njit(cache=True, nogil=True, inline="always")
def _clear_of(sx: float, sy: float, sz: float, pts: np.ndarray, first: int, a2: float) -> bool:
    """Is ``(sx, sy, sz)`` farther than ``sqrt(a2)`` from every row of ``pts`` from ``first`` on?
    (One exit, no view: inlined in a loop, it then costs no reference count.)"""
    clear = True
    for m in range(first, len(pts)):
        if _d2(sx, sy, sz, pts[m, 0], pts[m, 1], pts[m, 2]) <= a2:
            clear = False
            break
    return clear


@njit(cache=True, nogil=True, inline="always")
def _request_triple(cands: np.ndarray, k: int, n_k: int, vec_flat: np.ndarray, nb_flat: np.ndarray, n_nb: int,
                    neighbours: np.ndarray, second: bool) -> None:
    """Request triple ``k``'s star vectors and neighbour rows (``second``: the neighbours' vectors,
    their rows being in cache by then); nothing past the last triple. A hint: reads nothing back."""
    if k >= n_k:
        return
    for t in range(3):
        own = cands[k, t]
        if not second:
            prefetch(vec_flat, np.int64(3 * own))
            if n_nb:
                prefetch(nb_flat, np.int64(own * n_nb))
        elif n_nb:
            row = neighbours[own, 0]
            if row >= 0:
                prefetch(vec_flat, np.int64(3 * row))


def _star_in_view(verifier: Verifier, cands: IntArray, obs_idx: IntArray) -> IntArray:
    """For each catalogue triple ``cands[k]`` matched to the observed rows ``obs_idx`` (under
    the attitude :func:`_sparse_attitudes` gives it): is a catalogue star other than the triple
    within the circle about the principal point that stays a match radius inside the image,
    and farther than ``radius_px / f_px`` (angle) from every other observed star? Such a star
    is one :func:`_field_check` counts as unseen: a pinhole image holds the circle, it is among
    the field's nearest stars to the boresight, and no observed star is within the match radius
    of its pixel (a pinhole's pixel distance is at least ``f_px`` times the angle). So a triple
    marked True cannot count. All False (no test) for a rig or a distorted camera."""
    obs = verifier.obs
    if len(obs.cameras) != 1 or obs.cameras[0].distortion:
        return np.zeros(len(cands), np.bool_)
    cam = obs.cameras[0]
    r = verifier.match_radius_px
    inner = min(cam.cx + 0.5 - r, cam.width - 0.5 - r - cam.cx, cam.cy + 0.5 - r, cam.height - 0.5 - r - cam.cy)
    if inner <= 0:
        return np.zeros(len(cands), np.bool_)
    half = math.atan(inner / cam.f_px)
    g = field_grid(verifier.db, math.degrees(half), any_star=True)  # a star qualifying ends each scan
    others = _rows_but(obs.by_camera, len(obs), obs_idx)
    boresight = np.ascontiguousarray(np.asarray(obs.mountings[0], dtype=np.float64)[2:3])  # body
    return _box_kernel(np.ascontiguousarray(obs.vec[obs_idx], dtype=np.float64), boresight,
                       np.ascontiguousarray(obs.vec[others], dtype=np.float64),
                       np.ascontiguousarray(cands, dtype=np.int64), 2 * math.sin(half / 2),
                       2 * math.sin(r / cam.f_px / 2), g.cell, g.n_side, g.keys, g.starts, g.stars, g.vec,
                       g.columns, 0, _NO_MASK, star_neighbours(verifier.db)) > 0


def warm_up_screens(db: NavDatabase, camera: Camera, frame: Centroids) -> None:
    """Compile (or load) the box screens' kernels on ``db``, and build the indexes they read:
    each screen of ``frame``'s first 3 and 4 stars against a few catalogue triples, and their
    attitudes (see :func:`~service.core.warmup.warm_up`)."""
    from .pipeline import _observation  # (the pipeline imports this module)

    triples = np.arange(6, dtype=np.int64).reshape(2, 3) % max(len(db.stars), 1)
    for n in (3, 4):
        obs = _observation([(Centroids(frame.xy[:n], frame.flux[:n]), camera, None)], [np.eye(3)])
        if len(obs) < 3:
            continue
        verifier = Verifier(db, obs, match_radius_px=3.0)
        _could_explain(verifier, triples, np.arange(3))
        _star_in_view(verifier, triples, np.arange(3))
        _sparse_attitudes(obs.vec[:3], star_vec64(db), triples)
        _triangle_fit(np.ascontiguousarray(obs.vec, dtype=np.float64), star_vec64(db), np.arange(3), triples[0], 1e-3)
        triangle_mismatch(np.ascontiguousarray(obs.vec, dtype=np.float64), star_vec64(db), np.arange(3), triples[0])
        # the kernels a proof and a small frame's screen call from Python, not from a compiled
        # caller (whose cached code holds its own copy): the pairing of a proven match
        # (match._match_rig) and the wide screen (screen.hits_under). Loaded on first use they
        # cost a worker's first 3-4-star frames 5-9 ms each (session 30)
        verifier._match_all(np.eye(3))
        verifier._wide_hits(np.arange(3), triples[0], np.arange(n), 3)
    _without_triple(triples, 0, 1, 2)


def _field_check(verifier: Verifier, rs: FloatArray, cands: IntArray,
                 obs_idx: IntArray, *, max_near: int = 96) -> tuple[IntArray, IntArray]:
    """For each attitude ``rs[k]`` with its catalogue triple ``cands[k]`` matched to the
    observed rows ``obs_idx``: how many catalogue stars it predicts inside an image (at least
    one match radius from the edge) with no observed star within the match radius (stars the
    camera should have seen), and how many of the other observed stars it explains (a
    predicted star within the match radius). Looks at the ``max_near`` catalogue stars nearest
    each boresight; one compiled call per camera (:func:`field_check_kernel`)."""
    obs = verifier.obs
    if len(rs) == 0:
        return np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64)
    rs = np.ascontiguousarray(rs, dtype=np.float64)
    cands = np.ascontiguousarray(cands, dtype=np.int64)
    stars, per_camera = _field_check_args(verifier)
    unseen = explained = None
    for c, (mount, cam, dist, chord, g) in enumerate(per_camera):
        rows = _rows_but(obs.by_camera[c:c + 1], len(obs), obs_idx)
        u, e = field_check_kernel(rs, cands, mount, cam, dist, stars, chord, g.cell, g.n_side, g.keys, g.starts,
                                  g.stars, g.columns, max_near, np.ascontiguousarray(obs.xy[rows]),
                                  float(verifier.match_radius_px))
        unseen, explained = (u, e) if unseen is None else (unseen + u, explained + e)
    return unseen, explained


def _field_check_args(verifier: Verifier) -> tuple[np.ndarray, list[tuple[object, ...]]]:
    """What :func:`field_check_kernel` takes of ``verifier``'s frame that no call changes: the
    star vectors and, per camera, its mounting, camera and distortion rows, the field's chord
    and grid (made on the frame's first field check and kept on the verifier: ~8 us a call)."""
    got = verifier.__dict__.get("_field_check_args")
    if got is None:
        obs = verifier.obs
        cams, dist = _camera_rows(tuple(obs.cameras))
        per_camera = []
        for c, cam in enumerate(obs.cameras):
            half_deg = cam.diagonal_fov_deg / 2 + 0.2
            per_camera.append((np.ascontiguousarray(obs.mountings[c], dtype=np.float64), cams[c], dist[c],
                               2 * math.sin(math.radians(half_deg) / 2), field_grid(verifier.db, half_deg)))
        got = verifier.__dict__["_field_check_args"] = (star_vec64(verifier.db), per_camera)
    return got


@njit(cache=True, nogil=True)
def field_check_kernel(rs: np.ndarray, cands: np.ndarray, mount: np.ndarray, cam: np.ndarray, dist: np.ndarray,
                       star_vec: np.ndarray, chord: float, cell: float, n_side: int, keys: np.ndarray,
                       starts: np.ndarray, stars: np.ndarray, columns: np.ndarray, max_near: int,
                       obs_xy: np.ndarray, radius_px: float) -> tuple[np.ndarray, np.ndarray]:
    """``(unseen, explained)`` per attitude ``rs[k]`` (ICRS -> body) with its catalogue triple
    ``cands[k]``, for one camera (``mount`` body -> camera, ``cam`` = ``f, cx, cy, w, h``,
    ``dist`` = Brown-Conrady ``k1, k2, p1, p2, k3``). The field: the ``max_near`` catalogue stars
    nearest the boresight within ``chord``, less the triple's own; ``obs_xy`` the observed stars
    other than the matched ones (px)."""
    n_k = len(rs)
    unseen = np.zeros(n_k, np.int64)
    explained = np.zeros(n_k, np.int64)
    buf = np.empty(len(star_vec), np.int64)
    w, h = cam[3], cam[4]
    rad2 = radius_px * radius_px
    n_obs = len(obs_xy)
    hit = np.zeros(n_obs, np.bool_)
    r_cam = np.empty((3, 3))
    for k in range(n_k):
        for a in range(3):
            for b in range(3):
                r_cam[a, b] = mount[a, 0] * rs[k, 0, b] + mount[a, 1] * rs[k, 1, b] + mount[a, 2] * rs[k, 2, b]
        bx, by, bz = r_cam[2, 0], r_cam[2, 1], r_cam[2, 2]
        n = collect_within(bx, by, bz, chord, cell, n_side, keys, starts, stars, star_vec, columns, buf)
        near = buf[:n]
        if n > max_near:  # the nearest max_near, as the k-d tree's k nearest
            d2 = np.empty(n)
            for i in range(n):
                v = star_vec[near[i]]
                d2[i] = (v[0] - bx) ** 2 + (v[1] - by) ** 2 + (v[2] - bz) ** 2
            near = near[np.argsort(d2)[:max_near]]
        hit[:] = False
        xy = np.empty((len(near), 2))
        inside = project_rows(r_cam, star_vec, near, cam, dist, xy)
        for i in range(len(near)):
            row = near[i]
            if row == cands[k, 0] or row == cands[k, 1] or row == cands[k, 2] or not inside[i]:
                continue
            x, y = xy[i, 0], xy[i, 1]
            seen = False
            for j in range(n_obs):
                dx = x - obs_xy[j, 0]
                dy = y - obs_xy[j, 1]
                if dx * dx + dy * dy <= rad2:
                    seen = True
                    hit[j] = True
            edge = x >= -0.5 + radius_px and x <= w - 0.5 - radius_px and y >= -0.5 + radius_px \
                and y <= h - 0.5 - radius_px
            if edge and not seen:
                unseen[k] += 1
        for j in range(n_obs):
            if hit[j]:
                explained[k] += 1
    return unseen, explained


__all__ = ["SPARSE_CONFIDENCE", "SPARSE_MAX_SAMPLE", "check_unique_triangle", "field_check_kernel",
           "triangle_mismatch"]
