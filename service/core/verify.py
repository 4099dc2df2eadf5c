"""Shared verification: from a proposed match to a proven one, or a refusal.

A method proposes a few (observed star, catalogue star) pairs. The verifier fits the attitude,
projects every catalogue star in the field into each camera, pairs observed and predicted
stars within ``match_radius_px`` (mutual nearest neighbours), refits with all pairs, and
bounds the probability that so many pairs arise by chance:

``P = n_trials * P[Binomial(n_free, p) >= n_extra]``, with ``p`` = the fraction of the image
lying within the match radius of some predicted star (``n_pred * pi r^2 / area``), ``n_free``
the observed stars not used by the hypothesis and ``n_extra`` those of them that matched.
``n_trials`` is the number of hypotheses the method tried (the look-elsewhere factor). A
match is accepted when ``P <= max_false_prob``. No method returns an unverified answer.

The binomial model treats unrelated stars as uniform, which flatters a near-miss: an attitude
rotated about a point close to a few real stars matches those few for real. So an answer with
``P > strong_false_prob`` is only *marginal*: the search goes on for ``confirm_patterns`` more
patterns; if a strong answer turns up it wins, and if two marginal answers disagree the frame is
ambiguous and refused. A wrong identification is worse than none.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np
from numba import njit
from scipy.special import betainc

from .attitude import ARCSEC_PER_RAD, wahba_kernel, wahba_svd
from .camera import Camera
from .match import (
    IDENTITY_MOUNTING,
    NEED_MAX_UNSCREENED,
    RigArrays,
    match_rig,
    needed_hits,
    refine,
    rig_arrays,
)
from .navdb.reader import NavDatabase
from .screen import could_pass_bound, hits_under, screen_hits
from .skygrid import fields_within
from .star_index import field_grid, sky_grid, sky_mask, star_tree, star_vec64
from .types import FloatArray, IntArray


@dataclass(frozen=True)
class Observation:
    """Observed stars of one frame (all cameras), brightest first.

    Attributes
    ----------
    vec : (N, 3) float64
        Unit vectors in the body frame (for one camera: the camera frame).
    xy : (N, 2) float64
        Pixel positions in their own camera.
    index : (N,) int64
        Index of each star in its camera's input centroid list.
    camera : (N,) int64
        Camera of each star.
    cameras : tuple of Camera
    mountings : tuple of (3, 3) arrays
        Body -> camera rotation matrices.
    """

    vec: FloatArray
    xy: FloatArray
    index: IntArray
    camera: IntArray
    cameras: tuple[Camera, ...]
    mountings: tuple[FloatArray, ...]
    by_camera: tuple[IntArray, ...] = field(default=())
    flux: FloatArray | None = None
    """(N,) fluxes as given (any linear unit), for the brightness check of the answer."""

    def __post_init__(self) -> None:
        if not self.by_camera:
            object.__setattr__(
                self, "by_camera", tuple(np.flatnonzero(self.camera == c) for c in range(len(self.cameras)))
            )

    def __len__(self) -> int:
        return int(self.vec.shape[0])

    # kept in the instance's __dict__ by hand: functools.cached_property takes a lock on every
    # access before Python 3.12 (~2 us; a frame reads these a dozen times)
    @property
    def kernel_arrays(self) -> RigArrays:
        """The cameras as plain arrays for the compiled kernels (built once)."""
        k = self.__dict__.get("_kernel_arrays")
        if k is None:
            k = self.__dict__["_kernel_arrays"] = rig_arrays(self.cameras, self.mountings, self.by_camera)
        return k

    @property
    def pixel_scale_rad(self) -> float:
        """Coarsest pixel scale among the cameras, radians per pixel."""
        s = self.__dict__.get("_pixel_scale_rad")
        if s is None:
            s = self.__dict__["_pixel_scale_rad"] = max(c.pixel_scale_rad for c in self.cameras)
        return s


def observation_of(vec: FloatArray, xy: FloatArray, index: IntArray, camera: IntArray, cameras: tuple[Camera, ...],
                   mountings: tuple[FloatArray, ...], by_camera: tuple[IntArray, ...],
                   flux: FloatArray | None) -> Observation:
    """``Observation(vec, xy, index, camera, cameras, mountings, by_camera=..., flux=...)`` made
    without the frozen dataclass's ``__init__`` (eight ``object.__setattr__``, ~2.5 us of a
    refused 3-star frame's ~100): the fields written into the instance's ``__dict__``, as that
    ``__init__`` leaves them (``by_camera`` given, so ``__post_init__`` has nothing to do).
    ``tests/core/test_verify.py`` checks it equals the dataclass's own."""
    obs = object.__new__(Observation)
    obs.__dict__.update(vec=vec, xy=xy, index=index, camera=camera, cameras=cameras, mountings=mountings,
                        by_camera=by_camera, flux=flux)
    return obs


