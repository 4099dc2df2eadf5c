"""``dmv``: distance-mapping vectors and cyclic angle features (seed 003).

Pattern of a star: its neighbours within radius ``R`` in counter-clockwise order around it
(right-handed about the star's direction, the same sense in the sky and in the camera frame);
``D_i`` the angular distance of neighbour ``i``, ``Phi_i`` the angle at the star between
neighbours ``i`` and ``i + 1`` (the ``Phi`` sum to 360 deg). Both vectors start at the nearest
neighbour. Distance-mapping vector ``Lambda``: ``N_D`` bits, bit ``floor(D_i / (R / N_D))``
set for every neighbour; the observed one adds the anti-interference code (also bit ``T + 1``
when ``D_i / (R / N_D)`` lies within ``zeta_1`` of its bin's upper edge, ``T - 1`` near the
lower edge).

Identification: the reference star is the observed star nearest the image centre.
1. Dispersion ``X = n_cat - popcount(lambda_obs AND Lambda_cat)``; candidates have
   ``X <= floor(m / 3) + 1`` (``m`` observed neighbours).
2. For one observed pair ``(d_i, phi_i)``: candidates holding some ``(D_j, Phi_j)`` with
   ``|d_i - D_j| <= zeta_2`` and ``|phi_i - Phi_j| <= zeta_3``; both vectors are shifted to
   start there.
3. Cumulative angles ``eps_k = phi_i + ... + phi_{i+k-1}`` and ``E_l`` likewise; similarity
   ``P`` = greedy in-order (two-pointer) matches ``|eps_k - E_l| <= zeta_4``.
4. Highest ``P`` wins; below the threshold, retry from the next ``(d_i, phi_i)``.
The winner's reference star, start neighbour and best-placed matched neighbour form a
triangle hypothesis that the shared verifier proves or refuses.

Tables: ``offsets`` ``(N + 1,)`` int64 into the CSR arrays ``nb`` (neighbour rows, int32),
``dist`` (``D``, rad, float32) and ``phi`` (``Phi``, rad, float32), each star's run in CCW
order from its nearest neighbour; ``lam`` ``(N_D / 64, N)`` uint64, word-major packed
``Lambda``.

``variant="paper"`` is the reading above with fixed thresholds (``zeta_3 = zeta_4`` = the angle
a position error of one tolerance makes at a quarter of ``R``, ``P >= m / 3``, one reference
star). ``variant="improved"`` (default) fixes what the paper leaves weak (measured in
docs/methods.md):

- **Truncated pattern.** The reference star is seldom at the exact centre, so its ``R`` circle
  leaves the image and its outer neighbours go unseen, which the paper's dispersion counts as
  misses. The improved variant uses ``R_eff`` = min(``R``, the reference star's distance to the
  image edge) on both sides: observed neighbours within ``R_eff``, catalogue bits and
  neighbours below ``R_eff``.
- **Distance-aware angles.** A position error ``sigma`` moves the angle of a neighbour at
  ``D`` by ``sigma / D``; fixed ``zeta_3``/``zeta_4`` are either too tight for near neighbours
  or too loose for far ones. The improved match demands ``|d - D| <= zeta_2`` *and* an angle
  within ``tol / d + tol / D`` of the cumulative angle (a 2-D position match), counted
  vectorised over all neighbour pairs.
- **Symmetric dispersion.** ``X`` counts catalogue neighbours the frame lacks, so every
  catalogue star with few neighbours passes; the improved filter also bounds the observed
  neighbours that find no catalogue bit by ``floor(m / 3) + 1``.
- **All start pairs, several reference stars.** The farthest observed neighbours (sharpest
  angles) are tried as starts in one vectorised pass and the alignments ranked by ``P``; the
  best few go to the verifier. When the reference star yields nothing, the next star nearest
  the centre takes over; when the centre is empty (no circle inside the image holds enough
  stars), the full circle ``R`` is matched on the observed side only; so is every reference
  star when none is proven: a database deeper than the camera puts neighbours in the
  catalogue's circle that the frame cannot see, which the dispersion counts as misses (issue
  16: a 6.5 Mv database, seed 003's camera at 6.0 Mv: 38 of 60 frames before, 60 of 60 after).
  Matched on the observed side only, thousands of catalogue stars tie (their bits cover the
  few observed ones); the ``MAX_CANDIDATES`` kept are those with the fewest unmatched catalogue
  neighbours, not the first rows (the issue's database, 12-deg frames to 6.0 Mv with 2 false
  stars: the true star was in none of the tied lists of the 6 frames lost; 2 lost after).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from ..catalog import StarTable
from ..geometry import cross
from ..navdb.reader import NavDatabase
from ..verify import Verified
from ._dmv_vote import vote
from ._pairs import build_pair_table
from .base import Progress, SolveContext

TWO_PI = 2 * math.pi
MAX_REFERENCES = 4
"""``improved``: reference stars tried, nearest the image centre first."""
MAX_CANDIDATES = 128
"""``improved``: at most this many catalogue candidates (the least dispersed) per reference."""
MAX_PATTERN = 24
"""``improved``: in a dense field the circle shrinks to hold this many observed neighbours."""
START_NEIGHBOURS = 4
"""``improved``: observed neighbours (the farthest, whose angles are sharpest) tried as the start
of the cyclic alignment."""
MAX_VERIFY = 6
"""``improved``: best-ranked (candidate, start) alignments handed to the verifier per reference."""


def position_angles(centre: np.ndarray, nbrs: np.ndarray) -> np.ndarray:
    """Angles (rad, [0, 2 pi)) of unit vectors ``nbrs`` ``(n, 3)`` around ``centre`` ``(3,)``,
    counter-clockwise by the right-hand rule about ``centre``, from an arbitrary zero."""
    ref = np.array([1.0, 0.0, 0.0]) if abs(centre[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    e1 = cross(centre[None, :], ref[None, :])[0]
    e1 /= np.linalg.norm(e1)
    e2 = cross(centre[None, :], e1[None, :])[0]
    return np.mod(np.arctan2(nbrs @ e2, nbrs @ e1), TWO_PI)


def star_pattern(dist: np.ndarray, theta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Order of neighbours CCW starting at the nearest one, and the gaps ``Phi`` (rad) between
    consecutive ones (the last wraps to the first)."""
    order = np.argsort(theta, kind="stable")
    start = int(np.argmin(dist[order]))
    order = np.roll(order, -start)
    th = theta[order]
    phi = np.mod(np.roll(th, -1) - th, TWO_PI)
    if len(th) == 1:
        phi[:] = TWO_PI
    return order, phi


