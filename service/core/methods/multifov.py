"""``multifov``: several cameras on one body, identified together by multiple master stars
(seed 001, GF-7's two 8.9 deg star cameras).

Every camera's stars arrive as body-frame vectors (``v_body = R_mount^T v_cam``; camera 0, the
reference "1a", usually has the identity mounting), so angles between stars of different
cameras are known. Identification, per attempt:

1. Masters: the brightest star of each camera (attempt ``k`` takes the ``k``-th brightest).
2. Each master is identified by "matching-probability centre star" voting: its angles to the
   other stars of its own camera are looked up in the pair table and every catalogue star of a
   matching pair gets a vote; the most-voted stars are the master's candidates.
3. Brightness triangle: the two masters plus the next brightest star (with three or more
   cameras: the three brightest masters). Candidate master pairs must reproduce the masters'
   inter-camera angle; the third star is then predicted from the pair's attitude.
4. Distance triangle: around the reference camera's master, the two stars between radii ``r``
   and ``R`` nearest it, matched through the pair table (master among its candidates).
5. Both triangles share the reference master: only identities on which they agree form a
   five-star hypothesis. The remaining stars are linked by the shared verifier, which projects
   the catalogue through the hypothesis' attitude into every camera and accepts the stars that
   fall on their predicted positions (the paper's distance links to identified stars, done for
   all of them at once); no answer leaves unverified.

Pair table: the paper needs inter-camera pairs out to ``theta + FOV`` (theta the angle between
the optical axes), a table that grows with theta, has to be rebuilt when a camera is remounted,
and returns thousands of pairs per look-up at 60-90 deg. We identify each master with
intra-camera pairs only (out to the field diagonal) and join the cameras through the known
mounting: a candidate pair of masters is checked by the dot product of the two catalogue
vectors. The database is the same for any rig whose cameras are no wider than it serves.
The pair table is the database's shared ``pairs/`` group (pyramid and triangle read it too);
multifov stores only its segment index over its rows.

Index (``index``): the paper's piecewise-linear fit of pair index against angle in 1-deg
segments (a k-vector variant, :class:`SegmentIndex`) or ``np.searchsorted`` on the sorted
angles; both return the same ranges, and ``bench/bench_multifov.py`` times them.

Where the paper is vague or weak we chose:
- the reference camera for the distance triangle is the one with the most stars (its votes
  are the strongest), not always camera 0;
- more attempts, every pair of ranks among the four brightest stars of the reference camera
  and of the others (a saturated or false brightest star, which the paper names as the cause
  of its failures, costs one attempt, not the frame), each also trying the two masters alone
  (an attitude from two stars far apart, screened on the bright stars of every camera) when
  the triangles fail;
- ``r`` = 0.5 deg (centroid noise and blends make shorter sides uninformative) and ``R`` = the
  camera's field side;
- a single-camera frame uses the distance triangle alone;
- ``robust`` ranks a master's candidates by their votes beyond chance (each catalogue star's
  expected chance votes from the star density around it, :meth:`MultiFovMatcher.chance_votes`),
  not by the votes alone: in dense sky every star collects many chance votes, which crowded
  the true master out of the candidates with coarse pixels (one camera, 0.5 px, 100 frames:
  seed 004 15 -> 90 % right, seed 003 67 -> 97 %, seed 000 79 -> 92 %, 0 wrong);
- a frame of 3-8 stars the masters do not solve (``robust``: e.g. (2, 2) or (1, 3) stars per
  camera, no camera with three for the vote) is proven by one triangle across the cameras and
  every other star (:mod:`.rig_proof`).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from ..catalog import StarTable
from ..geometry import angle_between
from ..navdb.reader import NavDatabase
from ..star_index import star_tree
from ..types import FloatArray, IntArray
from ..verify import Verified
from ._grow import screen_and_grow
from ._pairs import (
    PairLimits,
    SharedPairs,
    edge_keys,
    join_triangles,
    pair_limits,
    require_shared,
    same_handedness,
)
from .base import Progress, SolveContext
from .rig_proof import PairLookup, prove_sparse_rig

SEGMENT_DEG = 1.0
"""Width of the paper's straight-line segments of the pair index."""
R_INNER_DEG = 0.5
MAX_CANDIDATES = 64
"""A master keeps its this-many most-voted catalogue stars, and every star tied with the last."""
MAX_TIES = 4096
"""... but never more than this (a camera with three stars gives thousands of two-vote ties)."""
RING_DEG = (0.0, 2.0, 4.0, 8.0, 16.0, 32.0)
"""Rings (deg) around a star whose star densities set its chance votes (clipped to the pair table's reach)."""
MAX_PARTNERS = 20
"""A master votes with at most this many of the brightest other stars of its camera."""
NEAR_STARS = 4
"""``robust``, one camera: the distance triangle pairs the master with two of its this-many
nearest stars between ``r`` and ``R`` (the paper: the two nearest)."""


