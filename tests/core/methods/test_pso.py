"""pso (seed 004) on its paper's camera: the tour searches, the adaptive circle, the tables, and
the acceptance bar (>= 99% of 500 frames at 0.5 px, no wrong answer, random points refused)."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from service.core.evaluate import score
from service.core.methods import get_matcher
from service.core.methods._tour import _crossover, _mutate, best_tours, first_three, pso_tour, tour_length
from service.core.methods.pso import KEY_STRIDE, PsoMatcher, edge_distance, radius_code
from service.core.navdb import BuildConfig, NavDatabase, build_database, open_database
from service.core.pipeline import SolveOptions, solve
from service.core.presets import PRESETS
from service.core.sim import BLEND_DEG, BLEND_PX, SimConfig, random_points, simulate_frames

CAMERA = PRESETS["seed004"].camera
OPTIONS = SolveOptions(centroid_sigma_px=0.5)


def seed004_config() -> BuildConfig:
    """Seed 004's camera; doubles merged at the camera's own resolution (2 px), as it sees them."""
    sep = max(BLEND_PX / CAMERA.f_px * 180 / math.pi, BLEND_DEG)
    return BuildConfig(fov_max_deg=CAMERA.diagonal_fov_deg + 0.2, fov_min_deg=CAMERA.fov_deg, mag_limit=6.5,
                       epoch=2026.0, double_star_sep_deg=sep, methods=("pso",))


@pytest.fixture(scope="module")
def db(tmp_path_factory: pytest.TempPathFactory) -> NavDatabase:
    path = tmp_path_factory.mktemp("pso") / "seed004"
    build_database(path, seed004_config())
    return open_database(path)


def _plane(n: int, seed: int, batch: int = 1) -> np.ndarray:
    p = np.random.default_rng(seed).random((batch, n, 2))
    return np.linalg.norm(p[:, :, None] - p[:, None], axis=3)


# ---- tours --------------------------------------------------------------------------------
@pytest.mark.parametrize("n", [4, 5, 6, 7, 8])
def test_exact_tours_are_shortest(n: int) -> None:
    d = _plane(n, n, batch=10)
    order, length = best_tours(d)
    for b in range(10):
        brute = min(tour_length(d[b], np.array((0, *p))) for p in itertools.permutations(range(1, n)))
        assert length[b] == pytest.approx(brute, abs=1e-12)
        assert order[b, 0] == 0 and sorted(order[b]) == list(range(n))


@pytest.mark.parametrize("n", [12, 20, 30])
def test_deterministic_tours_ignore_star_numbering(n: int) -> None:
    d = _plane(n, 100 + n, batch=20)
    _, length = best_tours(d)
    perm = np.concatenate([[0], 1 + np.random.default_rng(n).permutation(n - 1)])
    order2, length2 = best_tours(d[:, perm][:, :, perm])
    np.testing.assert_allclose(length, length2, rtol=0, atol=1e-12)
    assert np.all(np.sort(order2, axis=1) == np.arange(n))


def test_local_search_close_to_exact() -> None:
    d = _plane(11, 7, batch=200)
    _, exact = best_tours(d, exact_max_nodes=11)
    _, heur = best_tours(d, exact_max_nodes=4)
    assert np.all(heur >= exact - 1e-12)
    assert np.mean(heur - exact < 1e-9) >= 0.95


def test_pso_finds_small_optimum_and_is_seeded() -> None:
    d = _plane(7, 1)[0]
    _, exact = best_tours(d[None])
    order, length = pso_tour(d, rng=5)
    assert length == pytest.approx(exact[0], abs=1e-12)
    assert order[0] == 0 and sorted(order) == list(range(7))
    assert pso_tour(d, rng=5)[1] == length


@settings(max_examples=50, deadline=None)
@given(st.integers(3, 30), st.integers(1, 12), st.integers(0, 2**31))
def test_swarm_operators_keep_permutations(m: int, particles: int, seed: int) -> None:
    gen = np.random.default_rng(seed)
    x = np.argsort(gen.random((particles, m)), axis=1) + 1
    best = np.argsort(gen.random((particles, m)), axis=1) + 1
    d = _plane(m + 1, seed % 1000)[0]
    for y in (_crossover(x, best, gen), _mutate(d, x, gen)):
        assert np.all(np.sort(y, axis=1) == np.arange(1, m + 1))


def test_first_three_reads_the_tour_towards_the_nearer_neighbour() -> None:
    pts = np.array([[0, 0], [3, 0], [3, 3], [0, 1.0]])  # tour 0-1-2-3: node 3 is nearer the centre
    d = np.linalg.norm(pts[:, None] - pts[None], axis=2)[None]
    s2, s3 = first_three(d, np.array([[0, 1, 2, 3]]))
    assert (s2[0], s3[0]) == (3, 2)


# ---- circle and image geometry ------------------------------------------------------------
def test_radius_rule() -> None:
    assert radius_code(np.array([0, 5, 6, 25, 26])).tolist() == [2, 2, 1, 1, 0]


def test_edge_distance() -> None:
    v = CAMERA.pixel_to_vector(np.array([[511.5, 511.5], [-0.5, 300.0], [511.5, 100.0]]))
    e = np.degrees(edge_distance(CAMERA, v))
    assert e[0] == pytest.approx(10.0, abs=1e-6)
    assert e[1] == pytest.approx(0.0, abs=1e-6)
    assert 0 < e[2] < 10


# ---- tables -------------------------------------------------------------------------------
def test_every_star_has_a_feature(db: NavDatabase) -> None:
    t = db.tables["pso"]
    key = np.asarray(t["key"])
    assert np.all(np.diff(key) >= 0)
    covered = np.unique(np.asarray(t["ids"])[:, 0])
    assert len(covered) >= 0.99 * len(db.stars)
    sides = np.asarray(t["sides"], np.float64)
    vec = db.stars.vec
    ids = np.asarray(t["ids"])[:50]
    for (a, b, c), s in zip(ids, sides[:50], strict=True):
        got = [math.acos(min(1.0, vec[a] @ vec[b])), math.acos(min(1.0, vec[b] @ vec[c])),
               math.acos(min(1.0, vec[a] @ vec[c]))]
        np.testing.assert_allclose(got, s, atol=1e-6)
    codes = np.floor(key / KEY_STRIDE)
    assert set(np.unique(codes)) <= {0.0, 1.0, 2.0}


# ---- identification -----------------------------------------------------------------------
@pytest.mark.slow
def test_identifies_99_percent_with_no_wrong_answer(db: NavDatabase) -> None:
    frames = simulate_frames(CAMERA, 500, SimConfig(mag_limit=6.5, centroid_noise_px=0.5), rng=4004)
    solved = wrong = 0
    for f in frames:
        sol = solve(f.centroids, CAMERA, db, method="pso", options=OPTIONS)
        s = score(sol, f.quaternion, f.hip.tolist(), blends=f.blends)
        solved += s.solved
        wrong += bool(s.solved and not s.correct)
        if s.solved:
            assert sol.method == "pso" and s.cross_boresight_arcsec < 60  # 1 px = 71 arcsec
    assert wrong == 0
    assert solved >= 0.99 * len(frames)


@pytest.mark.slow
def test_random_points_never_solve(db: NavDatabase) -> None:
    for i in range(50):  # 20-119 points (~0.1 s each: the swarm's tours run out; 100 until session 25)
        pts = random_points(CAMERA, 20 + (7 * i) % 100, rng=i)
        assert not solve(pts, CAMERA, db, method="pso", options=OPTIONS).solved


@pytest.mark.parametrize("variant", [("pso", "paper"), ("exact", "paper"), ("pso", "robust")])
def test_other_variants_identify(db: NavDatabase, variant: tuple[str, str]) -> None:
    """The paper's own reading (swarm on the sky side, its filter cascade) and the mixed ones."""
    frames = simulate_frames(CAMERA, 8, SimConfig(mag_limit=6.5, centroid_noise_px=0.5), rng=44)
    matcher = PsoMatcher(db, sky_tour=variant[0], matching=variant[1])
    db.__dict__.setdefault("_matchers", {})["pso"] = matcher
    try:
        results = [solve(f.centroids, CAMERA, db, method="pso", options=SolveOptions(centroid_sigma_px=0.5,
                                                                                     timeout_ms=5000))
                   for f in frames]
    finally:
        db.__dict__["_matchers"].pop("pso")
    scores = [score(r, f.quaternion, f.hip.tolist(), blends=f.blends)
              for r, f in zip(results, frames, strict=True)]
    assert all(s.correct for s in scores if s.solved)
    assert sum(s.solved for s in scores) >= 6
    assert matcher.tours >= 8


def test_default_matcher_is_the_robust_deterministic_one(db: NavDatabase) -> None:
    m = get_matcher(db, "pso")
    assert isinstance(m, PsoMatcher) and (m.sky_tour, m.matching) == ("exact", "robust")
    with pytest.raises(ValueError):
        PsoMatcher(db, sky_tour="annealing")
