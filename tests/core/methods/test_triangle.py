"""triangle (Liebe's classic) on seed 000's camera: the pair index, the triangle look-up, and
the acceptance bar (>= 99% of 500 frames at 0.5 px, no wrong answer, random points refused)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from service.core.evaluate import score
from service.core.methods import get_matcher
from service.core.methods.triangle import TriangleMatcher, build_kvector, kvector_range
from service.core.navdb import NavDatabase, build_database, open_database
from service.core.pipeline import SolveOptions, solve
from service.core.sim import SimConfig, simulate_frames
from tests.conftest import SEED000_CAMERA, seed000_config
from tests.core.acceptance import assert_refuses_random_points, tally

CAMERA = SEED000_CAMERA
OPTIONS = SolveOptions(centroid_sigma_px=0.5)


@pytest.fixture(scope="module")
def db(tmp_path_factory: pytest.TempPathFactory) -> NavDatabase:
    path = tmp_path_factory.mktemp("triangle") / "seed000"
    build_database(path, seed000_config(("triangle",)))
    return open_database(path)


@pytest.fixture(scope="module")
def frames():
    return simulate_frames(CAMERA, 500, SimConfig(mag_limit=6.5, centroid_noise_px=0.5), rng=2000)


@settings(max_examples=60, deadline=None)
@given(st.lists(st.floats(0.0, 0.1, allow_nan=False), min_size=2, max_size=400, unique=True),
       st.floats(0.0, 0.12), st.floats(0.0, 0.02))
def test_kvector_range_holds_every_value_in_range(values: list[float], lo: float, width: float) -> None:
    y = np.sort(np.asarray(values))
    k, m, q = build_kvector(y)
    s, e = kvector_range(k, m, q, np.array([lo]), np.array([lo + width]))
    inside = np.flatnonzero((y >= lo) & (y <= lo + width))
    assert np.all((inside >= s[0]) & (inside < e[0]))


def test_kvector_index_agrees_with_searchsorted(db: NavDatabase) -> None:
    m = TriangleMatcher(db)
    k, m_, q = build_kvector(np.asarray(m.angles))
    mk = TriangleMatcher(db)
    mk.kvector, mk.kv_line = k, (m_, q)
    rng = np.random.default_rng(3)
    lo = rng.uniform(0.0, math.radians(8.0), 50)
    hi = lo + rng.uniform(0.0, 1e-3, 50)
    for a, b in zip(m.windows(lo, hi), mk.windows(lo, hi), strict=True):
        assert np.array_equal(a, b)


def test_triples_hold_the_true_triangle(db: NavDatabase) -> None:
    f = simulate_frames(CAMERA, 1, SimConfig(mag_limit=6.5, centroid_noise_px=0.5), rng=11)[0]
    row = {int(h): i for i, h in enumerate(db.stars.hip)}
    v = CAMERA.pixel_to_vector(f.centroids.xy[:3])
    truth = [row[int(h)] for h in f.hip[:3]]
    tol = (3 * math.sqrt(2) * 0.5 + 0.5) * CAMERA.pixel_scale_rad
    cands = get_matcher(db, "triangle").triples(v, tol)
    assert any(list(c) == truth for c in cands)
    mirrored = v * np.array([-1.0, 1.0, 1.0])  # a mirror image never matches
    assert not any(list(c) == truth for c in get_matcher(db, "triangle").triples(mirrored, tol))


@pytest.mark.slow
def test_identifies_99_percent_with_no_wrong_answer(db: NavDatabase, frames) -> None:
    solved, wrong = tally(frames, CAMERA, db, "triangle", OPTIONS)
    assert wrong == 0
    assert solved >= 0.99 * len(frames)


@pytest.mark.slow
def test_random_points_never_solve(db: NavDatabase) -> None:
    assert_refuses_random_points(CAMERA, db, "triangle", seed=10_000, options=OPTIONS)


def test_classic_brightness_order_solves_too(db: NavDatabase) -> None:
    classic = TriangleMatcher(db, order="brightness")
    db.__dict__.setdefault("_matchers", {})
    saved = db.__dict__["_matchers"].get("triangle")
    db.__dict__["_matchers"]["triangle"] = classic
    try:
        config = SimConfig(mag_limit=6.5, centroid_noise_px=0.5, false_stars=1)
        for f in simulate_frames(CAMERA, 20, config, rng=5):
            sol = solve(f.centroids, CAMERA, db, method="triangle", options=OPTIONS)
            assert score(sol, f.quaternion, f.hip.tolist(), blends=f.blends).correct is not False
    finally:
        if saved is None:
            del db.__dict__["_matchers"]["triangle"]
        else:
            db.__dict__["_matchers"]["triangle"] = saved


def test_compiled_joins_give_the_vectorised_join_in_its_order(db: NavDatabase) -> None:
    # the windows of the density box (wide: tens of thousands of pairs) and of a query
    from service.core.methods._pairs import (
        LINKED_JOIN_MAX_ROWS,
        edge_keys,
        join_triangles,
        join_windows,
        join_windows_counting,
        join_windows_linked,
    )

    m = get_matcher(db, "triangle")
    pairs, angles = np.asarray(m.pairs), np.asarray(m.angles)

    def edges(s: int, e: int) -> np.ndarray:  # both orientations, stably sorted by first star
        p = pairs[s:e].astype(np.int64)
        both = np.concatenate([p, p[:, ::-1]])
        return both[np.argsort(both[:, 0], kind="stable")]

    rng = np.random.default_rng(5)
    compared = small = 0
    for width in (2e-6, 2e-5, 2e-4, 2e-3):
        for _ in range(6):
            sides = rng.uniform(0.01, m.max_angle * 0.9, 3)
            s = np.searchsorted(angles, sides - width)
            e = np.searchsorted(angles, sides + width, side="right")
            want = join_triangles(edges(s[0], e[0]), edges(s[1], e[1]), edge_keys(edges(s[2], e[2]), m.n_stars),
                                  m.n_stars)
            rows = (pairs, int(s[0]), int(e[0]), int(s[1]), int(e[1]), int(s[2]), int(e[2]))
            heads = np.full(m.n_stars, -1, np.int64), np.full(m.n_stars, -1, np.int64)
            for got in (join_windows(*rows, m.n_stars), join_windows_counting(*rows, m.n_stars),
                        join_windows_linked(*rows, *heads)):
                np.testing.assert_array_equal(got, want.reshape(-1, 3))
            assert (heads[0] == -1).all() and (heads[1] == -1).all()  # left as found
            compared += len(want)
            small += int((e - s).sum()) <= LINKED_JOIN_MAX_ROWS
    assert compared > 100 and small >= 6


def test_small_window_joins_run_side_by_side_on_threads(db: NavDatabase) -> None:
    # the linked-list join keeps its scratch per thread: joins on four threads at once give
    # what the counting sort gives one at a time
    from concurrent.futures import ThreadPoolExecutor

    from service.core.methods._pairs import LINKED_JOIN_MAX_ROWS, join_windows, join_windows_counting

    m = get_matcher(db, "triangle")
    pairs, angles = np.asarray(m.pairs), np.asarray(m.angles)
    vec = np.asarray(db.stars.vec, np.float64)
    rng = np.random.default_rng(11)
    jobs = []
    while len(jobs) < 1500:  # catalogue triangles: a star and two of its neighbours
        a = int(rng.integers(len(vec)))
        near = np.flatnonzero(vec @ vec[a] > math.cos(m.max_angle * 0.6))
        near = near[near != a]
        if len(near) < 2:
            continue
        b, c = rng.choice(near, 2, replace=False)
        sides = np.arccos(np.clip([vec[a] @ vec[b], vec[a] @ vec[c], vec[b] @ vec[c]], -1, 1))
        s = np.searchsorted(angles, sides - 2e-5)
        e = np.searchsorted(angles, sides + 2e-5, side="right")
        jobs.append((pairs, int(s[0]), int(e[0]), int(s[1]), int(e[1]), int(s[2]), int(e[2]), m.n_stars))
    want = [join_windows_counting(*job) for job in jobs]
    with ThreadPoolExecutor(4) as pool:
        got = list(pool.map(lambda job: join_windows(*job), jobs))
    assert sum(len(w) for w in want) >= 1300  # nearly every job holds its own triangle
    assert sum(sum(j[k + 1] - j[k] for k in (1, 3, 5)) <= LINKED_JOIN_MAX_ROWS for j in jobs) > 1100
    for w, g in zip(want, got, strict=True):
        np.testing.assert_array_equal(g, w)


def test_triangles_pyramid_joined_in_vain_are_not_joined_again(default_set_db, monkeypatch) -> None:
    """On seed 002's 4-star frames with 2 false stars, ``pyramid`` then ``triangle`` search the
    same member's pair table: the triangles pyramid found matching no catalogue triple are
    skipped by triangle (``_pairs.empty_triangles``), with the same answer."""
    from service.core.methods.base import SolveContext
    from service.core.pipeline import _observation
    from service.core.presets import PRESETS
    from service.core.verify import Verifier

    p = PRESETS["seed002"]
    member = default_set_db.members["sparse"]
    frames = [f for f in simulate_frames(p.camera, 400, SimConfig(mag_limit=p.mag_limit, centroid_noise_px=0.5,
                                                                   false_stars=2), rng=12) if len(f.centroids) == 4]
    assert len(frames) >= 10
    tri = get_matcher(member, "triangle")
    calls = []
    real = TriangleMatcher.triples
    monkeypatch.setattr(TriangleMatcher, "triples", lambda self, v, eps: calls.append(1) or real(self, v, eps))
    skipped = 0
    for frame in frames[:10]:
        answers = []
        for after_pyramid in (False, True):
            obs = _observation([(frame.centroids, p.camera, None)], [np.eye(3)])
            ver = Verifier(member, obs, match_radius_px=2.5)
            tol = (3.0 * math.sqrt(2.0) * 0.5 + 0.5) * obs.pixel_scale_rad
            if after_pyramid:
                get_matcher(member, "pyramid").identify(SolveContext(obs, ver, tol, math.inf, 8))
            calls.clear()
            answers.append((tri.identify(SolveContext(obs, ver, tol, math.inf, 8)), len(calls)))
        (alone, n_alone), (after, n_after) = answers
        assert (alone is None) == (after is None)
        skipped += n_alone - n_after
    assert skipped >= 10


def test_density_box_joins_without_a_usable_table(db: NavDatabase) -> None:
    """A database without ``maxangle`` has no box table: the box is the join."""
    tri = get_matcher(db, "triangle")
    assert tri.box_table is None
    v = np.asarray(db.stars.vec)[:3]
    np.testing.assert_array_equal(tri.box_triples(v, 1e-3), tri.triples(v, 1e-3, pivot_longest=True))


def test_selective_order_is_the_pair_windows_order(default_set_db) -> None:
    """The compiled order of a frame's triangles (most distinctive first, ``_selective_order``)
    is the one the pair windows' counts give in numpy, ties kept in ``combinations`` order."""
    from itertools import combinations

    from service.core.geometry import pairwise_angles
    from service.core.methods.triangle import _selective_order

    member = default_set_db.members["sparse"]
    angles = np.asarray(member.tables["triangle"]["angles"])
    vec = np.asarray(member.stars.vec)
    rng = np.random.default_rng(4)
    for n, eps in ((3, 1e-4), (4, 8e-5), (5, 3e-4), (7, 1e-3)):
        c = vec[int(rng.integers(len(vec)))]
        near = np.flatnonzero(vec @ c > math.cos(math.radians(3.0)))
        d = pairwise_angles(vec[rng.choice(near, n, replace=False)])
        count = np.ones((n, n))
        for i, j in combinations(range(n), 2):
            s, e = np.searchsorted(angles, d[i, j] - eps, "left"), np.searchsorted(angles, d[i, j] + eps, "right")
            count[i, j] = count[j, i] = max(e - s, 1)
        cost = [count[i, j] * count[i, k] * count[j, k] for i, j, k in combinations(range(n), 3)]
        assert _selective_order(angles, d, n, eps).tolist() == np.argsort(cost, kind="stable").tolist()