class SegmentIndex:
    """Piecewise-linear index over sorted values: in each segment ``[s w, (s+1) w)`` a straight
    line ``index ~ slope * value + intercept`` fitted by least squares, with the largest error of
    the fit, so that a range query reads only ``2 err + 1`` entries around the estimate.

    Attributes
    ----------
    start : (S + 1,) int64
        Index of the first value of each segment (and the table length).
    coef : (S, 2) float64
        ``slope, intercept`` of each segment.
    err : (S,) int64
        Largest ``|fitted - true|`` index within the segment, rounded up.
    """

    def __init__(self, values: np.ndarray, start: np.ndarray, coef: np.ndarray, err: np.ndarray,
                 width: float) -> None:
        self.values, self.start, self.coef, self.err, self.width = values, start, coef, err, width

    @classmethod
    def build(cls, values: np.ndarray, width: float) -> SegmentIndex:
        """Fit the segments of sorted ``values`` (segments of ``width``)."""
        v = np.asarray(values, np.float64)
        n_seg = max(1, int(math.ceil((v[-1] if len(v) else 0.0) / width + 1e-12)) + 1)
        start = np.searchsorted(v, np.arange(n_seg + 1) * width, side="left")
        coef = np.zeros((n_seg, 2))
        err = np.zeros(n_seg, np.int64)
        for s in range(n_seg):
            lo, hi = int(start[s]), int(start[s + 1])
            x = v[lo:hi]
            idx = np.arange(lo, hi, dtype=np.float64)
            slope, icpt = 0.0, float(idx.mean()) if hi > lo else float(lo)
            worst = float(np.abs(icpt - idx).max(initial=0.0))
            if hi - lo >= 2:  # least squares, by hand; kept only where it beats a flat line
                xm = x - x.mean()
                var = float(xm @ xm)
                fit = float(xm @ (idx - idx.mean())) / var if var > 1e-300 else 0.0
                b = float(idx.mean() - fit * x.mean())
                with np.errstate(over="ignore", invalid="ignore"):
                    w = float(np.abs(fit * x + b - idx).max())
                if math.isfinite(w) and w < worst:
                    slope, icpt, worst = fit, b, w
            coef[s] = slope, icpt
            err[s] = int(math.ceil(worst)) + 1
        return cls(v, start, coef, err, width)

    def position(self, x: np.ndarray) -> IntArray:
        """``np.searchsorted(values, x, side="left")`` through the fitted lines: the line's
        estimate, then a bisection of the ``2 err + 1`` entries the fit can be off by
        (vectorised over the queries)."""
        x = np.atleast_1d(np.asarray(x, np.float64))
        seg = np.clip((x / self.width).astype(np.int64), 0, len(self.coef) - 1)
        fitted = np.clip(self.coef[seg, 0] * x + self.coef[seg, 1], self.start[seg], self.start[seg + 1])
        est = np.rint(fitted).astype(np.int64)
        err = self.err[seg]
        lo = np.clip(est - err, self.start[seg], self.start[seg + 1])
        hi = np.clip(est + err + 1, self.start[seg], self.start[seg + 1])
        last = len(self.values) - 1
        for _ in range(int(np.max(2 * err + 2, initial=1)).bit_length()):
            mid = (lo + hi) // 2
            go = (lo < hi) & (self.values[np.minimum(mid, last)] < x)
            lo = np.where(go, mid + 1, lo)
            hi = np.where(go | (lo >= hi), hi, mid)
        return lo

    def range(self, lo: np.ndarray, hi: np.ndarray) -> tuple[IntArray, IntArray]:
        """Index ranges ``[start, end)`` of the values within ``[lo, hi]``."""
        hi = np.atleast_1d(np.asarray(hi, np.float64))
        return self.position(lo), self.position(np.nextafter(hi, np.inf))


