"""The rig proof's third-star lookup (``_rig_third.third_star_candidates``): ``cross_triples``
with the sky grid gives the triples the dense ring product gives, in the same order, on the base
triangles of real sparse rig frames and at the density boxes' widths; a pair whose region cannot
be bounded makes the kernel say so, and ``cross_triples`` then takes the dense path."""

from __future__ import annotations

import math

import numpy as np
import pytest

from service.core.attitude import quat_to_matrix
from service.core.methods import get_matcher
from service.core.methods._rig_third import third_star_candidates
from service.core.methods.rig_proof import THIRD_STAR_REACH_DEG, base_triangles, cross_triples, sky_limits
from service.core.pipeline import _observation
from service.core.sim import SimConfig
from service.core.sim_rig import gf7_rig, simulate_rig_frames

RIG = gf7_rig()


@pytest.fixture(scope="module")
def rig_member(default_set_db):
    return default_set_db.members["rig"]


def test_the_grid_finds_the_triples_the_rings_find(rig_member) -> None:
    matcher = get_matcher(rig_member, "multifov")
    skies = sky_limits(rig_member)
    calls = found = 0
    for seed, noise in ((1, 0.5), (2, 1.0)):
        config = SimConfig(mag_limit=5.5, centroid_noise_px=noise, false_stars=1)
        frames = simulate_rig_frames(RIG, 60, config, rng=seed)
        for rf in frames:
            inputs = rf.inputs(RIG)
            if not 3 <= sum(len(c) for c, _, _ in inputs) <= 8:
                continue
            obs = _observation(inputs, [quat_to_matrix(np.asarray(q, float)) for _, _, q in inputs])
            tol = (3.0 * math.sqrt(2.0) * noise + 0.5) * obs.pixel_scale_rad
            bases = base_triangles(obs.vec, obs.camera, obs.by_camera, tol, matcher.lookup.max_angle)
            for i, j, k in bases[:4]:
                v3 = obs.vec[[i, j, k]]
                t_k = tol + (matcher.mount_tol if obs.camera[k] != obs.camera[i] else 0.0)
                cases = (((tol, t_k, t_k), skies[0], None), ((5 * tol,) * 3, skies[-1], skies[-1].index))
                for tols, sky, index in cases:
                    dense = cross_triples(matcher.lookup, sky.vec, v3, tols, index)
                    at = sky.grid(THIRD_STAR_REACH_DEG)
                    grid = cross_triples(matcher.lookup, sky.vec, v3, tols, index, at)
                    np.testing.assert_array_equal(grid, dense)
                    calls += 1
                    found += len(dense)
    assert calls >= 100 and found > 0


def test_a_region_that_cannot_be_bounded_is_refused(rig_member) -> None:
    sky = sky_limits(rig_member)[0]
    g = sky.grid(THIRD_STAR_REACH_DEG)
    nearest = int(np.argsort(-(sky.vec @ sky.vec[0]))[1])
    pairs = np.array([[0, nearest]], np.int64)
    ij = math.acos(float(sky.vec[0] @ sky.vec[nearest]))
    # a third star at |ik| + |jk| = |ij|: on the great circle through I and J, where the two
    # rings only touch
    lo1, hi1 = math.cos(ij / 2 + 1e-5), math.cos(ij / 2 - 1e-5)
    grid = (g.cell, g.n_side, g.keys, g.starts, g.stars, g.columns)
    ok, _, _ = third_star_candidates(pairs, sky.vec, lo1, hi1, lo1, hi1, 1.0, *grid)
    assert not ok
    # well apart, the region is bounded and gathered
    lo1, hi1 = math.cos(math.radians(20) + 1e-5), math.cos(math.radians(20) - 1e-5)
    ok, pair, _ = third_star_candidates(pairs, sky.vec, lo1, hi1, lo1, hi1, 1.0, *grid)
    assert ok and np.all(pair == 0)
