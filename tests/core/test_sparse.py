"""Sparse fields: the 4x4 deg, 7.0 Mv camera of seed 002, where the median frame holds ~6 stars
and one in five holds three or fewer. A frame of three stars has no fourth star to confirm its
triangle; ``triangle`` proves it when the triangle matches one catalogue triple and the chance
that an unrelated triangle lands that close to a catalogue triangle consistent with the frame
is below the bound (``sparse_proof.check_unique_triangle``). Random 3-4 point frames are the
dangerous case: 1000 of them must all be refused."""

from __future__ import annotations

import numpy as np
import pytest

from service.core.evaluate import score
from service.core.navdb import NavDatabase, build_database, open_database
from service.core.pipeline import SolveOptions, solve
from service.core.presets import PRESETS
from service.core.sim import SimConfig, random_points, simulate_frames
from service.core.types import Centroids

PRESET = PRESETS["seed002"]
CAMERA = PRESET.camera
OPTIONS = SolveOptions(centroid_sigma_px=0.5)




@pytest.fixture(scope="module")
def db(tmp_path_factory: pytest.TempPathFactory) -> NavDatabase:
    path = tmp_path_factory.mktemp("sparse") / "seed002"
    build_database(path, PRESET.build_config(("triangle",)))
    return open_database(path)


@pytest.fixture(scope="module")
def frames():
    config = SimConfig(mag_limit=PRESET.mag_limit, centroid_noise_px=0.5)
    return simulate_frames(CAMERA, 500, config, rng=4002)


@pytest.mark.slow
def test_three_and_four_star_frames_are_proven_without_a_wrong_answer(db: NavDatabase, frames) -> None:
    solved: dict[int, list[bool]] = {}
    wrong = 0
    for f in frames:
        sol = solve(f.centroids, CAMERA, db, method="triangle", options=OPTIONS)
        s = score(sol, f.quaternion, f.hip.tolist(), blends=f.blends)
        wrong += s.solved and not s.correct
        solved.setdefault(min(len(f.centroids), 5), []).append(s.solved)
        if s.solved:
            assert sol.false_match_probability <= OPTIONS.max_false_prob
    assert wrong == 0
    assert not any(any(solved.get(n, [])) for n in (0, 1, 2))  # nothing to identify
    assert np.mean(solved[3]) >= 0.6  # measured 0.78 on these frames (docs/methods.md)
    assert np.mean(solved[4]) >= 0.97
    assert np.mean(solved[5]) >= 0.98


@pytest.mark.slow
def test_random_three_and_four_point_frames_never_solve(db: NavDatabase) -> None:
    for i in range(1000):
        pts = random_points(CAMERA, 3 + i % 2, rng=40_000 + i)
        assert not solve(pts, CAMERA, db, method="triangle", options=OPTIONS).solved


def test_a_star_the_camera_should_have_seen_refuses_the_frame(db: NavDatabase, frames) -> None:
    """Drop one real star well inside the image from 4-star frames: the three left may match
    their catalogue triangle uniquely, but that attitude predicts the dropped star, which
    nobody observed, so the frame is not proven (it is a different sky, or a faulty one)."""
    tested = 0
    for f in frames:
        if len(f.centroids) != 4 or f.blends:
            continue
        inside = CAMERA.contains(f.centroids.xy, margin_px=20.0)
        if not inside.all():
            continue
        keep = np.arange(3)
        cut = Centroids(f.centroids.xy[keep], f.centroids.flux[keep])
        assert not solve(cut, CAMERA, db, method="triangle", options=OPTIONS).solved
        tested += 1
    assert tested >= 10


def test_the_bound_tightens_with_the_mismatch(db: NavDatabase, frames) -> None:
    """The same three stars, moved 0.8 px apart from their true places, are proven with a
    larger coincidence probability, or not at all: the measured mismatch sets the box."""
    probs = []
    for f in frames:
        if len(f.centroids) != 3:
            continue
        sol = solve(f.centroids, CAMERA, db, method="triangle", options=OPTIONS)
        if not sol.solved:
            continue
        moved = f.centroids.xy + np.array([[0.8, 0.0], [-0.8, 0.0], [0.0, 0.8]])
        shifted = Centroids(moved, f.centroids.flux)
        sol2 = solve(shifted, CAMERA, db, method="triangle", options=OPTIONS)
        probs.append((sol.false_match_probability, sol2.false_match_probability if sol2.solved else 1.0))
        if len(probs) == 10:
            break
    assert len(probs) == 10
    assert sum(b > a for a, b in probs) >= 8


def test_a_sparse_frame_the_default_set_refuses_is_told_how_to_build_the_database_that_proves_it(
        db: NavDatabase, frames, default_set_db) -> None:
    # frames 50, 394, 462 and 471 of these 500 (4-5 stars): the default set's members
    # (density-capped, or to 7.0 Mv over 3.5-9 deg) cannot prove them; the camera's own database
    # (every star to 7.0 Mv) can, and the refusal says how to build it (429 and 450 were such
    # frames until the unique triangle was proven with its fourth star, sparse_others)
    for i in (471, 50):
        f = frames[i]
        refused = solve(f.centroids, CAMERA, default_set_db, options=OPTIONS)
        assert not refused.solved and 4 <= len(f.centroids) <= 5
        assert "skyfix db build --out db/camera --fov-min 4 --fov-max 5.9" in refused.message
        assert "--methods maxangle,pyramid,triangle --mag-limit V" in refused.message
        own = solve(f.centroids, CAMERA, db, method="triangle", options=OPTIONS)
        assert own.solved and score(own, f.quaternion, f.hip.tolist(), blends=f.blends).correct
    # no such advice from the camera's own database, nor for a frame of more stars
    assert "skyfix db build" not in solve(frames[76].centroids, CAMERA, db, options=OPTIONS).message
    crowded = random_points(CAMERA, 9, rng=2)
    assert "skyfix db build" not in solve(crowded, CAMERA, default_set_db, options=OPTIONS).message