class MultiFov:
    name = "multifov"
    summary = "multi-camera rigs: master stars by voting, brightness + distance triangles (seed 001)"

    def pair_limits(self, config: Any, params: dict[str, Any]) -> PairLimits:
        """Intra-camera pairs up to ``max_angle_deg`` (default: the database's largest field), degrees."""
        return pair_limits(config, params)

    def build_tables(
        self, stars: StarTable, config: Any, params: dict[str, Any], progress: Progress,
        *, shared: SharedPairs | None = None,
    ) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
        """Own arrays: the segment index over its rows of the shared pair table."""
        limits = self.pair_limits(config, params)
        _, angles = require_shared(shared, self.name).view(limits)
        seg = SegmentIndex.build(angles, math.radians(SEGMENT_DEG))
        progress(f"{len(angles)} pairs", 1.0)
        tables: dict[str, np.ndarray] = {"seg_start": seg.start, "seg_coef": seg.coef, "seg_err": seg.err}
        meta: dict[str, Any] = {
            "max_angle_deg": limits.max_angle_deg, "n_pairs": int(len(angles)), "segment_deg": SEGMENT_DEG,
            "index": str(params.get("index", "searchsorted")), "mode": str(params.get("mode", "robust")),
        }
        return tables, meta

    def matcher(self, db: NavDatabase) -> MultiFovMatcher:
        return MultiFovMatcher(db)


