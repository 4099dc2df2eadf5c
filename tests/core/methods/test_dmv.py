"""dmv (seed 003) on its paper's camera (f 50 mm, 13 um, 1024x1024, 6.0 Mv): the pattern
features, the distance-mapping vector, the two-pointer similarity, and the acceptance bar."""

from __future__ import annotations

import math

import numpy as np
import pytest

from service.core.evaluate import score
from service.core.geometry import radec_to_vector
from service.core.methods import get_matcher
from service.core.methods.dmv import DmvMatcher, greedy_similarity, map_bits, position_angles, star_pattern
from service.core.navdb import NavDatabase, build_database, open_database
from service.core.pipeline import SolveOptions, solve
from service.core.presets import PRESETS
from service.core.sim import SimConfig, simulate_frames
from tests.core.acceptance import assert_refuses_random_points, tally

PRESET = PRESETS["seed003"]
CAMERA = PRESET.camera
OPTIONS = SolveOptions(centroid_sigma_px=0.5)
SIM = SimConfig(mag_limit=PRESET.mag_limit, centroid_noise_px=0.5)


@pytest.fixture(scope="module")
def db(tmp_path_factory: pytest.TempPathFactory) -> NavDatabase:
    path = tmp_path_factory.mktemp("dmv") / "seed003"
    build_database(path, PRESET.build_config(("dmv",)))
    return open_database(path)


def test_position_angles_are_counter_clockwise_about_the_star() -> None:
    centre = np.array([0.0, 0.0, 1.0])
    nbrs = radec_to_vector(np.radians([0.0, 90.0, 180.0]), np.radians([89.0, 89.0, 89.0]))
    th = position_angles(centre, nbrs)
    steps = np.mod(np.diff(th), 2 * math.pi)
    assert np.allclose(steps, math.pi / 2)  # +90 deg of right ascension = +90 deg CCW about +z


def test_pattern_starts_at_the_nearest_neighbour_and_gaps_close_the_circle() -> None:
    dist = np.array([3.0, 1.0, 2.0, 4.0])
    theta = np.array([0.1, 2.0, 4.0, 5.0])
    order, phi = star_pattern(dist, theta)
    assert list(order) == [1, 2, 3, 0]
    assert math.isclose(phi.sum(), 2 * math.pi)
    assert np.allclose(phi[:3], [2.0, 1.0, 2 * math.pi - 5.0 + 0.1])


def test_anti_interference_code_sets_the_neighbouring_bin() -> None:
    assert list(map_bits(np.array([2.5]), 1.0, 8, 0.2)) == [2]
    assert list(map_bits(np.array([2.9]), 1.0, 8, 0.2)) == [2, 3]
    assert list(map_bits(np.array([2.1]), 1.0, 8, 0.2)) == [1, 2]
    assert list(map_bits(np.array([0.05]), 1.0, 8, 0.2)) == [0]


def test_two_pointer_similarity_survives_missing_and_false_stars() -> None:
    # the paper's worked example (figures 2-4): two missing and three false stars, P = 10
    big_phi = [23, 10, 32, 25, 50, 40, 25, 30, 35, 10, 30, 50]
    small_phi = [23, 42, 25, 25, 25, 40, 25, 17, 13, 20, 15, 40, 50]
    p, pairs = greedy_similarity(np.cumsum(small_phi), np.cumsum(big_phi), 0.5)
    assert p == 10
    assert all(b > a for (_, a), (_, b) in zip(pairs, pairs[1:], strict=False))


@pytest.mark.parametrize("variant", ["improved", "paper"])
def test_identifies_frames(db: NavDatabase, variant: str) -> None:
    m = DmvMatcher(db, variant=variant)
    cache = db.__dict__.setdefault("_matchers", {})
    saved = cache.get("dmv")
    cache["dmv"] = m
    try:
        frames = simulate_frames(CAMERA, 30, SIM, rng=31)
        results = [score(solve(f.centroids, CAMERA, db, method="dmv", options=OPTIONS), f.quaternion,
                         f.hip.tolist(), blends=f.blends) for f in frames]
        assert all(r.correct is not False for r in results)
        assert sum(r.solved for r in results) >= 25
    finally:
        cache.pop("dmv")
        if saved is not None:
            cache["dmv"] = saved


@pytest.mark.slow
def test_identifies_99_percent_with_no_wrong_answer(db: NavDatabase) -> None:
    frames = simulate_frames(CAMERA, 500, SIM, rng=2003)
    solved, wrong = tally(frames, CAMERA, db, "dmv", OPTIONS)
    assert wrong == 0
    assert solved >= 0.99 * len(frames)


@pytest.mark.slow
def test_random_points_never_solve(db: NavDatabase) -> None:
    assert_refuses_random_points(CAMERA, db, "dmv", seed=30_000, options=OPTIONS)


def test_matcher_is_registered(db: NavDatabase) -> None:
    assert isinstance(get_matcher(db, "dmv"), DmvMatcher)
    with pytest.raises(ValueError):
        DmvMatcher(db, variant="nope")
