"""``pyramid``: star-pair look-ups confirmed by a fourth star (Mortari et al. 2004).

Tables: every catalogue pair closer than ``max_angle_deg``, sorted by angle: the rows of the
database's shared pair table (``pairs/``) within that limit; pyramid stores no array of its own
(binary search on the sorted angles plays the role of Mortari's k-vector: both are a range query
over a sorted array; numpy's ``searchsorted`` is the faster of the two here). Identification: triangles of
the brightest observed stars in the pyramid order; for each, the catalogue triples whose three
sides agree within tolerance and whose handedness matches; each is confirmed by projecting the
catalogue into the image, which demands at least one further star (the "fourth star" of the
pyramid) and a coincidence probability below the verifier's bound.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from ..catalog import StarTable
from ..geometry import pairwise_angles
from ..navdb.reader import NavDatabase
from ..verify import Verified
from ._pairs import (
    PairLimits,
    SharedPairs,
    empty_triangles,
    join_windows,
    pair_limits,
    pair_windows,
    pattern_order,
    require_shared,
    same_handedness,
)
from ._table_join import table_join, triangle_table
from .base import Progress, SolveContext

MAX_CANDIDATES = 1000
"""Triangles matching more catalogue triples than this are skipped as uninformative."""

EMPTY_TRIANGLES_TO_REFUSE = 2
"""A frame of no more stars than a proof pairs (4) is given up once this many of its triangles
match no catalogue triple. Its proof would pair every star, so every triangle of them would be
a catalogue triangle within the side tolerance (3 sqrt(2) sigma + 0.5 px, wider than the match
radius's 3 sigma on a side): one triangle can still miss by noise (a side beyond ~3.4 of its
sigmas, ~0.3% of true triangles), two hardly, and a star too faint for the member's table
leaves the frame unprovable there anyway. A 4-star frame with a false star has 3 such triangles.
On seed 002 (4-deg, 7 Mv), where 4-star frames are 7% of the frames, this halves pyramid's
~0.7 ms on those it cannot prove (both members)."""


class Pyramid:
    name = "pyramid"
    summary = "k-vector star pairs, triangles in pyramid order, confirmed by a fourth star (Mortari 2004)"

    def pair_limits(self, config: Any, params: dict[str, Any]) -> PairLimits:
        """Pairs up to ``max_angle_deg`` (default: the database's largest field), degrees."""
        return pair_limits(config, params)

    def build_tables(
        self, stars: StarTable, config: Any, params: dict[str, Any], progress: Progress,
        *, shared: SharedPairs | None = None,
    ) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
        """No arrays of its own: the shared pair table's rows within its limits are all it reads."""
        limits = self.pair_limits(config, params)
        _, angles = require_shared(shared, self.name).view(limits)
        progress(f"{len(angles)} pairs", 1.0)
        return {}, {"max_angle_deg": limits.max_angle_deg, "n_pairs": int(len(angles))}

    def matcher(self, db: NavDatabase) -> PyramidMatcher:
        return PyramidMatcher(db)


class PyramidMatcher:
    def __init__(self, db: NavDatabase) -> None:
        t = db.tables["pyramid"]
        self.pairs = t["pairs"]
        self.angles = t["angles"]
        self.vec = db.stars.vec
        self.n_stars = len(db.stars)
        self.max_angle = math.radians(db.method_params("pyramid")["max_angle_deg"])
        self.table = triangle_table(db)  # the join's triples looked up, where it holds them (_table_join)

    def identify(self, ctx: SolveContext) -> Verified | None:
        obs = ctx.obs
        n = min(len(obs), ctx.max_stars)
        if n < 3:
            return None
        v = obs.vec[:n]
        d = pairwise_angles(v)
        tol = ctx.tol_rad
        windows: tuple[np.ndarray, np.ndarray] | None = None  # each pair's rows [start, end), when first joined
        # a frame of as many stars as a proof pairs: every one must be a catalogue star, so every
        # triangle of them a catalogue triangle (see EMPTY_TRIANGLES_TO_REFUSE)
        all_needed = len(obs) <= ctx.verifier.min_matches
        empty = 0
        known_empty = empty_triangles(obs, self.pairs, tol)
        for i, j, k in pattern_order(n):
            if ctx.expired() or not ctx.verifier.could_prove(3):
                break  # (no later triangle's answer could pass the bound: trials only grow)
            sides = (d[i, j], d[i, k], d[j, k])
            if max(sides) > self.max_angle - tol or min(sides) < 4 * tol:
                continue
            cand = None if self.table is None else table_join(self.table, v[[i, j, k]], d[i, j], d[i, k], d[j, k], tol)
            if cand is None:  # no triangle table, or one that may not hold them all: the join
                if windows is None:  # every pair's window of the pair table at once
                    windows = pair_windows(self.angles, d, tol)
                start, end = windows
                cand = join_windows(self.pairs, int(start[i, j]), int(end[i, j]), int(start[i, k]), int(end[i, k]),
                                    int(start[j, k]), int(end[j, k]), self.n_stars)
                if len(cand):
                    cand = cand[same_handedness(self.vec, v[[i, j, k]], cand)]
            if len(cand) == 0:
                known_empty.add((i, j, k))
                empty += 1
                if all_needed and empty >= EMPTY_TRIANGLES_TO_REFUSE:
                    break
                continue
            if len(cand) > MAX_CANDIDATES:
                continue
            found = ctx.verifier.screen_and_check(np.array([i, j, k]), cand)
            if found is not None:
                return found
        return None
