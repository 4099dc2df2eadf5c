"""``check_kernel``: a hypothesis checked in one compiled call, and the marginal answers' books."""

from __future__ import annotations

import math

import numpy as np
import pytest

from service.core.attitude import wahba_kernel
from service.core.check_kernel import (
    DEEPER_REACH,
    RECHECK_REACH,
    could_pair_more,
    keep_marginal,
    names_marginal,
    pairable_count,
    recheck_could_pass,
    recheck_pairs,
    verify_pairs,
)
from service.core.pipeline import _observation
from service.core.sim import SimConfig, simulate_frames
from service.core.star_index import field_grid, sky_grid, star_vec64
from service.core.verify import NEAR_MARGIN_DEG
from tests.conftest import SEED000_CAMERA

RADIUS_PX = 3.0


@pytest.fixture(scope="module")
def case(seed000_db):
    """A frame of >= 15 true stars and 2 false ones, its observation and its true pairs (rows)."""
    frames = simulate_frames(SEED000_CAMERA, 40, SimConfig(centroid_noise_px=1.0, false_stars=2), rng=7)
    f = next(f for f in frames if (f.hip >= 0).sum() >= 15)
    obs = _observation([(f.centroids, SEED000_CAMERA, None)], [np.eye(3)])
    row_of = {int(h): i for i, h in enumerate(np.asarray(seed000_db.stars.hip))}
    hips = np.asarray(f.hip)[obs.index]  # per observed row (brightest first)
    true = [(o, row_of[int(h)]) for o, h in enumerate(hips) if h >= 0 and int(h) in row_of]
    return obs, np.array([t[0] for t in true]), np.array([t[1] for t in true])


def _check(db, obs, o, c, trials=1):
    vec = star_vec64(db)
    near_deg = SEED000_CAMERA.diagonal_fov_deg / 2 + NEAR_MARGIN_DEG
    k = obs.kernel_arrays
    r = wahba_kernel(obs.vec[o], vec[c], np.ones(len(o)))
    return verify_pairs(obs.vec, obs.xy, vec, o.copy(), c.copy(), r, *field_grid(db, near_deg).kernel_args(),
                        2 * math.sin(math.radians(near_deg) / 2), k.mounts[0], np.empty(len(vec), np.int64),
                        np.zeros(4), k.mounts, k.cams, k.dist, k.rows, k.row_off, RADIUS_PX,
                        1.5 * RADIUS_PX * obs.pixel_scale_rad, trials)


def test_a_true_triangle_is_proven_with_every_true_pair(seed000_db, case) -> None:
    obs, o_true, c_true = case
    ok, m_obs, m_cat, r, prob = _check(seed000_db, obs, o_true[:3], c_true[:3], trials=100)
    assert ok and prob <= 1e-5
    named = dict(zip(m_obs.tolist(), m_cat.tolist(), strict=True))
    truth = dict(zip(o_true.tolist(), c_true.tolist(), strict=True))
    assert all(truth.get(o) == c for o, c in named.items())  # no false star paired, no wrong star
    assert len(named) >= len(truth) - 2


def test_a_wrong_triangle_is_not_proven(seed000_db, case) -> None:
    obs, o_true, c_true = case
    ok, _, _, _, prob = _check(seed000_db, obs, o_true[:3], c_true[[3, 4, 5]])
    assert not ok or prob > 1e-5


def test_recheck_from_some_pairs_names_the_same_stars(seed000_db, case) -> None:
    """Re-verifying from 5 of an answer's pairs (its stars another member also holds, here the
    same member) pairs the rest again; from all of them it proves nothing new (no extra pair)."""
    obs, o_true, c_true = case
    _, m_obs, m_cat, _, _ = _check(seed000_db, obs, o_true[:3], c_true[:3])
    vec = star_vec64(seed000_db)
    near_deg = SEED000_CAMERA.diagonal_fov_deg / 2 + NEAR_MARGIN_DEG
    k = obs.kernel_arrays

    def recheck(o, c):
        return recheck_pairs(obs.vec, obs.xy, vec, o.copy(), c.copy(), *field_grid(seed000_db, near_deg).kernel_args(),
                             2 * math.sin(math.radians(near_deg) / 2), k.mounts, k.cams, k.dist, k.rows, k.row_off,
                             RADIUS_PX, obs.pixel_scale_rad, 1)

    ok, r_obs, r_cat, _, prob = recheck(m_obs[:5], m_cat[:5])
    assert ok and prob <= 1e-5
    assert sorted(zip(r_obs.tolist(), r_cat.tolist())) == sorted(zip(m_obs.tolist(), m_cat.tolist()))
    assert not recheck(m_obs, m_cat)[0]


