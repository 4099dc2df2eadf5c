"""radial (seed 002) on its paper's camera (4x4 deg, 4096x4096, 9 um): the packed ring codes,
the candidate scores, and the acceptance bar.

The acceptance camera goes to 8.0 Mv (``PRESETS["seed002"].acceptance()``): there the median
frame holds 15 stars and 99.9% of frames hold at least four, so the >= 99% bar is asserted on
all 500 frames, with no wrong answer and random points refused.

The 7.0 Mv camera (``PRESETS["seed002"]``) is the sparse-field study: of its 500 frames here 1
holds no star, 45 one or two (nothing to identify) and 68 exactly three (no fourth star to
confirm a triangle; the ``triangle`` method's sparse-field proof covers those,
tests/core/test_sparse.py). There the bar is asserted on the frames with at least four stars;
no wrong answer on any frame.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from service.core.evaluate import score
from service.core.geometry import pairwise_angles
from service.core.methods import get_matcher
from service.core.methods.radial import RadialMatcher, ring_codes
from service.core.navdb import NavDatabase
from service.core.pipeline import SolveOptions, solve
from service.core.presets import PRESETS
from service.core.sim import SimConfig, SimFrame, simulate_frames
from tests.core.acceptance import (
    assert_identifies,
    assert_refuses_random_points,
    preset_database,
    preset_frames,
)

PRESET = PRESETS["seed002"]
DEEP = PRESET.acceptance()
CAMERA = PRESET.camera
OPTIONS = SolveOptions(centroid_sigma_px=0.5)
TOL = (3 * math.sqrt(2) * 0.5 + 0.5) * CAMERA.pixel_scale_rad


@pytest.fixture(scope="module")
def db(tmp_path_factory: pytest.TempPathFactory) -> NavDatabase:
    return preset_database(tmp_path_factory, PRESET, ("radial",))


@pytest.fixture(scope="module")
def frames() -> list[SimFrame]:
    return preset_frames(PRESET, 500, rng=2002)


@pytest.fixture(scope="module")
def deep_db(tmp_path_factory: pytest.TempPathFactory) -> NavDatabase:
    return preset_database(tmp_path_factory, DEEP, ("radial",))


@pytest.fixture(scope="module")
def deep_frames() -> list[SimFrame]:
    return preset_frames(DEEP, 500, rng=2002)


def test_ring_codes_set_one_bit_per_occupied_ring() -> None:
    pairs = np.array([[0, 1], [0, 2], [1, 2]])
    angles = np.array([0.5, 0.55, 70.2])  # rings 0, 0 and 70 (ring width 1)
    codes = ring_codes(pairs, angles, 3, 1.0, 128)
    assert codes.shape == (2, 3) and codes.dtype == np.uint64
    assert list(codes[0]) == [1, 1, 1]  # ring 0: every star has a neighbour there
    assert list(codes[1]) == [0, 1 << 6, 1 << 6]  # ring 70 = word 1, bit 6: stars 1 and 2
    assert np.bitwise_count(codes).sum() == 5


@pytest.mark.parametrize("variant", [{"score": "neighbours"}, {"score": "paper"},
                                     {"score": "neighbours", "threshold": "fraction"}])
def test_true_star_is_a_top_candidate(db: NavDatabase, frames, variant) -> None:
    m = RadialMatcher(db, **variant)
    row = {int(h): i for i, h in enumerate(db.stars.hip)}
    found = total = 0
    for f in frames[:40]:
        if len(f.centroids) < 6:
            continue
        d = pairwise_angles(CAMERA.pixel_to_vector(f.centroids.xy))
        for i in range(len(d)):
            total += 1
            found += row[int(f.hip[i])] in m.candidates(np.delete(d[i], i), TOL)[:8]
    assert found >= 0.9 * total


@pytest.mark.slow
def test_identifies_99_percent_of_frames_with_four_stars(db: NavDatabase, frames) -> None:
    solved = wrong = with_four = solved_four = 0
    for f in frames:
        sol = solve(f.centroids, CAMERA, db, method="radial", options=OPTIONS)
        s = score(sol, f.quaternion, f.hip.tolist(), blends=f.blends)
        solved += s.solved
        wrong += s.solved and not s.correct
        if len(f.centroids) >= 4:
            with_four += 1
            solved_four += s.solved
    assert wrong == 0
    assert solved_four >= 0.99 * with_four
    assert with_four >= 0.75 * len(frames)


@pytest.mark.slow
def test_random_points_never_solve(db: NavDatabase) -> None:
    assert_refuses_random_points(CAMERA, db, "radial", seed=20_000, options=OPTIONS)


def test_deep_limit_is_the_shallowest_half_magnitude_with_four_stars_in_almost_every_frame() -> None:
    def share_with_four(mag_limit: float) -> float:
        config = SimConfig(mag_limit=mag_limit, centroid_noise_px=0.5)
        return np.mean([len(f.centroids) >= 4 for f in simulate_frames(CAMERA, 4000, config, rng=7)])

    assert DEEP.name == "seed002deep" and DEEP.camera == CAMERA and PRESET.mag_limit == 7.0
    assert share_with_four(DEEP.mag_limit) >= 0.995  # measured 99.9%
    assert share_with_four(DEEP.mag_limit - 0.5) < 0.99  # measured 96.6%


@pytest.mark.slow
def test_identifies_99_percent_of_all_frames_of_the_deep_camera(deep_db: NavDatabase, deep_frames) -> None:
    assert_identifies(deep_frames, CAMERA, deep_db, "radial", options=OPTIONS)  # measured 500/500


@pytest.mark.slow
def test_random_points_never_solve_on_the_deep_camera(deep_db: NavDatabase) -> None:
    assert_refuses_random_points(CAMERA, deep_db, "radial", seed=21_000, options=OPTIONS)


def test_matcher_is_registered(db: NavDatabase) -> None:
    assert isinstance(get_matcher(db, "radial"), RadialMatcher)
    with pytest.raises(ValueError):
        RadialMatcher(db, score="nope")


def test_informative_radius_is_where_a_window_fills_by_chance_half_the_time() -> None:
    """Issue 16: beyond it a ring window holds a catalogue star more often than not."""
    from service.core.methods.radial import CHANCE_OCCUPANCY, informative_radius

    ring, eps, n = math.radians(99 / 3600), math.radians(183 / 3600), 9042  # seed 004 at 0.5 px
    r = informative_radius(n, ring, eps, math.radians(28.2))
    expected = n / 2 * math.sin(r) * (2 * eps + ring)  # catalogue stars in the window at r
    assert 1 - math.exp(-expected) == pytest.approx(CHANCE_OCCUPANCY)
    assert 3.5 < math.degrees(r) < 4.5
    assert informative_radius(100, ring, eps, math.radians(5.0)) == math.radians(5.0)  # sparse: all of R