@dataclass(frozen=True)
class Verified:
    """A proven identification."""

    obs: IntArray  # rows of the Observation
    cat: IntArray  # rows of the star table
    matrix: FloatArray  # ICRS -> body
    false_prob: float
    n_trials: int


@dataclass
class Verifier:
    """Checks hypotheses against one frame; counts how many it was asked (``trials``)."""

    db: NavDatabase
    obs: Observation
    match_radius_px: float = 4.0
    max_false_prob: float = 1e-5
    strong_false_prob: float = 1e-12
    confirm_patterns: int = 12
    min_matches: int = 4
    trials: int = 0
    patterns: int = 0
    screen_stars: int = 6
    deadline: float = math.inf
    """``time.perf_counter()`` after which no further hypothesis is checked."""
    trial_limit: int | None = None
    """Hypotheses (``trials``) after which no further one is checked: a budget of work."""
    marginal: list[Verified] = field(default_factory=list)
    exhausted: bool = False
    """Set by a method (``quad``) that looked up every pattern of the frame's brightest stars
    and proved none (the pipeline's fast refusal reads it)."""
    _first_marginal_at: int | None = None
    _marginal_maps: list[dict[int, int]] | None = field(default=None, repr=False)
    _near_cache: tuple[FloatArray, IntArray, IntArray] | None = field(default=None, repr=False)
    _pair_chance: float | None = field(default=None, repr=False)
    """:meth:`could_prove`'s ``p``, made on its first call (the frame and radius are fixed)."""

    def settled(self) -> bool:
        """True once a marginal answer has had ``confirm_patterns`` patterns to be beaten."""
        return self._first_marginal_at is not None and self.patterns - self._first_marginal_at >= self.confirm_patterns

    def over_limit(self) -> bool:
        """Has the search tried its ``trial_limit`` hypotheses?"""
        return self.trial_limit is not None and self.trials >= self.trial_limit

    def could_prove(self, hypothesis_stars: int) -> bool:
        """Could an answer whose hypothesis holds ``hypothesis_stars`` observed stars pass the
        bound on this frame at all? Its best case pairs every observed star: ``n_extra =
        n_free = n - h``, and ``p`` is at least ``n pi r^2 / area`` (each pair is a prediction
        inside an image), so ``P >= (n pi r^2 / area)^(n - h) * trials``. False when that
        exceeds ``max_false_prob`` (or no star is left beyond the hypothesis): a method
        proving by this bound alone cannot answer. A 4-star frame of a 1024-px camera never
        can (``4 pi 2.5^2 / 1024^2`` = 7.5e-5); one of seed 002's 4096-px camera can up to
        ~1.5 px."""
        n = len(self.obs)
        extra = n - hypothesis_stars
        if n < self.min_matches or extra < 1:
            return False
        p = self._pair_chance
        if p is None:
            area = sum(float(c.width) * float(c.height) for c in self.obs.cameras)
            p = self._pair_chance = min(1.0, n * math.pi * self.match_radius_px ** 2 / area)
        return p ** extra * max(self.trials, 1) <= self.max_false_prob

    def count_unchecked(self, n_candidates: int) -> None:
        """Count one observed pattern's ``n_candidates`` candidates as tried without checking
        them: for a method that skips a pattern once :meth:`could_prove` says no check could
        pass (the trials only grow, so none could later either)."""
        self.patterns += 1
        self.trials += n_candidates

    def best_marginal(self) -> Verified | None:
        """The most probable marginal answer, or None if there is none or they disagree.

        Two answers agree when they never pair one observed star with two catalogue stars (or
        one catalogue star with two observed stars) and no point of any image moves by more
        than three match radii between their attitudes. (A rotation angle alone would call
        two right answers apart: roll is the least constrained axis, and a roll of a few
        arcminutes moves the image edge by about a pixel.) One compiled call
        (:func:`marginal_choice`, which ``auto``'s first pass calls too)."""
        if len(self.marginal) <= 1:
            return self.marginal[0] if self.marginal else None
        off = np.zeros(len(self.marginal) + 1, np.int64)
        off[1:] = np.cumsum([len(v.obs) for v in self.marginal])
        k = marginal_choice(np.stack([np.asarray(v.matrix, np.float64) for v in self.marginal]),
                            np.array([v.false_prob for v in self.marginal], np.float64), off,
                            np.concatenate([v.obs for v in self.marginal]).astype(np.int64),
                            np.concatenate([v.cat for v in self.marginal]).astype(np.int64),
                            _image_probes(self.obs), 3 * self.match_radius_px * self.obs.pixel_scale_rad)
        return None if k < 0 else self.marginal[k]

    def names_marginal(self, obs_idx: IntArray, cat_idx: IntArray) -> bool:
        """Does a marginal answer already pair every observed row ``obs_idx`` with ``cat_idx``?

        Such a hypothesis is the same identification reached through another pattern: a frame
        proven through one triangle is usually proven through most of its others, and a 7-star
        frame of seed 002 checked ~4 of them each (~17 us a check). The screen skips them and
        counts each as a trial, so every later bound is unchanged. A check from another
        triangle starts from a slightly different attitude and may settle on one more pair:
        over 47,500 frames of the five paper cameras (0.5-2 px, 0-5 false stars) it did once,
        where the answer now names 5 of the frame's 6 true stars (the 6th had made it strong)."""
        if not self.marginal:
            return False
        if self._marginal_maps is None or len(self._marginal_maps) != len(self.marginal):
            self._marginal_maps = [dict(zip(v.obs.tolist(), v.cat.tolist(), strict=True)) for v in self.marginal]
        pairs = list(zip(np.asarray(obs_idx).tolist(), np.asarray(cat_idx).tolist(), strict=True))
        return any(all(m.get(o) == c for o, c in pairs) for m in self._marginal_maps)

    def screen_and_check(self, obs_idx: IntArray, cands: IntArray) -> Verified | None:
        """Test every candidate triple ``cands`` ``(K, 3)`` for one observed triangle
        ``obs_idx`` (see :meth:`screen_and_check_many`)."""
        cands = np.asarray(cands, dtype=np.int64).reshape(-1, 3)
        tris = np.empty(cands.shape, np.int64)  # (a writable array: a read-only broadcast view of one
        tris[:] = np.asarray(obs_idx, dtype=np.int64)  # candidate was a second compiled signature of the screen)
        return self.screen_and_check_many(tris, cands, n_patterns=1)

    def screen_and_check_many(self, obs_tris: IntArray, cands: IntArray, *, n_patterns: int) -> Verified | None:
        """Screen candidate matches of several observed triangles at once, then fully verify
        the promising ones, best first.

        ``obs_tris[k]`` (observed rows) is hypothesised to be catalogue rows ``cands[k]``.
        The screen fits every candidate's attitude (batched SVD), predicts the ICRS direction
        of the brightest other observed stars and counts those with a catalogue star within
        1.5 match radii (one k-d tree query for all). Every candidate counts as a trial in the
        coincidence bound; ``n_patterns`` observed patterns were tried.
        """
        obs_tris = np.asarray(obs_tris, dtype=np.int64).reshape(-1, 3)
        cands = np.asarray(cands, dtype=np.int64).reshape(-1, 3)
        self.patterns += n_patterns
        if len(cands) == 0:
            return None
        self.trials += len(cands) - 1  # check() counts the last one
        others = np.arange(min(len(self.obs), self.screen_stars + 3))
        hits = self._screen(obs_tris, cands, others)
        order = np.argsort(-hits, kind="stable")
        order = order[hits[order] >= (1 if len(self.obs) > 3 else 0)]
        need = self._needed_extras(len(others))
        for row in order[:CHECKS_PER_CHUNK]:
            if time.perf_counter() > self.deadline or self.over_limit():
                break
            if self.marginal and self.names_marginal(obs_tris[row], cands[row]):
                self.trials += 1  # a trial all the same, as check() would count it
                continue
            if hits[row] < need and self._wide_hits(obs_tris[row], cands[row], others, need) < need:
                self.trials += 1  # a trial all the same, as check() would count it
                continue  # too few stars even in the wide screen to pass the bound
            if not self._could_pass(obs_tris[row], cands[row], len(others)):
                self.trials += 1  # a trial all the same, as check() would count it
                continue  # a big frame: too few of all its stars in the wide screen
            found = self.check(obs_tris[row], cands[row])
            if found is not None:
                return found
        return None

    def _needed_extras(self, n_screened: int) -> int:
        """The screen hits a candidate needs now (:func:`~service.core.match.needed_hits`); one
        screened with fewer is checked only if the wide screen (:meth:`_wide_hits`) finds enough."""
        area = sum(float(c.width) * float(c.height) for c in self.obs.cameras)
        return needed_hits(len(self.obs), 3, n_screened, float(self.match_radius_px), area, self.trials + 1,
                           float(self.max_false_prob), int(self.min_matches))

    def _wide_hits(self, obs_tri: IntArray, cand: IntArray, others: IntArray, enough: int) -> int:
        """Screen hits of one candidate at its check's starting attitude (Wahba's on its three
        stars) and ``NEED_SCREEN_FACTOR`` times the screen's chord, counted up to ``enough``
        (:func:`~service.core.screen.hits_under`, as ``maxangle``'s compiled search calls it)."""
        vec, o, c, r, chord, g, stars = self._wide_start(obs_tri, cand)
        return int(hits_under(vec, o, r, len(others), chord, enough, int(c[0]), int(c[1]), int(c[2]), g.cell,
                              g.n_side, g.keys, g.starts, g.stars, stars, g.columns))

    def _could_pass(self, obs_tri: IntArray, cand: IntArray, n_screened: int) -> bool:
        """:func:`~service.core.screen.could_pass_bound` of one candidate, as ``maxangle``'s
        compiled search calls it: every observed star at the check's starting attitude (Wahba's
        on the candidate's three stars) and the wide screen's chord, against the extra pairs the
        check after this one would need (a frame of one camera; True for a rig's)."""
        if len(self.obs) <= n_screened + NEED_MAX_UNSCREENED or len(self.obs.cameras) != 1:
            return True
        vec, o, c, r, chord, g, stars = self._wide_start(obs_tri, cand)
        cam = self.obs.cameras[0]
        return bool(could_pass_bound(vec, o, r, n_screened, chord, float(self.match_radius_px),
                                     float(cam.width) * float(cam.height), self.trials + 1, float(self.max_false_prob),
                                     int(self.min_matches), int(c[0]), int(c[1]), int(c[2]), g.cell, g.n_side, g.keys,
                                     g.starts, g.stars, stars, g.columns))

    def _wide_start(self, obs_tri: IntArray, cand: IntArray) -> tuple[object, ...]:
        """What the wide screens of one candidate start from: the observed vectors, its rows
        (observed, catalogue), Wahba's attitude on its three stars (ICRS -> body), the wide
        chord (``NEED_SCREEN_FACTOR`` times the screen's), the sky grid and the star vectors."""
        stars = star_vec64(self.db)
        o = np.asarray(obs_tri, dtype=np.int64)
        c = np.asarray(cand, dtype=np.int64)
        r = wahba_kernel(np.ascontiguousarray(self.obs.vec[o], dtype=np.float64), stars[c], np.ones(len(o)))
        chord = NEED_SCREEN_FACTOR * 1.5 * self.match_radius_px * self.obs.pixel_scale_rad
        return np.ascontiguousarray(self.obs.vec, dtype=np.float64), o, c, r, chord, sky_grid(self.db), stars

    def _screen(self, obs_tris: IntArray, cands: IntArray, others: IntArray) -> IntArray:
        """Hits per candidate: ``others`` (observed rows not in its triangle) that land near a
        catalogue star under the candidate's attitude; -1 for a mirror image (compiled:
        :func:`~service.core.screen.screen_hits`)."""
        radius = 1.5 * self.match_radius_px * self.obs.pixel_scale_rad
        return screen_hits(self.obs.vec, obs_tris, cands, others, sky_grid(self.db), radius, sky_mask(self.db, radius))

    def check(self, obs_idx: IntArray, cat_idx: IntArray, *, n_trials: int | None = None) -> Verified | None:
        """Verify a hypothesis pairing ``obs_idx`` rows with catalogue rows ``cat_idx``.

        ``n_trials`` overrides the look-elsewhere factor (default: hypotheses checked so far).
        """
        self.trials += 1
        obs_idx = np.asarray(obs_idx, dtype=np.int64)
        cat_idx = np.asarray(cat_idx, dtype=np.int64)
        if len(set(cat_idx.tolist())) != len(cat_idx):  # a few rows: ~20x cheaper than np.unique
            return None
        trials = self.trials if n_trials is None else n_trials
        if len(self.obs.cameras) == 1 and self.min_matches == 4:
            # one camera: the same steps as one compiled call (check_kernel.verify_pairs; ~10 us
            # where these Python steps take ~70)
            from .answer import recheck  # (answer imports this module)
            ok, m_obs, m_cat, r, prob = recheck(self.obs, self.db, obs_idx, cat_idx, max(trials, 1),
                                                self.match_radius_px)
            return self._accept(m_obs, m_cat, r, prob, trials) if ok else None
        stars = self.db.stars.vec
        obs = self.obs
        r = wahba_svd(obs.vec[obs_idx], stars[cat_idx])
        near, near_off = self._near(r)
        k = obs.kernel_arrays
        # quick reject (the hypothesis' own stars must fit), pair, and refit with every pair
        # while the pairs grow (a compact hypothesis in a wide field extrapolates poorly at
        # first); ``r`` ends fitted to the pairs kept. One compiled call (match.refine).
        ok, m_obs, m_cat, p_single, r = refine(
            obs.vec, obs.xy, stars, obs_idx, cat_idx, r, self.match_radius_px * obs.pixel_scale_rad * 1.5,
            near, near_off, k, self.match_radius_px, max_refits=4)
        if not ok:
            return None
        basin = self._settle(r, len(m_obs))
        if basin is not None:
            m_obs, m_cat, p_single, r = basin
        if len(self.obs.cameras) > 1:
            m_obs, m_cat, r = self._drop_unverifiable(m_obs, m_cat, r, obs_idx)
        hyp = (m_obs[:, None] == obs_idx[None, :]).any(axis=1)
        n_extra = int(len(m_obs) - hyp.sum())
        n_free = len(obs) - len(obs_idx)
        if len(m_obs) < self.min_matches or n_extra < 1:
            return None
        tail = float(betainc(n_extra, n_free - n_extra + 1, min(p_single, 1.0))) if n_free >= n_extra else 1.0
        return self._accept(m_obs, m_cat, r, min(1.0, tail * max(trials, 1)), trials)

    def _accept(self, m_obs: IntArray, m_cat: IntArray, r: FloatArray, prob: float, trials: int
                ) -> Verified | None:
        """The verified answer if its bound ``prob`` is strong; a marginal one is kept aside
        (:meth:`best_marginal`)."""
        if prob > self.max_false_prob:
            return None
        found = Verified(m_obs, m_cat, r, prob, trials)
        if prob > self.strong_false_prob:
            self.marginal.append(found)
            if self._first_marginal_at is None:
                self._first_marginal_at = self.patterns
            return None
        return found

    def _settle(self, r: FloatArray, n_pairs: int) -> tuple[IntArray, IntArray, float, FloatArray] | None:
        """Near-miss test of an attitude with ``n_pairs`` pairs at the match radius.

        A slightly rotated attitude (a false star or a wrong pair in the hypothesis pulls the
        fit a few to twenty pixels off) matches only the stars near its pivot, and many more at
        a wider radius; a right one matches about as many. At ``SETTLE_FACTORS`` times the match
        radius in turn (pairs alone within that radius: the usual twice-the-radius crowding rule
        would remove most pairs of a dense field there): when the wide pairing grows by more
        than ``max(3, n_pairs / 3)``, the attitude is refitted to the wide pairs and the pairing
        redone at the match radius; that basin replaces the answer if it pairs more stars (and
        is tested at the next factor). In a dense real frame (hundreds of detections, many not
        in the catalogue) the wide pairing also grows by chance; its refit then pairs fewer
        stars and the answer stays. A frame with no more than ``max(3, n_pairs / 3)`` stars
        left unpaired cannot grow so, and is settled without pairing. Returns the new basin
        ``(obs, cat, p, r)``, or None when the attitude is settled as it was.
        """
        k = self.obs.kernel_arrays
        moved: tuple[IntArray, IntArray, float, FloatArray] | None = None
        for factor in SETTLE_FACTORS:
            if len(self.obs) <= n_pairs + max(3, n_pairs // 3):
                break  # the wide pairing cannot grow enough: too few stars are left unpaired
            near, near_off = self._near(r)
            w_obs, w_cat, _ = match_rig(r, self.obs.xy, self.db.stars.vec, near, near_off, k,
                                        factor * self.match_radius_px, crowd=1.0)
            if len(w_obs) <= n_pairs + max(3, n_pairs // 3):
                continue
            ok, m_obs, m_cat, p_single, r2 = self.rematch(wahba_svd(self.obs.vec[w_obs], self.db.stars.vec[w_cat]))
            if not ok or len(m_obs) <= n_pairs:
                continue  # no better basin there: the wide pairs were mostly chance (a dense field)
            moved = (m_obs, m_cat, p_single, r2)
            r, n_pairs = r2, len(m_obs)
        return moved

    def rematch(self, r: FloatArray) -> tuple[bool, IntArray, IntArray, float, FloatArray]:
        """Every pair an attitude ``r`` (ICRS -> body) implies at the match radius, refitted while
        the pairs grow: ``(ok, obs rows, catalogue rows, p, r)`` (see :func:`match.refine`)."""
        near, near_off = self._near(r)
        return refine(self.obs.vec, self.obs.xy, self.db.stars.vec, np.zeros(0, np.int64), np.zeros(0, np.int64),
                      r, 1.0, near, near_off, self.obs.kernel_arrays, self.match_radius_px, max_refits=4)

    def _drop_unverifiable(self, m_obs: IntArray, m_cat: IntArray, r: FloatArray, hyp_obs: IntArray
                           ) -> tuple[IntArray, IntArray, FloatArray]:
        """Rigs: drop the pairs of a camera that holds only one or two of them when the other
        cameras cannot predict where its stars are.

        The attitude from one narrow camera is loose in roll, which swings a second camera's
        predictions by many pixels; a star there lands within the match radius of a catalogue
        neighbour, its pair turns the roll to fit, and the refit leaves a small residual on a
        wrong star. So each such pair must be unambiguous within the other cameras' prediction
        error: the match radius plus 3 sigma of the predicted position (from the information
        matrix of the other cameras' pairs, at half the match radius per axis). Pairs with
        another catalogue star in that disc are dropped, and the attitude refitted without them.
        """
        obs = self.obs
        cams = obs.camera[m_obs]
        radius_rad = self.match_radius_px * obs.pixel_scale_rad
        keep = np.ones(len(m_obs), dtype=bool)
        tree = star_tree(self.db)
        for c in np.unique(cams):
            mine = cams == c
            if mine.sum() > 2 or (~mine).sum() < 2 or np.isin(hyp_obs, m_obs[mine]).any():
                continue
            others = obs.vec[m_obs[~mine]]
            info = len(others) * np.eye(3) - others.T @ others
            try:
                cov = np.linalg.inv(info) * (radius_rad / 2) ** 2
            except np.linalg.LinAlgError:
                keep[mine] = False
                continue
            r_wo = wahba_svd(others, self.db.stars.vec[m_cat[~mine]])
            for i in np.flatnonzero(mine):
                u = obs.vec[m_obs[i]]
                ux = np.array([[0.0, -u[2], u[1]], [u[2], 0.0, -u[0]], [-u[1], u[0], 0.0]])
                spread = math.sqrt(max(float(np.linalg.eigvalsh(ux @ cov @ ux.T)[-1]), 0.0))
                disc = radius_rad + 3 * spread
                cands = tree.query_ball_point(r_wo.T @ u, 2 * math.sin(disc / 2))
                if len(cands) != 1 or cands[0] != m_cat[i]:
                    keep[mine] = False
        if keep.all():
            return m_obs, m_cat, r
        m_obs, m_cat = m_obs[keep], m_cat[keep]
        return m_obs, m_cat, wahba_svd(obs.vec[m_obs], self.db.stars.vec[m_cat])

    def _match_all(self, r_body: FloatArray) -> tuple[IntArray, IntArray, float]:
        """Pair observed and predicted stars in every camera; also return the chance that a
        random point falls within the match radius of a predicted star."""
        near, near_off = self._near(r_body)
        return match_rig(r_body, self.obs.xy, self.db.stars.vec, near, near_off, self.obs.kernel_arrays,
                         self.match_radius_px)

    def _near(self, r_body: FloatArray) -> tuple[IntArray, IntArray]:
        """Catalogue rows within each camera's diagonal half-field + ``NEAR_MARGIN_DEG`` of its
        boresight under ``r_body``, concatenated, with per-camera offsets. The last answer is
        reused while the attitude stays within ``NEAR_MARGIN_DEG - 0.2`` deg of the one it was
        asked for (refits and the near-miss test move it by arcseconds to arcminutes). Gathered
        from a sky grid in one compiled call (:func:`~.skygrid.fields_within`), not by the k-d
        tree's ball queries (~30 us a call in Python)."""
        cached = self._near_cache
        # rotation angle between the two attitudes (bounds every camera's boresight move)
        if cached is not None and (float(np.sum(cached[0] * r_body)) - 1) / 2 >= _NEAR_REUSE_COS:
            return cached[1], cached[2]
        halves = [math.radians(cam.diagonal_fov_deg / 2 + NEAR_MARGIN_DEG) for cam in self.obs.cameras]
        bores = [(np.asarray(mount, dtype=np.float64) @ r_body)[2] for mount in self.obs.mountings]
        grid = field_grid(self.db, math.degrees(max(halves)))
        near, off = fields_within(grid, np.array(bores), np.array([2 * math.sin(h / 2) for h in halves]))
        self._near_cache = (np.array(r_body, dtype=np.float64), near, off)
        return near, off


CHECKS_PER_CHUNK = 8
"""Candidates of one batch (:meth:`Verifier.screen_and_check_many`) fully checked, best screened first."""

NEED_SCREEN_FACTOR = 2.0
"""A candidate whose screen (1.5 match radii) finds fewer stars than a check would need to pass
the coincidence bound (:func:`~service.core.match.needed_hits`) is checked only if a second
screen, this many times wider and at the attitude the check starts from (Wahba's on the
candidate's own stars; :func:`~service.core.screen.hits_under`), finds enough. The first
screen's triangle frame can put a star far from a small triangle several match radii off: the
first screen alone lost 10 frames in 47,500 at 1-2 px, a wide one in the triangle frame 1 in
100,000 (a star 13.8 px off there, 2.1 px under Wahba's attitude). With this one the answer grid
and ``bench.bench_wrong --frames 100000`` name what they named without the rule."""

SETTLE_FACTORS = (3.0, 6.0)
"""Wide radii (in match radii) at which an accepted attitude is tested for a near miss."""

NEAR_MARGIN_DEG = 0.5
"""Catalogue stars are gathered this far beyond each image's half-diagonal."""
_NEAR_REUSE_COS = math.cos(math.radians(NEAR_MARGIN_DEG - 0.2))


@njit(cache=True, nogil=True)
def marginal_choice(marg_r, marg_prob, marg_off, marg_obs, marg_cat, probes, limit):
    """:meth:`Verifier.best_marginal` over arrays: answer ``k`` has attitude ``marg_r[k]``
    (ICRS -> body), bound ``marg_prob[k]`` and pairs ``marg_obs``/``marg_cat`` in
    ``marg_off[k]:marg_off[k + 1]``. Returns the index of the likeliest (the first of the
    smallest bound), or -1 when there is none or two disagree: a star paired two ways, or an
    image centre or corner ``probes`` ``(P, 3)`` (body frame) moved by more than ``limit``
    (unit-vector distance) between their attitudes."""
    n_k = len(marg_prob)
    if n_k == 0:
        return -1
    best = 0
    for k in range(1, n_k):
        if marg_prob[k] < marg_prob[best]:
            best = k
    b_lo, b_hi = marg_off[best], marg_off[best + 1]
    for k in range(n_k):
        if k == best:
            continue
        for i in range(marg_off[k], marg_off[k + 1]):
            o, c = marg_obs[i], marg_cat[i]
            for j in range(b_lo, b_hi):
                if (marg_obs[j] == o) != (marg_cat[j] == c):
                    return -1
    lim2 = limit * limit
    for k in range(n_k):
        for p in range(len(probes)):
            s = 0.0
            for a in range(3):
                m = 0.0
                for i in range(3):
                    m += probes[p, i] * (marg_r[k, i, a] - marg_r[best, i, a])
                s += m * m
            if s > lim2:
                return -1
    return best


def _image_probes(obs: Observation) -> FloatArray:
    """Body-frame unit vectors ``(5 * n_cameras, 3)`` of each image's centre and corners (kept
    with the observation: every method's pass asks again)."""
    probes = obs.__dict__.get("_image_probes")
    if probes is None:
        probes = obs.__dict__["_image_probes"] = _probes_of(obs)
    return probes


def _probes_of(obs: Observation) -> FloatArray:
    if len(obs.cameras) == 1:  # one camera: its own kept array (read only)
        return camera_probes(obs.cameras[0], obs.mountings[0])
    return np.concatenate([camera_probes(cam, mount) for cam, mount in zip(obs.cameras, obs.mountings, strict=True)])


PROBES_KEPT = 256
_PROBES: dict[tuple[Camera, bytes], FloatArray] = {}
_IDENTITY_BYTES = IDENTITY_MOUNTING.tobytes()


def camera_probes(cam: Camera, mount: FloatArray) -> FloatArray:
    """Body-frame unit vectors ``(5, 3)`` of one image's centre and four corners (``mount``:
    body -> camera), kept per camera and mounting (every frame of a camera asks; read only)."""
    identity = mount is IDENTITY_MOUNTING  # solve()'s camera: no bytes to make, no product to take
    key = (cam, _IDENTITY_BYTES if identity else np.asarray(mount).tobytes())
    got = _PROBES.get(key)
    if got is None:
        if len(_PROBES) >= PROBES_KEPT:
            _PROBES.clear()
        if identity and not cam.distortion:
            got = _pinhole_probes(cam)
        else:
            w, h = cam.width - 0.5, cam.height - 0.5
            xy = np.array([[cam.cx, cam.cy], [-0.5, -0.5], [w, -0.5], [-0.5, h], [w, h]])
            got = np.ascontiguousarray(cam.pixel_to_vector(xy) @ mount, np.float64)  # R_mount^T v
        _PROBES[key] = got
    return got


def _pinhole_probes(cam: Camera) -> FloatArray:
    """:func:`camera_probes` of a pinhole camera on the identity mounting, by plain arithmetic
    (~1.5 us where the array steps took ~6 for a camera's first frame); the operations of
    :func:`~.camera._pinhole_vectors`, so the same bits."""
    cx, cy, f = cam.cx, cam.cy, cam.f_px
    left, right = (-0.5 - cx) / f, (cam.width - 0.5 - cx) / f
    top, bottom = (-0.5 - cy) / f, (cam.height - 0.5 - cy) / f
    out = [0.0, 0.0, 1.0]  # the centre: (cx - cx) / f is 0 exactly
    for x, y in ((left, top), (right, top), (left, bottom), (right, bottom)):
        n = math.sqrt(x * x + y * y + 1.0)
        out += (x / n, y / n, 1.0 / n)
    return np.array(out).reshape(5, 3)


def residuals_arcsec(obs: Observation, db: NavDatabase, v: Verified) -> FloatArray:
    """Per-match angular residual, arcsec."""
    pred = db.stars.vec[v.cat] @ v.matrix.T
    chord = np.linalg.norm(pred - obs.vec[v.obs], axis=1)
    return 2 * np.arcsin(np.clip(chord / 2, 0, 1)) * ARCSEC_PER_RAD
