"""``pso``: a star's shortest closed tour through its neighbours (seed 004, Mao et al.).

Feature of a star: the stars within an angular circle of radius ``r`` around it, and the
shortest closed tour that starts at the star and visits them all. The radius adapts to the sky:
``r0`` (``radius_deg``, 4 deg) by default; fewer than 6 neighbours within ``r0`` -> 5 deg; more
than 25 -> 2.5 deg (keeps 4-25 stars per pattern; the paper gives no base radius: at 6.5 Mv,
4 deg leaves 86% of the stars at ``r0``, 8% go to 5 deg and 6% to 2.5). Stored for every
catalogue star: the tour length (sorted, binary search), the tour's first three stars (the
centre, then the centre's tour neighbour nearer to it, then the next one) with ``d12``, ``d23``
and, for verification, ``d13``; the three magnitudes are read from ``stars/mag`` by id rather
than stored again.

Identification: candidate masters are the brightest stars farther than ``r`` from every image
edge (``max_masters`` of them), tried nearest the image centre first; the master's circle gives
a tour whose length is looked up by binary search, then ``d12``/``d23``, ``d13`` and the
brightness of the three stars filter the records; the survivors go to the shared verifier. On
failure, the next master.

Tour search (``sky_tour``): ``"pso"`` is the paper's hybrid particle swarm (80 particles, 200
iterations, seeded; see ``_tour.pso_tour``); ``"exact"`` is the deterministic tour of
``_tour.best_tours`` (Held-Karp up to 10 stars, else the best of 8 nearest-neighbour starts
improved by 2-opt and or-opt). The catalogue side is always built with the deterministic tour:
the swarm costs ~60 ms per star (~9 minutes for the catalogue) and, on 12+ stars, often stops
short of the shortest tour, so the same stars give different lengths on the two sides (the
paper's failure mode; ``bench/bench_pso.py`` measures how often).

Where the paper is weak, and what ``matching="robust"`` (the default) does instead of
``"paper"``:

- the tour length depends on every star of the circle, and a star within the centroid
  tolerance of the circle's edge is in on one side and out on the other: the sky side also tries
  the tours with those (at most two) boundary stars flipped, then the tours that leave out one
  star of the circle each (a false star, which the catalogue lacks; issue 16: seed 003's camera
  with 2 false stars at 0.5 px, 81 -> 94 of 100 frames, 0 wrong);
- the radius depends on a star count that can differ by one or two between sky and catalogue
  (boundary stars, blends): the catalogue stores a record for every radius the rule would choose
  for counts within ``count_margin`` of its own, so the sky side's choice is always stored;
- the first three stars of a tour change when two tours are nearly as short or the centre's two
  tour neighbours are nearly equidistant, while the length barely moves: the record's ``d12``,
  ``d23``, ``d13`` triangle is searched among all the circle's stars instead of the sky tour's
  own first three, and mirror images are refused (triple-product sign);
- magnitudes only rank candidates (the frame's brightness order against the catalogue's) and
  never reject one: the paper fails when magnitudes leave more than one candidate, we let the
  verifier decide.

Also (both matchings): candidates are screened on the frame's stars within 5 deg of the master
and verified with those as part of the hypothesis (``_grow``): in a 20 deg field the verifier's
own screen, which predicts the brightest stars from the triangle, loses right candidates to the
lever arm. A circle uses every star in it, not only ``ctx.max_stars``; with a rig, each camera's
stars are searched on their own. The observation carries each star's brightness order, not
calibrated magnitudes, so the magnitude check compares the order of the three stars'
brightness with the catalogue's.

Depth (issue 16): the tour runs through every star of the circle, so the catalogue's circle
and the camera's hold the same stars only when the database is built to the camera's own
magnitude limit, which is not part of a request. The table therefore holds the records of
several *cuts* of the database's stars (``depth_steps``, ``DEPTH_STEPS``): every star (the
limit), then the stars to 0.5, 1.0 and 1.5 Mv brighter, each with the circles, radii and tours
its own stars give (:func:`depth_cuts`; cut ``c`` keyed ``c * CUT_STRIDE + ...``, so cut 0 is
the table of one cut of before, and a database built before the cuts, with one, is searched as
before). Every sky circle and variant is looked up in every cut, first the one whose stars
(spread evenly) best match the frame's count (both matchings). With robust matching, a second
pass over the masters meets a frame deeper than a cut: the circles of the master's neighbours
brighter than a threshold (the frame's rows are brightest first), one per threshold the master
passes (``_fainter_left_out``); a frame the first pass names costs no more tours than before.
Every candidate of every cut goes through ``screen_and_grow``, so the verifier's look-elsewhere
factor counts it. Measured (``bench_pso --sections depth``, docs/methods.md; 100 frames, 0 wrong
in every cell): issue 16's 12-17 deg 6.5 Mv database, 12-deg frames to 6.0 Mv, 2% -> 57%; seed
004's camera, frames to 6.0 Mv 16% -> 100%, 5.5 Mv 0% -> 93%, 7.0 Mv 41% -> 99%.

Measured (``bench/bench_pso.py``, docs/methods.md): the deterministic tour makes the catalogue
and the sky agree; the swarm's tours of 11+ stars often do not, which costs the paper variant
its rate and ~10x the time.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from scipy.spatial import cKDTree

from ..camera import Camera
from ..catalog import StarTable
from ..geometry import chord_from_angle, pairwise_angles
from ..navdb.reader import NavDatabase
from ..types import FloatArray, IntArray
from ..verify import Verified
from ._grow import screen_and_grow
from ._tour import best_tours, first_three, pso_tour
from .base import Progress, SolveContext
from .capability import SKY_DEG2

R_SMALL_DEG = 2.5
R_LARGE_DEG = 5.0
FEW = 6
"""Fewer neighbours than this within ``r0``: the circle grows to ``R_LARGE_DEG``."""
MANY = 25
"""More neighbours than this within ``r0``: the circle shrinks to ``R_SMALL_DEG``."""
KEY_STRIDE = 100.0
"""Records are sorted by ``radius code * KEY_STRIDE + tour length (rad)``."""
MAX_CANDIDATES = 64
Variant = tuple[IntArray, int, IntArray, int]
"""A sky circle to look up: its stars (local rows, the master left out), radius code, the stars
its first three may be drawn from, and the batch its tour is searched in."""
DEPTH_STEPS = (0.0, 0.5, 1.0, 1.5)
"""Magnitude cuts of the catalogue the table holds records for, below the database's limit
(``depth_steps``): a camera shallower than the database sees the stars of a cut, not all."""
CUT_STRIDE = 1000.0
"""Cut ``c``'s records are keyed ``c * CUT_STRIDE + radius code * KEY_STRIDE + length``: cut 0
(every star) keeps the keys of a one-cut table, so a reader that knows no cuts reads cut 0."""
MIN_CUT_STARS = 100
"""A cut holding fewer stars than this is not built (nor one holding as many as the last)."""


def radius_code(n_neighbours: np.ndarray | int) -> np.ndarray:
    """Radius code (0: 2.5 deg, 1: r0, 2: 5 deg) chosen for a neighbour count within r0."""
    n = np.asarray(n_neighbours)
    return np.where(n < FEW, 2, np.where(n > MANY, 0, 1))


def angle_matrices(vec: FloatArray) -> FloatArray:
    """Pairwise angles ``(B, n, n)`` of unit vectors ``(B, n, 3)``."""
    diff = vec[:, :, None, :] - vec[:, None, :, :]
    chord = np.sqrt(np.einsum("bijk,bijk->bij", diff, diff))
    return 2.0 * np.arcsin(np.clip(chord / 2.0, 0.0, 1.0))


def depth_cuts(mag: FloatArray, limit: float, steps: list[float]) -> tuple[list[float], list[IntArray]]:
    """The magnitude cuts a table is built for, and each one's star rows: every star first
    (the database's own limit), then the stars to ``limit - step`` for each further step;
    a cut of fewer than ``MIN_CUT_STARS`` stars, or no fewer than the cut before, is left out."""
    if not steps or steps[0] != 0.0 or any(b <= a for a, b in zip(steps, steps[1:], strict=False)):
        raise ValueError(f"pso depth_steps {steps!r}: expected 0 first, then increasing steps")
    cuts, subsets = [limit], [np.arange(len(mag), dtype=np.int64)]
    for step in steps[1:]:
        keep = np.flatnonzero(mag <= limit - step)
        if len(keep) < MIN_CUT_STARS or len(keep) >= len(subsets[-1]):
            continue
        cuts.append(round(limit - step, 6))
        subsets.append(keep)
    return cuts, subsets


def tour_records(vec: FloatArray, radii: tuple[float, float, float], margin: int, progress: Progress
                 ) -> tuple[IntArray, FloatArray, IntArray, FloatArray, IntArray]:
    """The tour records of the stars ``vec`` ``(N, 3)``: for every star and every radius the
    rule picks for its neighbour count within ``margin``, the radius code, the tour length,
    the tour's first three stars (rows of ``vec``), their sides and the circle's star count."""
    tree = cKDTree(vec)
    progress("neighbours", 0.0)
    neigh = [tree.query_ball_point(vec, float(chord_from_angle(math.radians(r)))) for r in radii]
    n0 = np.array([len(x) - 1 for x in neigh[1]])
    codes = np.stack([radius_code(n0 + k) for k in range(-margin, margin + 1)], axis=1)
    centre, code, members = [], [], []
    for i in range(len(vec)):
        for c in np.unique(codes[i]):
            mem = [j for j in neigh[int(c)][i] if j != i]
            if len(mem) >= 2:
                centre.append(i)
                code.append(int(c))
                members.append(np.asarray(mem, np.int64))
    size = np.array([len(m) for m in members], np.int64)
    n_rec = len(centre)
    length = np.zeros(n_rec)
    ids = np.zeros((n_rec, 3), np.int64)
    sides = np.zeros((n_rec, 3))
    centre_a = np.asarray(centre, np.int64)
    done = 0
    for k in np.unique(size):
        rows = np.flatnonzero(size == k)
        for lo in range(0, len(rows), 4096):
            part = rows[lo:lo + 4096]
            nodes = np.column_stack([centre_a[part], np.stack([members[r] for r in part])])
            d = angle_matrices(vec[nodes])
            order, tour_len = best_tours(d)
            s2, s3 = first_three(d, order)
            b = np.arange(len(part))
            length[part] = tour_len
            ids[part] = np.column_stack([nodes[:, 0], nodes[b, s2], nodes[b, s3]])
            sides[part] = np.column_stack([d[b, 0, s2], d[b, s2, s3], d[b, 0, s3]])
            done += len(part)
            progress(f"tours ({k + 1} stars)", done / max(n_rec, 1))
    return np.asarray(code, np.int64), length, ids, sides, size


class Pso:
    name = "pso"
    summary = "shortest closed tour of a star's neighbours, hybrid particle swarm (seed 004)"

    def build_tables(
        self, stars: StarTable, config: Any, params: dict[str, Any], progress: Progress
    ) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
        r0 = float(params.get("radius_deg", 4.0))
        margin = int(params.get("count_margin", 2))
        radii = (R_SMALL_DEG, r0, R_LARGE_DEG)
        limit = float(getattr(config, "mag_limit", float(np.max(stars.mag, initial=0.0))))
        cuts, subsets = depth_cuts(np.asarray(stars.mag, np.float64), limit,
                                   [float(x) for x in params.get("depth_steps", DEPTH_STEPS)])
        keys, ids, sides, sizes = [], [], [], []
        total = sum(len(k) for k in subsets)
        done = 0
        for c, keep in enumerate(subsets):
            def sub(stage: str, frac: float, c: int = c, base: int = done, n: int = len(keep)) -> None:
                progress(f"cut {cuts[c]:g} Mv: {stage}", (base + frac * n) / max(total, 1))
            code, length, ids_c, sides_c, size_c = tour_records(stars.vec[keep], radii, margin, sub)
            keys.append(c * CUT_STRIDE + code * KEY_STRIDE + length)
            ids.append(keep[ids_c])
            sides.append(sides_c)
            sizes.append(size_c)
            done += len(keep)
        key = np.concatenate(keys)
        size = np.concatenate(sizes)
        order_k = np.argsort(key, kind="stable")
        tables: dict[str, np.ndarray] = {
            "key": key[order_k],
            "ids": np.concatenate(ids)[order_k].astype(np.int32),
            "sides": np.concatenate(sides)[order_k].astype(np.float32),
            "size": size[order_k].astype(np.uint8 if size.max(initial=0) < 256 else np.uint16),
        }
        n_rec = len(key)
        meta: dict[str, Any] = {
            "radius_deg": r0, "radii_deg": list(radii), "few": FEW, "many": MANY, "count_margin": margin,
            "n_records": int(n_rec), "sky_tour": str(params.get("sky_tour", "exact")),
            "matching": str(params.get("matching", "robust")),
            "max_masters": int(params.get("max_masters", 8)),
            "cuts_mag": cuts, "cut_stars": [len(k) for k in subsets], "cut_records": [len(k) for k in keys],
            "cut_stride": CUT_STRIDE,
        }
        progress(f"{n_rec} tours", 1.0)
        return tables, meta

    def matcher(self, db: NavDatabase) -> PsoMatcher:
        return PsoMatcher(db)


class PsoMatcher:
    """Solver over the ``pso`` tables; ``sky_tour``/``matching``/``max_masters`` default to the
    values the database was built with (see the module docstring)."""

    def __init__(self, db: NavDatabase, *, sky_tour: str | None = None, matching: str | None = None,
                 max_masters: int | None = None, particles: int = 80, iterations: int = 200,
                 seed: int = 0) -> None:
        t = db.tables["pso"]
        prm = db.method_params("pso")
        self.key, self.ids, self.sides = t["key"], t["ids"], t["sides"]
        self.radii = [math.radians(r) for r in prm["radii_deg"]]
        self.sky_tour = sky_tour or prm.get("sky_tour", "exact")
        self.matching = matching or prm.get("matching", "robust")
        self.max_masters = int(max_masters or prm.get("max_masters", 8))
        if self.sky_tour not in ("exact", "pso") or self.matching not in ("paper", "robust"):
            raise ValueError(f"pso: unknown variant {self.sky_tour!r}/{self.matching!r}")
        self.particles, self.iterations, self.seed = particles, iterations, seed
        self.vec = db.stars.vec
        self.mag = np.asarray(db.stars.mag, np.float64)
        self.tours = 0  # tours searched (diagnostics)
        self.candidates = 0  # candidate triples handed to screen_and_grow, every cut's (diagnostics)
        self.cuts = [float(c) for c in prm.get("cuts_mag", [db.mag_limit])]
        self.cut_stars = [int(n) for n in prm.get("cut_stars", [len(db.stars)])]
        self.cut_stride = float(prm.get("cut_stride", CUT_STRIDE))

    # ---- sky side ----------------------------------------------------------------------------
    def identify(self, ctx: SolveContext) -> Verified | None:
        obs = ctx.obs
        for c, rows in enumerate(obs.by_camera):
            if len(rows) < 3:
                continue
            v_cam = obs.vec[rows] @ np.asarray(obs.mountings[c]).T
            edge = edge_distance(obs.cameras[c], v_cam)
            d = pairwise_angles(obs.vec[rows])
            eligible = np.flatnonzero(edge > self.radii[1])[: self.max_masters]
            off_axis = np.arccos(np.clip(v_cam[eligible, 2], -1.0, 1.0))
            cuts = self.cut_order(obs.cameras[c], len(rows))
            # the circles as seen, then (a table with cuts, robust matching) those of a frame
            # deeper than a cut: every master's first, so a frame the first pass names costs
            # no more tours than before the cuts
            deeper = (False, True) if len(self.cuts) > 1 and self.matching == "robust" else (False,)
            for fainter in deeper:
                for m in eligible[np.argsort(off_axis, kind="stable")]:
                    if ctx.expired():
                        return None
                    found = self._try_master(ctx, rows, d, edge, int(m), cuts, fainter)
                    if found is not None:
                        return found
        return None

    def cut_order(self, camera: Camera, n_observed: int) -> list[int]:
        """The magnitude cuts to search, the one whose catalogue stars (spread evenly over the
        sky) best match the ``n_observed`` stars of ``camera``'s frame first, then by how far
        off they are (ties: the deeper first)."""
        if len(self.cuts) == 1:
            return [0]
        area = camera.fov_deg * camera.fov_y_deg / SKY_DEG2
        off = [abs(math.log(max(n * area, 1e-9) / max(n_observed, 1))) for n in self.cut_stars]
        return sorted(range(len(self.cuts)), key=lambda k: (off[k], k))

    def _try_master(self, ctx: SolveContext, rows: IntArray, d: FloatArray, edge: FloatArray,
                    m: int, cuts: list[int], fainter: bool = False) -> Verified | None:
        """Master ``m``'s circle and its variants, their tours looked up in each of ``cuts``;
        ``fainter``: instead, the circles without the stars fainter than a threshold."""
        dm = d[m]
        others = np.flatnonzero(np.arange(len(dm)) != m)
        code = int(radius_code(int((dm[others] <= self.radii[1]).sum())))
        r = self.radii[code]
        if edge[m] <= r:
            return None
        tol = ctx.tol_rad
        inside = others[dm[others] <= r]
        on_edge = others[np.abs(dm[others] - r) <= tol]  # in on one side, out on the other
        pool = np.union1d(inside, on_edge)
        variants: list[Variant] = [(inside, code, pool, 0)]
        if self.matching == "robust":
            near = on_edge[np.argsort(np.abs(dm[on_edge] - r), kind="stable")][:2]
            for flip in range(1, 1 << len(near)):
                flipped = {int(near[b]) for b in range(len(near)) if flip >> b & 1}
                members = np.array(sorted(set(inside.tolist()) ^ flipped), np.int64)
                variants.append((members, code, pool, flip))
            # a star the catalogue lacks (a false star) in the circle: the tour without it (one
            # batch: the local search is vectorised over it, 2-9x faster than one tour at a time)
            variants += [(np.delete(inside, k), code, pool, 4) for k in range(len(inside))]
        if fainter:
            variants = self._fainter_left_out(dm, others, edge[m], m, tol, variants)
        tours: dict[int, tuple[float, int, int]] = {}
        for i, (members, code_i, pool_i, batch) in enumerate(variants):
            if len(members) < 2 or ctx.expired():
                continue
            nodes = np.concatenate([[m], members])
            if i not in tours:
                todo = [j for j, v in enumerate(variants) if v[3] == batch and len(v[0]) >= 2]
                tours.update(zip(todo, self._tours(d, m, [variants[j][0] for j in todo]), strict=True))
            length, s2, s3 = tours[i]
            for cut in cuts:  # each tour in every cut: it is the tour's cost, not the look-up's
                win = self._window(code_i, length, len(nodes), tol, cut)
                if len(win) == 0:
                    continue
                if self.matching == "paper":
                    found = self._paper(ctx, rows, d, m, nodes[s2], nodes[s3], win)
                else:
                    found = self._robust(ctx, rows, d, m, pool_i, win)
                if found is not None:
                    return found
        return None

    def _fainter_left_out(self, dm: FloatArray, others: IntArray, edge: float, m: int, tol: float,
                          have: list[Variant]) -> list[Variant]:
        """The circles of a frame deeper than a cut: the master's neighbours brighter than a
        threshold (rows are brightest first), for every threshold the master itself passes,
        each with the radius its own count picks; those the list ``have`` lacks."""
        near5 = others[dm[others] <= self.radii[2] + tol]  # every star a circle or its edge can hold
        seen = {tuple(v[0].tolist()) for v in have}
        out = []
        for t in range(len(near5) - 1, 1, -1):
            if m > near5[t]:
                break  # the master is fainter than a star this threshold leaves out
            kept = near5[:t]
            code = int(radius_code(int((dm[kept] <= self.radii[1]).sum())))
            r = self.radii[code]
            if edge <= r:
                continue
            members = kept[dm[kept] <= r]
            if len(members) < 2 or tuple(members.tolist()) in seen:
                continue
            seen.add(tuple(members.tolist()))
            out.append((members, code, np.union1d(members, kept[np.abs(dm[kept] - r) <= tol]), 5 + t))
        return out

    def _tours(self, d: FloatArray, m: int, sets: list[IntArray]) -> list[tuple[float, int, int]]:
        """Tours from master ``m`` through each of ``sets`` (equally many stars each): length,
        and the nodes (positions in ``[m, *set]``) of the tour's second and third stars."""
        nodes = np.array([np.concatenate([[m], s]) for s in sets])
        dn = d[nodes[:, :, None], nodes[:, None, :]]
        self.tours += len(sets)
        if self.sky_tour == "pso":
            got = [pso_tour(x, particles=self.particles, iterations=self.iterations, rng=self.seed)
                   for x in dn]
            order, lengths = np.array([g[0] for g in got]), np.array([g[1] for g in got])
        else:
            order, lengths = best_tours(dn)
        s2, s3 = first_three(dn, order)
        return [(float(a), int(b), int(c)) for a, b, c in zip(lengths, s2, s3, strict=True)]

    def _window(self, code: int, length: float, n_nodes: int, tol: float, cut: int = 0) -> IntArray:
        """Records of magnitude cut ``cut`` and radius ``code`` whose tour length is within
        tolerance of ``length``: each of the ``n_nodes`` stars moves the length by at most
        ~``tol``, independently."""
        tol_len = tol * math.sqrt(n_nodes)
        base = cut * self.cut_stride + code * KEY_STRIDE + length
        lo, hi = np.searchsorted(self.key, [base - tol_len, base + tol_len])
        return np.arange(lo, hi)

    def _paper(self, ctx: SolveContext, rows: IntArray, d: FloatArray, m: int, j: int, k: int,
               win: IntArray) -> Verified | None:
        """The paper's cascade: d12 and d23, then d13, then magnitudes; only a unique survivor is
        verified."""
        tol = ctx.tol_rad
        s = self.sides[win]
        cand = win[(np.abs(s[:, 0] - d[m, j]) <= tol) & (np.abs(s[:, 1] - d[j, k]) <= tol)]
        if len(cand) > 1:
            cand = cand[np.abs(self.sides[cand, 2] - d[m, k]) <= tol]
        if len(cand) > 1:
            disc = self._discordance(np.array([m, j, k]), self.ids[cand])
            cand = cand[disc == disc.min()]
        if len(cand) != 1:
            return None
        return self._verify(ctx, rows, d, np.array([m, j, k]), self.ids[cand].astype(np.int64))

    def _robust(self, ctx: SolveContext, rows: IntArray, d: FloatArray, m: int, pool: IntArray,
                win: IntArray) -> Verified | None:
        """Every record of the window whose d12/d23/d13 triangle (same handedness) appears
        anywhere among the circle's stars, grouped by the observed stars it lands on."""
        tol = ctx.tol_rad
        s = self.sides[win].astype(np.float64)
        dj = d[m, pool]
        hit1 = np.abs(s[:, 0, None] - dj[None, :]) <= tol  # (W, J): star 2 candidates
        hit3 = np.abs(s[:, 2, None] - dj[None, :]) <= tol  # star 3 candidates
        djk = d[np.ix_(pool, pool)]
        hit2 = np.abs(s[:, 1, None, None] - djk[None]) <= tol  # (W, J, J): side 2-3
        w, a, b = np.nonzero(hit1[:, :, None] & hit3[:, None, :] & hit2)
        if len(w) == 0:
            return None
        cat = self.ids[win[w]].astype(np.int64)
        obs3 = np.column_stack([np.full(len(w), m), pool[a], pool[b]])
        ov = ctx.obs.vec[rows[obs3]]
        cv = self.vec[cat]
        s_obs = np.sign(np.einsum("ij,ij->i", ov[:, 0], np.cross(ov[:, 1], ov[:, 2])))
        s_cat = np.sign(np.einsum("ij,ij->i", cv[:, 0], np.cross(cv[:, 1], cv[:, 2])))
        keep = s_obs == s_cat
        obs3, cat = obs3[keep], cat[keep]
        if len(cat) == 0:
            return None
        pair_key = obs3[:, 1] * len(rows) + obs3[:, 2]
        for key in np.unique(pair_key):
            sel = np.flatnonzero(pair_key == key)
            tri = obs3[sel[0]]
            cands = cat[sel]
            if len(cands) > MAX_CANDIDATES:
                continue
            cands = cands[np.argsort(self._discordance(tri, cands), kind="stable")]
            found = self._verify(ctx, rows, d, tri, cands)
            if found is not None:
                return found
        return None

    def _verify(self, ctx: SolveContext, rows: IntArray, d: FloatArray, tri: IntArray,
                cands: IntArray) -> Verified | None:
        """Screen candidate triples ``cands`` ``(K, 3)`` for the observed triangle ``tri`` (local
        indices) on the stars within 5 deg of the master, and verify the best ones with the
        stars that screened as part of the hypothesis (``_grow.screen_and_grow``).

        The verifier's own screen predicts the frame's brightest stars: in a 20 deg field
        those lie up to 15 deg from a triangle a degree or two across, and 1 px of centroid
        noise tilts such an attitude by several pixels out there, so right candidates fail the
        screen. Stars within 5 deg of the master screen reliably, and a hypothesis spanning
        them fits an attitude good enough for the verifier to extend over the whole field.
        """
        near = np.flatnonzero(d[tri[0]] <= self.radii[2])
        self.candidates += len(cands)
        return screen_and_grow(ctx, rows[tri], cands, rows[near])

    def _discordance(self, obs_tri: IntArray, cat: IntArray) -> IntArray:
        """How many of the three star pairs are ordered differently by brightness in the frame
        (observation rows are brightest first) and by catalogue magnitude; ``(K,)`` in 0..3."""
        cat = np.asarray(cat).reshape(-1, 3)
        mag = self.mag[cat]
        out = np.zeros(len(cat), np.int64)
        for a, b in ((0, 1), (0, 2), (1, 2)):
            brighter_obs = obs_tri[a] < obs_tri[b]
            out += (mag[:, a] < mag[:, b]) != brighter_obs
        return out


def edge_distance(camera: Camera, v_cam: FloatArray) -> FloatArray:
    """Angular distance (radians) of camera-frame unit vectors ``(N, 3)`` from the nearest image
    edge (positive inside). An edge of a pinhole image is a great circle through the camera
    centre and two corners."""
    w, h = camera.width - 0.5, camera.height - 0.5
    corners = camera.pixel_to_vector(np.array([[-0.5, -0.5], [w, -0.5], [w, h], [-0.5, h]]))
    normals = np.cross(corners, np.roll(corners, -1, axis=0))
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    normals *= np.sign(normals[:, 2])[:, None]  # the boresight is inside
    return np.arcsin(np.clip(v_cam @ normals.T, -1.0, 1.0)).min(axis=1)