def map_bits(dist: np.ndarray, bin_rad: float, n_bins: int, zeta1: float = 0.0) -> np.ndarray:
    """Bits of a distance-mapping vector: ``floor(D / bin)``, plus the neighbouring bin when
    ``D / bin`` lies within ``zeta1`` of a bin edge (the anti-interference code)."""
    t = dist / bin_rad
    base = np.floor(t).astype(np.int64)
    frac = t - base
    bits = [base, base[frac >= 1 - zeta1] + 1, base[frac <= zeta1] - 1] if zeta1 > 0 else [base]
    allb = np.concatenate(bits)
    return np.unique(allb[(allb >= 0) & (allb < n_bins)])


def pack_bits(bits: np.ndarray, n_bins: int) -> np.ndarray:
    """One packed vector ``(n_bins / 64,)`` uint64 from bit indices."""
    out = np.zeros(-(-n_bins // 64), dtype=np.uint64)
    np.bitwise_or.at(out, bits >> 6, np.left_shift(np.uint64(1), (bits & 63).astype(np.uint64)))
    return out


def greedy_similarity(eps: np.ndarray, big_e: np.ndarray, zeta4: float) -> tuple[int, list[tuple[int, int]]]:
    """The paper's two-pointer similarity: in-order matches ``|eps_i - E_j| <= zeta4``; returns
    ``P`` and the matched index pairs."""
    pairs: list[tuple[int, int]] = []
    j0 = 0
    for i, e in enumerate(eps):
        for j in range(j0, len(big_e)):
            if abs(e - big_e[j]) <= zeta4:
                pairs.append((i, j))
                j0 = j + 1
                break
    return len(pairs), pairs


class Dmv:
    name = "dmv"
    summary = "distance-mapping vectors, cyclic angle features and cumulative-angle similarity (seed 003)"

    def build_tables(
        self, stars: StarTable, config: Any, params: dict[str, Any], progress: Progress
    ) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
        radius_deg = float(params.get("radius_deg", config.fov_min_deg / 2))
        n_bins = int(params.get("n_bins", 128))
        radius = math.radians(radius_deg)
        vec = stars.vec
        n = len(vec)
        progress("star pairs", 0.0)
        pairs, angles = build_pair_table(vec, radius)
        a = np.concatenate([pairs[:, 0], pairs[:, 1]]).astype(np.int64)
        b = np.concatenate([pairs[:, 1], pairs[:, 0]]).astype(np.int64)
        d = np.concatenate([angles, angles])
        order = np.lexsort((d, a))
        a, b, d = a[order], b[order], d[order]
        offsets = np.searchsorted(a, np.arange(n + 1)).astype(np.int64)
        nb = np.empty(len(a), np.int32)
        dist = np.empty(len(a), np.float32)
        phi = np.empty(len(a), np.float32)
        bin_rad = radius / n_bins
        lam = np.zeros((-(-n_bins // 64), n), dtype=np.uint64)
        for s in range(n):
            if s % 500 == 0:
                progress("patterns", 0.1 + 0.9 * s / n)
            lo, hi = offsets[s], offsets[s + 1]
            if lo == hi:
                continue
            theta = position_angles(vec[s], vec[b[lo:hi]])
            o, gaps = star_pattern(d[lo:hi], theta)
            nb[lo:hi] = b[lo:hi][o]
            dist[lo:hi] = d[lo:hi][o]
            phi[lo:hi] = gaps
            lam[:, s] = pack_bits(map_bits(d[lo:hi], bin_rad, n_bins), n_bins)
        progress(f"{n} patterns, {len(nb)} neighbours", 1.0)
        tables: dict[str, np.ndarray] = {"offsets": offsets, "nb": nb, "dist": dist, "phi": phi, "lam": lam}
        meta: dict[str, Any] = {"radius_deg": radius_deg, "n_bins": n_bins, "n_neighbours": int(len(nb))}
        return tables, meta

    def matcher(self, db: NavDatabase) -> DmvMatcher:
        return DmvMatcher(db)


class DmvMatcher:
    """DMV matcher over one database; ``variant`` is ``"improved"`` or ``"paper"``."""

    def __init__(self, db: NavDatabase, *, variant: str = "improved") -> None:
        t = db.tables["dmv"]
        prm = db.method_params("dmv")
        if variant not in ("improved", "paper"):
            raise ValueError(f"dmv: unknown variant {variant!r}")
        self.variant = variant
        self.offsets = np.asarray(t["offsets"])
        self.nb, self.dist, self.phi = t["nb"], t["dist"], t["phi"]
        self.lam = t["lam"]
        self.vec = db.stars.vec
        self.radius = math.radians(prm["radius_deg"])
        self.n_bins = int(prm["n_bins"])
        self.bin_rad = self.radius / self.n_bins
        self.n_nb = np.diff(self.offsets)

    # -- the observed pattern ------------------------------------------------------------------
    def observed_pattern(self, ctx: SolveContext, ref: int,
                         radius: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Neighbour rows, distances and CCW position angles of observed star ``ref`` within
        ``radius``, in the paper's order (CCW from the nearest)."""
        v = ctx.obs.vec
        chord = np.linalg.norm(v - v[ref], axis=1)
        d = 2 * np.arcsin(np.minimum(chord / 2, 1.0))
        rows = np.flatnonzero((d < radius) & (np.arange(len(v)) != ref))
        if len(rows) == 0:
            return rows, d[rows], d[rows]
        theta = position_angles(v[ref], v[rows])
        order, _ = star_pattern(d[rows], theta)
        return rows[order], d[rows][order], theta[order]

    def reference_stars(self, ctx: SolveContext) -> list[tuple[int, float]]:
        """Observed stars nearest their image centre first, with the angular distance to the
        nearest image edge."""
        obs = ctx.obs
        out = []
        for i in range(len(obs)):
            cam = obs.cameras[int(obs.camera[i])]
            x, y = obs.xy[i]
            edge_px = min(x + 0.5, cam.width - 0.5 - x, y + 0.5, cam.height - 0.5 - y)
            centre_px = math.hypot(x - cam.cx, y - cam.cy)
            out.append((centre_px, i, max(edge_px, 0.0) * cam.pixel_scale_rad))
        out.sort()
        return [(i, edge) for _, i, edge in out]

    # -- step 1: dispersion ----------------------------------------------------------------------
    def dispersion_candidates(self, d_obs: np.ndarray, eps: float, r_eff: float | None,
                              symmetric: bool = False, catalogue_side: bool = True) -> np.ndarray:
        """Catalogue stars with ``X <= floor(m / 3) + 1``; with ``r_eff`` only the bins below it
        count on the catalogue side (the truncated pattern); ``symmetric`` also demands that at
        most ``floor(m / 3) + 1`` *observed* neighbours find no catalogue bit (the paper's
        ``X`` alone lets every catalogue star with few neighbours through)."""
        m = len(d_obs)
        zeta1 = min(0.5, eps / self.bin_rad)
        bits = map_bits(d_obs, self.bin_rad, self.n_bins, zeta1)
        words = np.unique(bits >> 6)
        obs = pack_bits(bits, self.n_bins)[words]
        b = np.bitwise_count(self.lam[words] & obs[:, None]).sum(axis=0, dtype=np.int64)
        if r_eff is None:
            n_cat = self.n_nb
        else:
            top = min(int(r_eff / self.bin_rad), self.n_bins)  # bins [0, top) are visible
            mask = pack_bits(np.arange(top), self.n_bins)
            n_cat = np.bitwise_count(self.lam & mask[:, None]).sum(axis=0, dtype=np.int64)
        allowed = m // 3 + 1
        x = n_cat - b if catalogue_side else np.zeros(len(n_cat), np.int64)
        if symmetric:
            missed = np.zeros(len(n_cat), np.int64)
            for dk in d_obs:  # observed neighbours with no catalogue bit in their window
                wb = map_bits(np.array([dk]), self.bin_rad, self.n_bins, zeta1)
                ww = np.unique(wb >> 6)
                hit = (self.lam[ww] & pack_bits(wb, self.n_bins)[ww][:, None]).any(axis=0)
                missed += ~hit
            rows = np.flatnonzero((x <= allowed) & (missed <= allowed))
            if len(rows) > MAX_CANDIDATES:  # the least dispersed first
                # ties (every catalogue star whose bits cover the observed ones, when only the
                # observed side counts) go to the fewest unmatched catalogue neighbours
                rows = rows[np.lexsort(((n_cat - b)[rows], x[rows] + missed[rows]))[:MAX_CANDIDATES]]
            return rows
        return np.flatnonzero(x <= allowed)

    # -- identification ------------------------------------------------------------------------
    def identify(self, ctx: SolveContext) -> Verified | None:
        if len(ctx.obs) < 3:
            return None
        refs = self.reference_stars(ctx)
        if self.variant == "paper":
            return self._identify_paper(ctx, refs[0][0])
        starved = []
        for ref, edge in refs[:MAX_REFERENCES]:
            if ctx.expired():
                break
            r_eff = min(self.radius, edge + ctx.tol_rad)
            if len(self.observed_pattern(ctx, ref, r_eff)[0]) < 3:
                starved.append(ref)
                continue
            found = self._identify_improved(ctx, ref, r_eff)
            if found is not None:
                return found
        # an empty centre (the circle inside the image holds too few stars), or a database deeper
        # than the camera (the catalogue's extra neighbours fail the dispersion): match the
        # observed neighbours within R against whatever the catalogue holds (observed side only)
        for ref in starved + [r for r, _ in refs[:MAX_REFERENCES] if r not in starved]:
            if ctx.expired():
                break
            found = self._identify_improved(ctx, ref, self.radius, complete=False)
            if found is not None:
                return found
        return None

    def _catalogue_pattern(self, s: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        lo, hi = self.offsets[s], self.offsets[s + 1]
        return np.asarray(self.nb[lo:hi], np.int64), np.asarray(self.dist[lo:hi], np.float64), \
            np.asarray(self.phi[lo:hi], np.float64)

    def _identify_paper(self, ctx: SolveContext, ref: int) -> Verified | None:
        eps = ctx.tol_rad
        rows, d_obs, theta = self.observed_pattern(ctx, ref, self.radius)
        m = len(rows)
        if m < 2:
            return None
        phi_obs = np.mod(np.roll(theta, -1) - theta, TWO_PI)
        zeta_ang = eps / (self.radius / 4)
        cands = self.dispersion_candidates(d_obs, eps, None)
        p_min = max(2, math.ceil(m / 3))
        for i in range(m):  # retry from the next (d_i, phi_i) while the best P is too low
            if ctx.expired():
                break
            best: tuple[int, int, int, list[tuple[int, int]]] | None = None
            eps_cum = np.cumsum(np.roll(phi_obs, -i))[:-1]
            for s in cands:
                nb, dist, phi = self._catalogue_pattern(int(s))
                close = (np.abs(dist - d_obs[i]) <= eps) & (np.abs(phi - phi_obs[i]) <= zeta_ang)
                hit = np.flatnonzero(close)
                for start in hit:
                    e_cum = np.cumsum(np.roll(phi, -start))[:-1]
                    p, pairs = greedy_similarity(eps_cum, e_cum, zeta_ang)
                    if best is None or p > best[0]:
                        best = (p, int(s), int(start), pairs)
            if best is None or best[0] < p_min:
                continue
            _, star, j, pairs = best
            nb, _, _ = self._catalogue_pattern(star)
            k, l_ = pairs[len(pairs) // 2]  # a matched neighbour halfway round: a wide triangle
            obs_idx = np.array([ref, rows[i], rows[(i + k + 1) % m]])
            cat_idx = np.array([star, nb[j], nb[(j + l_ + 1) % len(nb)]])
            found = ctx.verifier.check(obs_idx, cat_idx)
            if found is not None:  # a refused winner is treated like a low P: next (d_i, phi_i)
                return found
        return None

    def _identify_improved(self, ctx: SolveContext, ref: int, r_eff: float, *,
                           complete: bool = True) -> Verified | None:
        """One reference star; ``complete``: the circle ``r_eff`` lies inside the image, so
        the catalogue side of the dispersion counts too."""
        eps = ctx.tol_rad
        rows, d_obs, theta = self.observed_pattern(ctx, ref, r_eff)
        if len(rows) > MAX_PATTERN:  # dense field: shrink the circle to the nearest MAX_PATTERN
            d_sorted = np.sort(d_obs)
            r_eff = float(d_sorted[MAX_PATTERN - 1] + d_sorted[MAX_PATTERN]) / 2
            rows, d_obs, theta = self.observed_pattern(ctx, ref, r_eff)
        m = len(rows)
        if m < 2:
            return None
        cands = self.dispersion_candidates(d_obs, eps, r_eff if complete else None, symmetric=True,
                                           catalogue_side=complete)
        if len(cands) == 0:
            return None
        # every catalogue neighbour of every candidate within reach, each alignment of a start
        # neighbour with one at the same distance, and each observed neighbour's vote under it
        # (far start neighbours first: they give sharp angles); one compiled call (_dmv_vote)
        starts = np.argsort(-d_obs, kind="stable")[:START_NEIGHBOURS]
        flat, owner, oi, fj, a_ok, k_ok, f_ok, scores = vote(
            np.ascontiguousarray(d_obs, dtype=np.float64), np.ascontiguousarray(theta, dtype=np.float64),
            starts.astype(np.int64), self.offsets[cands].astype(np.int64),
            (self.offsets[cands + 1] - self.offsets[cands]).astype(np.int64), self.dist, self.phi,
            float(r_eff + eps), float(eps))
        if len(oi) == 0:
            return None
        order = np.argsort(-scores, kind="stable")
        tried = 0
        for a in order:
            if scores[a] < 3 or tried >= MAX_VERIFY or ctx.expired():
                break
            # the matched neighbour farthest round from the start makes the widest triangle
            mine = np.flatnonzero((a_ok == a) & (k_ok != oi[a]))
            if len(mine) == 0:
                continue
            spread = np.abs(np.mod(theta[k_ok[mine]] - theta[oi[a]] + math.pi, TWO_PI) - math.pi)
            pick = mine[int(np.argmax(spread))]
            tried += 1
            s = int(cands[owner[fj[a]]])
            obs_idx = np.array([ref, rows[oi[a]], rows[k_ok[pick]]])
            cat_idx = np.array([s, int(self.nb[flat[fj[a]]]), int(self.nb[flat[f_ok[pick]]])])
            found = ctx.verifier.check(obs_idx, cat_idx)
            if found is not None:
                return found
        return None