class MultiFovMatcher:
    """Solver over the ``multifov`` tables.

    ``index``: ``"segments"`` or ``"searchsorted"``; ``mode``: ``"paper"`` or ``"robust"``
    (both default to the database's build parameters); ``attempts``: master ranks per camera
    (the paper: 1, the brightest star; robust: 4, every rank pair of the four brightest);
    ``mount_tol_arcsec``: the mounting calibration's error, added to inter-camera angle
    tolerances."""

    def __init__(self, db: NavDatabase, *, index: str | None = None, mode: str | None = None,
                 attempts: int | None = None, mount_tol_arcsec: float = 10.0) -> None:
        t = db.tables["multifov"]
        prm = db.method_params("multifov")
        self.pairs, self.angles = t["pairs"], t["angles"]
        self.max_angle = math.radians(prm["max_angle_deg"])
        self.segments = SegmentIndex(self.angles, t["seg_start"], t["seg_coef"], t["seg_err"],
                                     math.radians(prm["segment_deg"]))
        self.index = index or prm.get("index", "searchsorted")
        self.mode = mode or prm.get("mode", "robust")
        if self.index not in ("segments", "searchsorted") or self.mode not in ("paper", "robust"):
            raise ValueError(f"multifov: unknown index/mode {self.index!r}/{self.mode!r}")
        self.attempts = attempts or (1 if self.mode == "paper" else 4)
        self.mount_tol = math.radians(mount_tol_arcsec / 3600.0)
        self.vec = db.stars.vec
        self.n_stars = len(db.stars)
        self.lookup = PairLookup(self.pairs, self.angles, self.max_angle)
        self._rings: tuple[FloatArray, FloatArray] | None = None

    # ---- look-ups --------------------------------------------------------------------------
    def ranges(self, lo: np.ndarray, hi: np.ndarray) -> tuple[IntArray, IntArray]:
        """Pair-table ranges of angles within ``[lo, hi]`` (radians, arrays)."""
        if self.index == "segments":
            return self.segments.range(lo, hi)
        lo = np.atleast_1d(lo)
        hi = np.atleast_1d(hi)
        return np.searchsorted(self.angles, lo, side="left"), np.searchsorted(self.angles, hi, side="right")

    def _rows(self, lo: np.ndarray, hi: np.ndarray) -> tuple[IntArray, IntArray]:
        """Pair rows within the ranges, and which range each came from."""
        s, e = self.ranges(lo, hi)
        counts = np.maximum(e - s, 0)
        total = int(counts.sum())
        which = np.repeat(np.arange(len(s)), counts)
        rows = np.repeat(s - np.cumsum(counts) + counts, counts) + np.arange(total)
        return rows, which

    def vote(self, master: int, partners: IntArray, obs_vec: FloatArray, tol: float) -> IntArray:
        """Candidates of observed star ``master``: catalogue stars voted for by its angles to
        ``partners`` (rows of ``obs_vec``), most votes first, at least two votes each: the
        ``MAX_CANDIDATES`` best and all tied with the last of them."""
        d = np.asarray(angle_between(obs_vec[master][None, :], obs_vec[partners]))
        d = d[d <= self.max_angle - tol]
        if len(d) < 2:
            return np.zeros(0, np.int64)
        rows, _ = self._rows(d - tol, d + tol)
        votes = np.bincount(np.asarray(self.pairs[rows]).ravel(), minlength=self.n_stars)
        if self.mode == "robust":  # the votes beyond each star's chance (see chance_votes)
            chance = self.chance_votes(d, tol)
            voted = np.flatnonzero(votes >= 2)
            z = (votes[voted] - chance[voted]) / np.sqrt(chance[voted] + 1.0)
            return voted[np.argsort(-z, kind="stable")[:MAX_CANDIDATES]]
        order = np.argsort(-votes, kind="stable")
        floor = max(2, int(votes[order[min(MAX_CANDIDATES, len(order)) - 1]]))
        return order[: min(int((votes >= floor).sum()), MAX_TIES)]

    def chance_votes(self, d: FloatArray, tol: float) -> FloatArray:
        """Expected chance votes of every catalogue star for partners at angles ``d`` (rad,
        +- ``tol``): a partner at ``d`` collects the stars of an annulus ``4 pi sin(d) tol`` in
        area, at the density of the star's own neighbours in the ring of ``RING_DEG`` that
        holds ``d``.

        The paper ranks a master's candidates by their votes alone. With coarse pixels every
        catalogue star collects chance votes, far more in dense sky than the average: on seed
        004 (70 "/px) the 64th-best star had 55-77 votes and the true master 36-90, among the
        candidates in 13 of 160 tries. Ranked by the votes beyond chance, ``(votes - chance) /
        sqrt(chance + 1)`` (``robust`` mode), a star of dense sky no longer crowds out the
        master (``paper`` mode keeps the paper's ranking)."""
        if self._rings is None:  # each star's neighbours per ring (the pair rows are sorted by angle)
            edges = np.radians(np.minimum(np.asarray(RING_DEG), math.degrees(self.max_angle)))
            ends = np.searchsorted(self.angles, edges, side="right")
            within = np.stack([np.bincount(np.asarray(self.pairs[:e]).ravel(), minlength=self.n_stars)
                               for e in ends])  # (rings + 1, n_stars), cumulative
            area = np.maximum(np.cos(edges[:-1]) - np.cos(edges[1:]), 1e-12)  # / (2 pi sr)
            self._rings = (edges, np.diff(within, axis=0) / area[:, None])
        edges, density = self._rings
        ring = np.clip(np.searchsorted(edges, d, side="right") - 1, 0, len(density) - 1)
        weight = np.bincount(ring, weights=2.0 * np.sin(d) * tol, minlength=len(density))
        return weight @ density

    def _edges(self, d: float, tol: float, firsts: IntArray) -> IntArray:
        """Directed catalogue pairs ``(a, b)`` with angle ``d +- tol`` and ``a`` in ``firsts``,
        sorted by ``a``."""
        rows, _ = self._rows(np.array([d - tol]), np.array([d + tol]))
        p = np.asarray(self.pairs[rows], np.int64)
        both = np.concatenate([p, p[:, ::-1]])
        both = both[np.isin(both[:, 0], firsts)]
        return both[np.argsort(both[:, 0], kind="stable")]

    # ---- identification ----------------------------------------------------------------------
    def identify(self, ctx: SolveContext) -> Verified | None:
        found = self._masters(ctx)
        if found is None and self.mode == "robust" and not ctx.verifier.marginal:
            # a sparse frame: one triangle across the cameras and every other star (rig_proof)
            found = prove_sparse_rig(ctx.verifier, self.lookup, ctx.tol_rad, self.mount_tol, ctx.expired)
        return found

    def _masters(self, ctx: SolveContext) -> Verified | None:
        """The paper's identification: attempts over master ranks (see the module docstring)."""
        obs = ctx.obs
        cams = [c for c in range(len(obs.cameras)) if len(obs.by_camera[c]) >= 3]
        if not cams:
            return None
        robust = self.mode == "robust"
        ref = max(cams, key=lambda c: len(obs.by_camera[c])) if robust else cams[0]
        voted: dict[int, IntArray] = {}

        def cand(m: int) -> IntArray:
            if m not in voted:
                rows = obs.by_camera[int(obs.camera[m])]
                voted[m] = self.vote(m, rows[rows != m][:MAX_PARTNERS], obs.vec, ctx.tol_rad)
            return voted[m]

        for i, j in self._rank_pairs(len(cams)):
            if ctx.expired():
                break
            masters = {c: int(obs.by_camera[c][i if c == ref else j]) for c in cams
                       if len(obs.by_camera[c]) > (i if c == ref else j)}
            if ref not in masters:
                continue
            cands = {c: cand(m) for c, m in masters.items()}
            found = self._attempt(ctx, masters, ref, cands)
            if found is None and robust and len(masters) > 1:
                found = self._master_pairs(ctx, masters, ref, cands)
            if found is not None:
                return found
        return None

    def _rank_pairs(self, n_cams: int) -> list[tuple[int, int]]:
        """Brightness ranks ``(reference master, other masters)`` to try, in order: the paper
        takes the brightest of every camera (more attempts: the k-th brightest everywhere);
        ``robust`` mixes ranks, so that one false or saturated star does not spoil the attempts
        of the other cameras."""
        k = self.attempts
        if self.mode == "paper":
            return [(r, r) for r in range(k)]
        if n_cams == 1:
            return [(r, 0) for r in range(k)]
        return sorted(((i, j) for i in range(k) for j in range(k)), key=lambda t: (t[0] + t[1], t[0]))

    def _attempt(self, ctx: SolveContext, masters: dict[int, int], ref: int,
                 cands: dict[int, IntArray]) -> Verified | None:
        """The paper's attempt: brightness triangle and distance triangle, joined on the
        reference master; with one camera the distance triangle alone."""
        tol = ctx.tol_rad
        a = masters[ref]
        others = [c for c in masters if c != ref and len(cands[c])]
        if not others:  # one camera: the distance triangle alone
            return self._distance_triangles_alone(ctx, a, cands[ref], tol)
        dist_tris = self._distance_triangle(ctx, a, cands[ref], tol)
        ctx.verifier.patterns += 1
        bright = self._brightness_triangle(ctx, masters, ref, cands, tol)
        if bright is None or dist_tris is None:
            return None
        (obs_b, cat_b), (obs_d, cat_d) = bright, dist_tris
        key_b, key_d = cat_b[:, 0], cat_d[:, 0]
        common = np.intersect1d(key_b, key_d)
        hyps = [(i, j) for s in common
                for i in np.flatnonzero(key_b == s) for j in np.flatnonzero(key_d == s)]
        for i, j in hyps[:16]:
            pairs = dict(zip(obs_b.tolist(), cat_b[i].tolist(), strict=True))
            same = zip(obs_d.tolist(), cat_d[j].tolist(), strict=True)
            if any(pairs.setdefault(o, s) != s for o, s in same):
                continue  # the triangles share a star and disagree on it
            found = ctx.verifier.check(np.array(list(pairs)), np.array(list(pairs.values())))
            if found is not None:
                return found
        return None

    def _master_pairs(self, ctx: SolveContext, masters: dict[int, int], ref: int,
                      cands: dict[int, IntArray]) -> Verified | None:
        """``robust`` fallback: every candidate pair of two masters of different cameras that
        reproduces their angle fixes an attitude; screen it on the other bright stars of all
        cameras and verify the best (no third star or distance-triangle star is trusted)."""
        obs = ctx.obs
        a = masters[ref]
        for c, b in masters.items():
            if c == ref or not len(cands[c]) or not len(cands[ref]):
                continue
            cat = self._cross_pairs(obs.vec[a], obs.vec[b], cands[ref], cands[c], ctx.tol_rad)
            if len(cat) == 0:
                continue
            others = np.arange(min(len(obs), 2 + 12))
            found = screen_and_grow(ctx, np.array([a, b]), cat, others, min_hits=2)
            if found is not None:
                return found
        return None

    def _cross_pairs(self, va: FloatArray, vb: FloatArray, ca: IntArray, cb: IntArray,
                     tol: float) -> IntArray:
        """Catalogue pairs ``(A, B)`` ``(K, 2)``, ``A`` in ``ca`` and ``B`` in ``cb``, whose angle
        matches the observed inter-camera angle ``va``-``vb`` (mounting error allowed)."""
        d_ab = float(angle_between(va, vb))
        cross_ab = np.arccos(np.clip(self.vec[ca] @ self.vec[cb].T, -1.0, 1.0))
        ia, ib = np.nonzero(np.abs(cross_ab - d_ab) <= tol + self.mount_tol)
        return np.column_stack([ca[ia], cb[ib]]).astype(np.int64)

    def _near_stars(self, ctx: SolveContext, a: int, tol: float, k: int) -> IntArray:
        """The ``k`` stars of ``a``'s camera between ``r`` and ``R`` nearest ``a``, nearest first."""
        obs = ctx.obs
        cam = int(obs.camera[a])
        rows = obs.by_camera[cam]
        rows = rows[rows != a]
        da = np.asarray(angle_between(obs.vec[a][None, :], obs.vec[rows]))
        r_outer = min(math.radians(obs.cameras[cam].fov_deg), self.max_angle - tol)
        ok = (da > math.radians(R_INNER_DEG)) & (da < r_outer)
        return rows[ok][np.argsort(da[ok], kind="stable")][:k]

    def _distance_triangles_alone(self, ctx: SolveContext, a: int, cand_a: IntArray,
                                  tol: float) -> Verified | None:
        """One camera: the distance triangle of master ``a`` screened and checked. The paper's
        triangle takes the two stars nearest the master; ``robust`` also tries the other pairs
        of its ``NEAR_STARS`` nearest, nearest pairs first, so that one false or missing star
        among the two nearest does not spoil the attempt (one camera at 0.5 px with 2 false
        stars: see docs/methods.md, multifov)."""
        if len(cand_a) == 0:
            return None
        near = self._near_stars(ctx, a, tol, NEAR_STARS if self.mode == "robust" else 2)
        pairs = sorted(((i, j) for i in range(len(near)) for j in range(i + 1, len(near))),
                       key=lambda t: (t[1], t[0]))
        for i, j in pairs:
            if ctx.expired():
                break
            found = self._triangle_of(ctx, a, int(near[i]), int(near[j]), cand_a, tol)
            if found is None:
                continue
            found = ctx.verifier.screen_and_check(found[0], found[1])
            if found is not None:
                return found
        return None

    def _distance_triangle(self, ctx: SolveContext, a: int, cand_a: IntArray,
                           tol: float) -> tuple[IntArray, IntArray] | None:
        """Observed ``(a, d, e)`` and catalogue triples for it: ``d``, ``e`` the two stars of
        ``a``'s camera between ``r`` and ``R`` nearest ``a``."""
        if len(cand_a) == 0:
            return None
        near = self._near_stars(ctx, a, tol, 2)
        if len(near) < 2:
            return None
        return self._triangle_of(ctx, a, int(near[0]), int(near[1]), cand_a, tol)

    def _triangle_of(self, ctx: SolveContext, a: int, d: int, e: int, cand_a: IntArray,
                     tol: float) -> tuple[IntArray, IntArray] | None:
        """Observed ``(a, d, e)`` and its catalogue triples with ``a`` among ``cand_a`` (the
        same handedness), or None."""
        obs = ctx.obs
        tri = np.array([a, d, e])
        ang = lambda i, j: float(angle_between(obs.vec[i], obs.vec[j]))  # noqa: E731
        e_ad = self._edges(ang(a, d), tol, cand_a)
        e_ae = self._edges(ang(a, e), tol, cand_a)
        p = self._rows(np.array([ang(d, e) - tol]), np.array([ang(d, e) + tol]))[0]
        pj = np.asarray(self.pairs[p], np.int64)
        keys = edge_keys(np.concatenate([pj, pj[:, ::-1]]), self.n_stars)
        cat = join_triangles(e_ad, e_ae, keys, self.n_stars)
        if len(cat) == 0:
            return None
        cat = cat[same_handedness(self.vec, obs.vec[tri], cat)]
        return (tri, cat) if len(cat) else None

    def _brightness_triangle(self, ctx: SolveContext, masters: dict[int, int], ref: int,
                             cands: dict[int, IntArray], tol: float) -> tuple[IntArray, IntArray] | None:
        """Observed ``(a, b, c)`` (``a`` the reference master, ``b`` the brightest other master,
        ``c`` the brightest remaining master or, with two cameras, the next brightest star) and
        catalogue triples for it."""
        obs = ctx.obs
        a = masters[ref]
        rest = sorted((m for c, m in masters.items() if c != ref and len(cands[c])))
        b = rest[0]
        if len(rest) >= 2:
            c = rest[1]
        else:
            used = set(masters.values())
            c = next((i for i in range(len(obs)) if i not in used), -1)
            if c < 0:
                return None
        pairs = self._cross_pairs(obs.vec[a], obs.vec[b], cands[ref], cands[int(obs.camera[b])], tol)
        if len(pairs) == 0:
            return None
        cat_a, cat_b = pairs[:, 0], pairs[:, 1]
        # the third star from each candidate pair's attitude (TRIAD on a, b)
        att = _triad_attitudes(obs.vec[a], obs.vec[b], self.vec[cat_a], self.vec[cat_b])
        pred = np.einsum("kji,j->ki", att, obs.vec[c])  # ICRS direction of c
        radius = ctx.verifier.match_radius_px * obs.pixel_scale_rad * 1.5
        dist, cat_c = star_tree(ctx.verifier.db).query(pred, k=1, distance_upper_bound=radius)
        ok = np.isfinite(dist)
        if not ok.any():
            return None
        cat = np.column_stack([cat_a[ok], cat_b[ok], cat_c[ok]]).astype(np.int64)
        return np.array([a, b, c]), cat


def _triad_attitudes(o1: FloatArray, o2: FloatArray, r1: FloatArray, r2: FloatArray) -> FloatArray:
    """ICRS -> body rotations ``(K, 3, 3)`` taking catalogue ``r1``, ``r2`` ``(K, 3)`` onto the
    observed ``o1``, ``o2`` (TRIAD anchored on the first star)."""

    def frame(a: FloatArray, b: FloatArray) -> FloatArray:
        t1 = a / np.linalg.norm(a, axis=-1, keepdims=True)
        t2 = np.cross(a, b)
        t2 /= np.linalg.norm(t2, axis=-1, keepdims=True)
        return np.stack([t1, t2, np.cross(t1, t2)], axis=-1)

    fo = frame(o1[None, :], o2[None, :])[0]
    fr = frame(r1, r2)
    return np.einsum("ij,kaj->kia", fo, fr)
