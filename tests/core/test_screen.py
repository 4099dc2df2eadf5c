"""The screens' compiled kernels (service/core/screen.py) on real frames and the real catalogue."""

from __future__ import annotations

import math

import numpy as np
import pytest

from service.core.attitude import quat_to_matrix
from service.core.match import NEED_MAX_UNSCREENED, least_extras
from service.core.pipeline import _observation
from service.core.screen import could_pass_bound
from service.core.sim import SimConfig, random_points, simulate_frames
from service.core.star_index import sky_grid, star_vec64
from tests.conftest import SEED000_CAMERA

N_SCREENED = 9  # the verifier's screen_stars + 3
RADIUS_PX = 3.0


def _args(db, obs, r, hyp, trials=1):
    g = sky_grid(db)
    chord = 2.0 * 1.5 * RADIUS_PX * obs.pixel_scale_rad  # NEED_SCREEN_FACTOR x the screen's chord
    area = float(SEED000_CAMERA.width) * float(SEED000_CAMERA.height)
    return (np.ascontiguousarray(obs.vec, dtype=np.float64), np.asarray(hyp, np.int64), r, N_SCREENED, chord,
            RADIUS_PX, area, trials, 1e-5, 4, -1, -1, -1, g.cell, g.n_side, g.keys, g.starts, g.stars,
            star_vec64(db), g.columns)


@pytest.fixture(scope="module")
def big_frames():
    """Frames of seed 000's camera at 1 px with 2 false stars, more stars than the screen's 9 + 2."""
    frames = simulate_frames(SEED000_CAMERA, 40, SimConfig(centroid_noise_px=1.0, false_stars=2), rng=23)
    return [f for f in frames if len(f.centroids) > N_SCREENED + NEED_MAX_UNSCREENED][:10]


def test_the_true_attitude_could_pass_and_a_turned_one_could_not(seed000_db, big_frames) -> None:
    """At the true attitude a big frame's stars land on catalogue stars, as many as the bound
    needs; turned 5 degrees about the boresight, the same stars land on empty sky."""
    assert len(big_frames) >= 5
    turn = np.array([[math.cos(0.087), -math.sin(0.087), 0.0], [math.sin(0.087), math.cos(0.087), 0.0],
                     [0.0, 0.0, 1.0]])
    for f in big_frames:
        obs = _observation([(f.centroids, SEED000_CAMERA, None)], [np.eye(3)])
        r = quat_to_matrix(np.asarray(f.quaternion, float))
        assert could_pass_bound(*_args(seed000_db, obs, r, [0, 1, 2]))
        assert not could_pass_bound(*_args(seed000_db, obs, turn @ r, [0, 1, 2]))


def test_random_points_could_not_pass_but_a_small_frame_is_left_to_needed_hits(seed000_db, big_frames) -> None:
    """Random points under a real attitude explain too few of themselves; a frame of at most
    ``n_screened + NEED_MAX_UNSCREENED`` stars always could (``needed_hits`` screens it)."""
    r = quat_to_matrix(np.asarray(big_frames[0].quaternion, float))
    rng = np.random.default_rng(3)
    for _ in range(20):
        pts = random_points(SEED000_CAMERA, int(rng.integers(N_SCREENED + NEED_MAX_UNSCREENED + 1, 40)), rng)
        obs = _observation([(pts, SEED000_CAMERA, None)], [np.eye(3)])
        assert not could_pass_bound(*_args(seed000_db, obs, r, [0, 1, 2]))
        small = _observation([(pts.__class__(pts.xy[:N_SCREENED + NEED_MAX_UNSCREENED],
                                             pts.flux[:N_SCREENED + NEED_MAX_UNSCREENED]), SEED000_CAMERA, None)],
                             [np.eye(3)])
        assert could_pass_bound(*_args(seed000_db, small, r, [0, 1, 2]))


def test_the_count_asked_is_least_extras_of_every_other_star(seed000_db, big_frames) -> None:
    """The demand is the bound's own, ``least_extras`` of all the frame's other stars after
    ``trials``: with just that many true stars left where they are (the rest turned away from
    the sky's stars) the hypothesis could pass; with one fewer it could not."""
    f = big_frames[0]
    obs = _observation([(f.centroids, SEED000_CAMERA, None)], [np.eye(3)])
    r = quat_to_matrix(np.asarray(f.quaternion, float))
    n = len(obs)
    pair_p = math.pi * RADIUS_PX ** 2 / (SEED000_CAMERA.width * SEED000_CAMERA.height)
    need = least_extras(n - 3, pair_p, 50, 1e-5, 4)
    assert 1 <= need < n - 3
    true_rows = [m for m in range(3, n) if f.hip[obs.index[m]] >= 0]
    keep = true_rows[:need]
    assert len(keep) == need
    args = list(_args(seed000_db, obs, r, [0, 1, 2], trials=50))
    vec = args[0].copy()
    away = vec @ quat_to_matrix(np.array([math.cos(0.3), 0.0, math.sin(0.3), 0.0])).T  # 34 deg off
    for m in range(3, n):
        if m not in keep:
            vec[m] = away[m]
    args[0] = vec
    assert could_pass_bound(*args)
    vec[keep[-1]] = away[keep[-1]]
    assert not could_pass_bound(*args)
