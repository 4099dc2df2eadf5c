"""``quad``: 4-star patterns of the brightest stars, hashed by shape (the Tetra family).

The fast first pass of ``auto``. Not one of the seven published methods: it follows tetra3
(Brown & Stubis) and its descendants. The database holds, for fields of every size the
database serves, the 4-star patterns of each field's brightest stars, keyed by their five edge
ratios and their largest edge and hashed into an open-addressing table
(:mod:`.quad_build`). A frame's patterns are formed from its brightest stars in brightness
order, looked up (one probe per key bin their tolerance reaches) and verified, all in one
compiled call (:mod:`.quad_kernel`) that applies the shared verifier's steps and coincidence
bound; Python only converts the input and wraps the answer.

A frame of fewer than 5 stars, or a rig of several cameras, is left to the other methods.
After a miss, the verifier's ``exhausted`` says whether every pattern of the brightest
``QUERY_STARS`` stars was looked up: then the pipeline gives the frame its first fallback alone,
within a budget of hypotheses (``pipeline.FEW_STARS_MAX_TRIALS``, ``MANY_STARS_MAX_TRIALS``).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from ..catalog import StarTable
from ..errors import DatabaseCorruptError
from ..navdb.reader import NavDatabase
from ..star_index import field_grid, sky_grid, star_vec64
from ..verify import NEAR_MARGIN_DEG, Verified, Verifier
from .base import Progress, SolveContext
from .quad_build import INLINE_LAYOUT, LAYOUT, build_quad_table
from .quad_kernel import STATUS_FOUND, quad_search, unpack_search

QUERY_STARS = 10
"""The brightest observed stars whose 4-star patterns are looked up (C(10, 4) = 210)."""
MAX_PROBES = 200_000
"""Hash probes a frame may make (about 2 ms)."""
MAX_CHECKS = 400
"""Full verifications a frame may make."""


class Quad:
    name = "quad"
    summary = "4-star patterns of each field's brightest stars, hashed by shape (Tetra family; auto's first pass)"

    def build_tables(self, stars: StarTable, config: Any, params: dict[str, Any], progress: Progress
                     ) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
        progress("4-star patterns", 0.0)
        mag = np.asarray(stars.mag, dtype=np.float64)
        rank = np.empty(len(mag), np.int64)
        rank[np.argsort(mag, kind="stable")] = np.arange(len(mag))
        tables, used = build_quad_table(np.asarray(stars.vec), rank, float(config.fov_min_deg),
                                        float(config.fov_max_deg), params)
        progress(f"{used['n_patterns']} patterns", 1.0)
        return tables, used

    def matcher(self, db: NavDatabase) -> QuadMatcher:
        return QuadMatcher(db)


MIN_STARS = 5
"""Stars a frame needs for ``quad``: a 4-star pattern and one more to pair."""


class QuadMatcher:
    """The table of one database, as the arrays the kernel reads (built once)."""

    def __init__(self, db: NavDatabase) -> None:
        t = db.tables["quad"]
        p = db.method_params("quad")
        if p.get("layout") not in (LAYOUT, INLINE_LAYOUT):
            raise DatabaseCorruptError(f"{db.path}: quad table of layout {p.get('layout')!r}, this skyfix reads "
                                       f"{LAYOUT!r} or {INLINE_LAYOUT!r}; rebuild it with `skyfix db build`")
        self.db = db
        self.patterns = np.asarray(t["patterns"])
        self.table = np.asarray(t["table"])
        self.spill = np.asarray(t["spill"]) if "spill" in t else np.zeros(0, np.int64)  # INLINE_LAYOUT: none
        self.ratio_bin = float(p["ratio_bin"])
        self.edge_bin = float(p["edge_bin_rad"])
        self.edge_max = math.radians(float(p["fov_max_deg"]))
        self.star_vec = star_vec64(db)
        s = sky_grid(db)
        self.screen = s.kernel_args()

    def identify(self, ctx: SolveContext) -> Verified | None:
        v = ctx.verifier
        v.exhausted = False
        obs = ctx.obs
        if len(obs.cameras) != 1 or len(obs) < MIN_STARS:
            return None
        pre = obs.__dict__.pop("_quad_prefetch", None)  # the first pass's own search (service.core.first_pass)
        if pre is not None and pre[0] is self.db and v.trials == 0:
            res = unpack_search(*pre[1])
        else:
            res = self.search(obs, v, ctx.tol_rad)
        status, hyp_obs, hyp_cat, m_obs, m_cat, r, prob, trials, n_pat, exhausted = res[:10]
        v.trials = int(trials)
        v.patterns += int(n_pat)
        v.exhausted = bool(exhausted)
        if status == STATUS_FOUND:
            return Verified(m_obs, m_cat, r, float(prob), int(trials))
        marg_r, marg_prob, marg_off, marg_obs, marg_cat, marg_trials = res[10:16]
        for k in range(len(marg_prob)):
            sl = slice(marg_off[k], marg_off[k + 1])
            v.marginal.append(Verified(marg_obs[sl], marg_cat[sl], marg_r[k], float(marg_prob[k]),
                                       int(marg_trials[k])))
        if len(marg_prob) and v._first_marginal_at is None:
            v._first_marginal_at = v.patterns
        return None

    def search(self, obs: Any, v: Verifier, tol_rad: float) -> tuple[Any, ...]:
        """The kernel's answer for ``obs`` under the verifier's settings (see
        :func:`~.quad_kernel.quad_search`)."""
        cam = obs.cameras[0]
        k = obs.kernel_arrays
        near_deg = cam.diagonal_fov_deg / 2 + NEAR_MARGIN_DEG
        near_chord = 2 * math.sin(math.radians(near_deg) / 2)
        return quad_search(obs.vec, obs.xy, QUERY_STARS, tol_rad, self.patterns, self.table, self.spill,
                           self.ratio_bin, self.edge_bin, self.edge_max, self.star_vec, *self.screen,
                           *field_grid(self.db, near_deg).kernel_args(), near_chord, k.mounts, k.cams, k.dist,
                           k.rows, k.row_off, float(v.match_radius_px), float(obs.pixel_scale_rad),
                           float(v.max_false_prob),
                           float(v.strong_false_prob), int(v.confirm_patterns), int(v.screen_stars),
                           int(v.trials), MAX_PROBES, MAX_CHECKS)
