"""pyramid (Mortari 2004) on seed 002's camera (4 deg, 4096 px, 7.0 Mv: sparse fields, fine
pixels): frames of exactly four stars, which a proof must pair in full, and the early refusal of
those whose triangles match no catalogue triple."""

from __future__ import annotations

import numpy as np
import pytest

from service.core.evaluate import score
from service.core.methods import pyramid
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
    path = tmp_path_factory.mktemp("pyramid") / "seed002"
    build_database(path, PRESET.build_config(("pyramid",)))
    return open_database(path)


def _four_brightest_real(f) -> tuple[Centroids, list[int]]:
    real = np.flatnonzero(f.hip >= 0)
    keep = real[np.argsort(-f.centroids.flux[real], kind="stable")[:4]]
    return Centroids(f.centroids.xy[keep], f.centroids.flux[keep]), f.hip[keep].tolist()


@pytest.fixture
def joins(monkeypatch: pytest.MonkeyPatch) -> list[int]:
    """Counts pyramid's triangle look-ups."""
    calls: list[int] = []
    real = pyramid.join_windows

    def counted(*args):
        calls.append(1)
        return real(*args)

    monkeypatch.setattr(pyramid, "join_windows", counted)
    return calls


def test_four_real_stars_are_still_proven(db: NavDatabase) -> None:
    frames = simulate_frames(CAMERA, 60, SimConfig(mag_limit=PRESET.mag_limit, centroid_noise_px=0.5), rng=41)
    right = tried = 0
    for f in frames:
        if (f.hip >= 0).sum() < 4:
            continue
        tried += 1
        cents, hip = _four_brightest_real(f)
        sol = solve(cents, CAMERA, db, method="pyramid", options=OPTIONS)
        if sol.solved:
            s = score(sol, f.quaternion, hip)
            assert s.correct and s.wrong_stars == 0
            right += 1
    assert tried >= 20 and right >= 0.8 * tried, (right, tried)


def test_four_random_points_are_refused_after_two_empty_triangles(db: NavDatabase, joins: list[int]) -> None:
    """A proof of 4 stars pairs all 4, so every triangle of them must be a catalogue triangle:
    once ``EMPTY_TRIANGLES_TO_REFUSE`` of them match nothing, the frame is given up (5 or more
    stars: every triangle is looked up, any 4 of them may be the real ones)."""
    rng = np.random.default_rng(8)
    looked_up = {4: [], 5: []}
    for n in (4, 5):
        for _ in range(20):
            joins.clear()
            sol = solve(random_points(CAMERA, n, rng), CAMERA, db, method="pyramid", options=OPTIONS)
            assert not sol.solved
            looked_up[n].append(len(joins))
    assert max(looked_up[4]) <= pyramid.EMPTY_TRIANGLES_TO_REFUSE
    assert np.mean(looked_up[5]) > 2 * pyramid.EMPTY_TRIANGLES_TO_REFUSE