def test_could_pair_more_only_while_an_unpaired_star_lies_near_a_catalogue_star(seed000_db, case) -> None:
    obs, o_true, c_true = case
    vec = star_vec64(seed000_db)
    r = wahba_kernel(obs.vec[o_true], vec[c_true], np.ones(len(o_true)))
    g = sky_grid(seed000_db)
    chord = RECHECK_REACH * RADIUS_PX * obs.pixel_scale_rad
    args = (g.cell, g.n_side, g.keys, g.starts, g.stars, vec, g.columns)
    assert could_pair_more(obs.vec, o_true[:-1].copy(), r, chord, *args)  # the last true star is free
    assert not could_pair_more(obs.vec, np.arange(len(obs), dtype=np.int64), r, chord, *args)  # every star paired


def test_recheck_could_pass_never_refuses_a_recheck_that_passes(seed000_db) -> None:
    """The least bound :func:`recheck_could_pass` gives a recheck is never above the bound it
    gets: over hypotheses of 3 to all-but-2 true pairs of frames with 0-5 false stars, every
    recheck that names more stars than the hypothesis' answer at a bound within the limit was
    allowed; and the test refuses some (a few free stars cannot prove a strong answer)."""
    vec = star_vec64(seed000_db)
    near_deg = SEED000_CAMERA.diagonal_fov_deg / 2 + NEAR_MARGIN_DEG
    g = field_grid(seed000_db, near_deg)
    grid = sky_grid(seed000_db)
    row_of = {int(h): i for i, h in enumerate(np.asarray(seed000_db.stars.hip))}
    passed = refused = 0
    for false in (0, 2, 5):
        for f in simulate_frames(SEED000_CAMERA, 25, SimConfig(centroid_noise_px=0.5, false_stars=false), rng=3):
            obs = _observation([(f.centroids, SEED000_CAMERA, None)], [np.eye(3)])
            hips = np.asarray(f.hip)[obs.index]
            true = [(o, row_of[int(h)]) for o, h in enumerate(hips) if h >= 0 and int(h) in row_of]
            if len(true) < 6:
                continue
            k = obs.kernel_arrays
            for n_hyp in range(3, len(true) - 1):
                o = np.array([t[0] for t in true[:n_hyp]], np.int64)
                c = np.array([t[1] for t in true[:n_hyp]], np.int64)
                for limit, trials in ((1e-12, 1), (1e-5, 50)):
                    ok, m_obs, _, r, prob = recheck_pairs(
                        obs.vec, obs.xy, vec, o, c, *g.kernel_args(), 2 * math.sin(math.radians(near_deg) / 2),
                        k.mounts, k.cams, k.dist, k.rows, k.row_off, RADIUS_PX, obs.pixel_scale_rad, trials)
                    r0 = wahba_kernel(obs.vec[o], vec[c], np.ones(len(o)))
                    n_pairable = pairable_count(obs.vec, o, r0, DEEPER_REACH * RADIUS_PX * obs.pixel_scale_rad,
                                                grid.cell, grid.n_side, grid.keys, grid.starts, grid.stars, vec,
                                                grid.columns)
                    allowed = recheck_could_pass(len(obs.vec), n_hyp, n_pairable, n_hyp, RADIUS_PX,
                                                 float(SEED000_CAMERA.width * SEED000_CAMERA.height), trials, limit)
                    if ok and prob <= limit and len(m_obs) > n_hyp:
                        assert allowed, (false, n_hyp, n_pairable, prob)
                        passed += 1
                    refused += not allowed
    assert passed >= 50 and refused >= 10


def test_marginal_answers_are_kept_and_named() -> None:
    room, n_obs = 4, 6
    marg_r, marg_prob, marg_trials = np.empty((room, 3, 3)), np.empty(room), np.empty(room, np.int64)
    marg_off = np.zeros(room + 1, np.int64)
    marg_obs, marg_cat = np.empty(room * n_obs, np.int64), np.empty(room * n_obs, np.int64)
    n = keep_marginal(marg_r, marg_prob, marg_trials, marg_off, marg_obs, marg_cat, 0, np.eye(3), 1e-7, 12,
                      np.array([0, 1, 2, 3]), np.array([10, 11, 12, 13]))
    n = keep_marginal(marg_r, marg_prob, marg_trials, marg_off, marg_obs, marg_cat, n, np.eye(3), 2e-7, 30,
                      np.array([1, 4]), np.array([20, 21]))
    assert n == 2 and marg_off[:3].tolist() == [0, 4, 6] and marg_trials[:2].tolist() == [12, 30]
    assert names_marginal(np.array([2, 0]), np.array([12, 10]), marg_off, marg_obs, marg_cat, n)
    assert names_marginal(np.array([4]), np.array([21]), marg_off, marg_obs, marg_cat, n)
    assert not names_marginal(np.array([2, 4]), np.array([12, 21]), marg_off, marg_obs, marg_cat, n)  # two answers
    assert not names_marginal(np.array([0]), np.array([11]), marg_off, marg_obs, marg_cat, n)
    closed = np.array([False, True])
    assert not names_marginal(np.array([0]), np.array([10]), marg_off, marg_obs, marg_cat, n, closed)
    assert names_marginal(np.array([4]), np.array([21]), marg_off, marg_obs, marg_cat, n, closed)
