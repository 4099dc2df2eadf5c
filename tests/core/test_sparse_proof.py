"""The sparse proof's compiled field test counts what the vectorised k-d tree version counted."""

from __future__ import annotations

import math

import numpy as np
import pytest

from service.core.attitude import quat_to_matrix
from service.core.navdb import NavDatabase
from service.core.pipeline import _observation
from service.core.sim import SimConfig, simulate_frames
from service.core.sparse_proof import _field_check, _without_triple
from service.core.star_index import star_tree
from service.core.verify import Verifier
from tests.conftest import SEED000_CAMERA


def _field_check_numpy(verifier: Verifier, rs, cands, obs_idx, max_near: int = 96):
    """The vectorised version this module replaced (k-d tree, K x max_near arrays)."""
    obs = verifier.obs
    stars = verifier.db.stars.vec
    tree = star_tree(verifier.db)
    rad = verifier.match_radius_px
    unseen = np.zeros(len(rs), dtype=np.int64)
    explained = np.zeros(len(rs), dtype=np.int64)
    for c, cam in enumerate(obs.cameras):
        r_cam = np.einsum("ij,kjl->kil", obs.mountings[c], rs)
        half = math.radians(cam.diagonal_fov_deg / 2 + 0.2)
        kk = min(max_near, len(stars))
        _, near = tree.query(r_cam[:, 2, :], k=kk, distance_upper_bound=2 * math.sin(half / 2))
        near = np.asarray(near).reshape(len(rs), kk)
        valid = near < len(stars)
        valid &= ~(near[:, :, None] == cands[:, None, :]).any(axis=2)
        k_of = np.nonzero(valid)[0]
        star = near[valid]
        v_cam = np.einsum("nij,nj->ni", r_cam[k_of], stars[star])
        pxy, inside = cam.vector_to_pixel(v_cam)
        k_all, p_all = k_of[inside], pxy[inside]
        rows = np.setdiff1d(obs.by_camera[c], obs_idx)
        edge = cam.contains(p_all, margin_px=rad)
        if len(rows) and len(p_all):
            close = ((p_all[:, None, :] - obs.xy[rows][None, :, :]) ** 2).sum(axis=2) <= rad * rad
            seen = close.any(axis=1)
            kr = np.unique((k_all[:, None] * len(rows) + np.arange(len(rows))[None, :])[close])
            explained += np.bincount(kr // len(rows), minlength=len(rs))
        else:
            seen = np.zeros(len(p_all), bool)
        unseen += np.bincount(k_all[edge & ~seen], minlength=len(rs))
    return unseen, explained


def test_compiled_field_check_counts_as_the_kd_tree_version(seed000_db: NavDatabase) -> None:
    # attitudes near each frame's truth (stars seen, explained, missed at the edges) and anywhere
    # on the sky, with random catalogue triples left out of the field
    frames = simulate_frames(SEED000_CAMERA, 6, SimConfig(mag_limit=6.5, centroid_noise_px=0.5, false_stars=2), rng=3)
    rng = np.random.default_rng(8)
    n_stars = len(seed000_db.stars.vec)
    total = 0
    for frame in frames:
        obs = _observation([(frame.centroids, SEED000_CAMERA, None)], [np.eye(3)])
        verifier = Verifier(seed000_db, obs, match_radius_px=3.0)
        truth = quat_to_matrix(np.asarray(frame.quaternion))
        tilts = [quat_to_matrix(np.r_[1.0, rng.normal(0, s, 3)]) for s in [0.0] * 3 + [1e-4] * 20 + [2e-3] * 20]
        near = np.stack([t @ truth for t in tilts])
        anywhere = quat_to_matrix(rng.normal(size=(40, 4)))
        rs = np.concatenate([near, anywhere])
        cands = rng.integers(0, n_stars, (len(rs), 3))
        obs_idx = np.arange(3)
        for max_near in (96, 8):  # 8: fewer than the field holds (the nearest are kept)
            got = _field_check(verifier, rs, cands, obs_idx, max_near=max_near)
            want = _field_check_numpy(verifier, rs, cands, obs_idx, max_near=max_near)
            np.testing.assert_array_equal(got[0], want[0])
            np.testing.assert_array_equal(got[1], want[1])
        total += int(want[1][:3].sum())
    assert total > 0  # the true attitudes explain observed stars


def test_could_explain_never_counts_fewer_than_the_field_check(seed000_db: NavDatabase) -> None:
    """``check_unique_triangle`` screens its density box with ``_could_explain`` before the field
    check; the screen must count at least what the field check's ``explained`` counts, on every
    triple (the true one, triples of neighbouring stars, random ones), or the box's count ``k`` of
    consistent triangles would change."""
    from service.core.sparse_proof import _could_explain, _sparse_attitudes

    frames = simulate_frames(SEED000_CAMERA, 8, SimConfig(mag_limit=6.5, centroid_noise_px=0.5, false_stars=2), rng=5)
    rng = np.random.default_rng(9)
    hip_rows = {int(h): i for i, h in enumerate(np.asarray(seed000_db.stars.hip))}
    tree = star_tree(seed000_db)
    stars = np.asarray(seed000_db.stars.vec)
    passed_random = checked_random = explained_true = 0
    for frame in frames:
        obs = _observation([(frame.centroids, SEED000_CAMERA, None)], [np.eye(3)])
        verifier = Verifier(seed000_db, obs, match_radius_px=3.0)
        hips = frame.hip[obs.index]
        real = [i for i in range(len(obs)) if hips[i] >= 0 and int(hips[i]) in hip_rows][:3]
        obs_idx = np.array(real)
        true = np.array([hip_rows[int(hips[i])] for i in real])
        neighbours = [tree.query(stars[t], k=6)[1][1:] for t in true]  # a vertex moved to a nearby star
        near = np.array([[rng.choice(neighbours[0]) if j == 0 else true[0], rng.choice(neighbours[1]), true[2]]
                         for j in range(30)])
        random = rng.integers(0, len(stars), (300, 3))
        random = random[[len(set(t)) == 3 for t in random.tolist()]]
        near = near[[len(set(t)) == 3 for t in near.tolist()]]
        box = np.concatenate([true[None], near, random])
        could = _could_explain(verifier, box, obs_idx)
        _, explained = _field_check(verifier, _sparse_attitudes(obs.vec[obs_idx], stars, box), box, obs_idx)
        assert np.all(could >= explained)
        explained_true += int(explained[0])
        checked_random += len(random)
        passed_random += int(np.count_nonzero(could[-len(random):] >= max(int(explained[0]), 1)))
    assert explained_true > 0  # the true triangle explains the frame's other stars
    assert passed_random < 0.05 * checked_random  # and the screen leaves few random triples to check


@pytest.mark.parametrize("false_stars", [0, 1])
def test_a_star_in_view_is_one_the_field_check_counts_unseen(seed000_db: NavDatabase, false_stars: int) -> None:
    """A frame of a triangle (and a false star): ``_star_in_view`` marks a box triple whose
    attitude puts another catalogue star in the circle a match radius inside the image, away
    from every other observed star; the field check must count that triple unseen (so dropping
    it cannot change the proof), and the screen must drop most triples."""
    from service.core.sparse_proof import _sparse_attitudes, _star_in_view
    from service.core.types import Centroids

    frames = simulate_frames(SEED000_CAMERA, 8, SimConfig(mag_limit=6.5, centroid_noise_px=0.5), rng=6)
    rng = np.random.default_rng(10)
    hip_rows = {int(h): i for i, h in enumerate(np.asarray(seed000_db.stars.hip))}
    stars = np.asarray(seed000_db.stars.vec)
    marked = total = 0
    for frame in frames:
        real = [i for i in np.argsort(-frame.centroids.flux) if frame.hip[i] >= 0 and int(frame.hip[i]) in hip_rows][:3]
        xy, flux = frame.centroids.xy[real], frame.centroids.flux[real]
        if false_stars:  # a fainter false star anywhere in the image
            xy = np.vstack([xy, rng.uniform(0, 1023, (false_stars, 2))])
            flux = np.append(flux, np.full(false_stars, flux.min() / 2))
        obs = _observation([(Centroids(xy, flux), SEED000_CAMERA, None)], [np.eye(3)])
        verifier = Verifier(seed000_db, obs, match_radius_px=3.0)
        obs_idx = np.arange(3)
        true = np.array([hip_rows[int(frame.hip[real[int(i)]])] for i in obs.index[:3]])
        box = np.concatenate([true[None], rng.integers(0, len(stars), (300, 3))])
        box = box[[len(set(t)) == 3 for t in box.tolist()]]
        in_view = _star_in_view(verifier, box, obs_idx)
        unseen, _ = _field_check(verifier, _sparse_attitudes(obs.vec[obs_idx], stars, box), box, obs_idx)
        assert np.all(unseen[in_view] > 0)
        marked += int(in_view.sum())
        total += len(box)
    assert marked > 0.8 * total


def test_sparse_attitudes_are_the_triad_rotations_to_the_bit(seed000_db: NavDatabase) -> None:
    """The compiled TRIAD rotations equal the numpy formula they replaced, to the bit (the proofs'
    counts then cannot move), and map each triple's first star onto the first observed one."""
    from service.core.geometry import cross
    from service.core.sparse_proof import _sparse_attitudes
    from service.core.star_index import star_vec64

    def frames(a, b):
        t1 = a / np.linalg.norm(a, axis=-1, keepdims=True)
        t2 = cross(a, b)
        t2 /= np.linalg.norm(t2, axis=-1, keepdims=True)
        return np.stack([t1, t2, cross(t1, t2)], axis=-1)

    rng = np.random.default_rng(11)
    stars = star_vec64(seed000_db)
    obs = rng.normal(size=(3, 3))
    obs /= np.linalg.norm(obs, axis=1, keepdims=True)
    box = rng.integers(0, len(stars), (2000, 3))
    got = _sparse_attitudes(obs, stars, box)
    want = np.einsum("ij,kmj->kim", frames(obs[0][None], obs[1][None])[0], frames(stars[box[:, 0]], stars[box[:, 1]]))
    assert np.array_equal(got, want)
    np.testing.assert_allclose(np.einsum("kij,kj->ki", got, stars[box[:, 0]]), np.broadcast_to(obs[0], (2000, 3)),
                               atol=1e-12)


@pytest.mark.parametrize("extra", [0, 1, 2])
def test_box_screens_short_cuts_change_no_count(seed000_db: NavDatabase, extra: int) -> None:
    """``_box_kernel``'s short cuts (the triple's stars' neighbours tested first, the sky mask's
    clear bits) give the counts of the plain scan: the in-view test (with ``extra`` other observed
    stars to stay away from, some placed on a neighbour of the triple's stars) and the explain test,
    on the true triple, triples of its neighbours and random ones."""
    from service.core.sparse_proof import _box_kernel
    from service.core.star_index import field_grid, sky_grid, sky_mask, star_neighbours, star_vec64

    frames = simulate_frames(SEED000_CAMERA, 6, SimConfig(mag_limit=6.5, centroid_noise_px=0.5), rng=12)
    rng = np.random.default_rng(13)
    hip_rows = {int(h): i for i, h in enumerate(np.asarray(seed000_db.stars.hip))}
    stars = star_vec64(seed000_db)
    nb = star_neighbours(seed000_db)
    no_nb = np.zeros((0, 1), np.int32)
    no_nb.flags.writeable = False
    none_mask = np.zeros(1, np.uint64)
    grid, fg = sky_grid(seed000_db), field_grid(seed000_db, 2.0, any_star=True)
    found = {"in_view": 0, "explained": 0}
    for frame in frames:
        truth = quat_to_matrix(np.asarray(frame.quaternion))  # ICRS -> camera (= body)
        real = [i for i in np.argsort(-frame.centroids.flux) if frame.hip[i] >= 0 and int(frame.hip[i]) in hip_rows]
        true = np.array([hip_rows[int(frame.hip[i])] for i in real[:3]])
        tri_vec = np.ascontiguousarray(stars[true] @ truth.T)
        near = np.array([[nb[t][rng.integers(0, 4)] if rng.random() < 0.5 else t for t in true] for _ in range(60)])
        box = np.concatenate([true[None], near, rng.integers(0, len(stars), (300, 3))]).astype(np.int64)
        box = box[[len(set(t)) == 3 for t in box.tolist()]]
        # stars to stay away from: the neighbours of the triple's stars where the true attitude puts them
        away = np.ascontiguousarray(stars[nb[true[:extra], 0]] @ truth.T) if extra else np.zeros((0, 3))
        bore = np.array([[0.0, 0.0, 1.0]])
        args = (tri_vec, bore, away, box, 2 * math.sin(math.radians(2.0) / 2), 2 * math.sin(math.radians(0.05) / 2),
                fg.cell, fg.n_side, fg.keys, fg.starts, fg.stars, fg.vec, fg.columns)
        plain = _box_kernel(*args, 0, none_mask, no_nb)
        np.testing.assert_array_equal(_box_kernel(*args, 0, none_mask, nb), plain)
        found["in_view"] += int(np.count_nonzero(plain))
        others = np.ascontiguousarray(stars[[hip_rows[int(frame.hip[i])] for i in real[3:8]]] @ truth.T)
        chord = 1e-4
        mask = sky_mask(seed000_db, chord)
        args = (tri_vec, others, np.zeros((0, 3)), box, chord, 0.0, grid.cell, grid.n_side, grid.keys, grid.starts,
                grid.stars, grid.vec, grid.columns)
        plain = _box_kernel(*args, 0, none_mask, no_nb)
        np.testing.assert_array_equal(_box_kernel(*args, mask.n, mask.words, no_nb), plain)
        found["explained"] += int(plain[0])
    assert found["in_view"] > 0 and found["explained"] > 0


def test_box_screens_neighbour_short_cut_keeps_the_scans_exclusions(seed000_db: NavDatabase) -> None:
    """Crafted in-view tests where the only star near the point is a neighbour the scan must not
    count: one of the triple's own stars, or one next to a star to stay away from. The short cut
    must answer as the scan does (0), and count the neighbour where nothing excludes it (1)."""
    from service.core.sparse_proof import _box_kernel
    from service.core.star_index import field_grid, star_neighbours, star_vec64

    stars = star_vec64(seed000_db)
    nb = star_neighbours(seed000_db)
    none_mask = np.zeros(1, np.uint64)
    fg = field_grid(seed000_db, 2.0, any_star=True)
    rng = np.random.default_rng(14)
    counted = {"own": 0, "away": 0, "free": 0}
    for t in rng.choice(len(stars), 400, replace=False):
        n1, n2 = int(nb[t, 0]), int(nb[t, 1])
        d1, d2 = np.linalg.norm(stars[n1] - stars[t]), np.linalg.norm(stars[n2] - stars[t])
        if d2 < 1.05 * d1:
            continue  # the first neighbour alone within the chord
        chord = 1.02 * d1
        others = rng.integers(0, len(stars), 2)
        if np.min(np.linalg.norm(stars[others] - stars[t], axis=1)) < 2 * chord:
            continue
        point = np.ascontiguousarray(stars[t][None])
        cases = {"own": (np.array([[t, n1, others[0]]]), np.zeros((0, 3))),
                 "away": (np.array([[t, others[0], others[1]]]), np.ascontiguousarray(stars[n1][None])),
                 "free": (np.array([[t, others[0], others[1]]]), np.zeros((0, 3)))}
        for name, (box, away) in cases.items():
            tri_vec = np.ascontiguousarray(stars[box[0]])  # body = ICRS
            args = (tri_vec, point, away, box.astype(np.int64), float(chord), 1e-7, fg.cell, fg.n_side, fg.keys,
                    fg.starts, fg.stars, fg.vec, fg.columns, 0, none_mask)
            want = _box_kernel(*args, np.zeros((0, 1), np.int32))
            assert _box_kernel(*args, nb)[0] == want[0]
            counted[name] += int(want[0])
    assert counted["own"] == 0 and counted["away"] == 0 and counted["free"] > 50


def test_the_box_without_the_match_is_the_masks() -> None:
    """``_without_triple`` drops every row equal to the match, keeps the rest in order (as the
    boolean mask it replaced), and returns the box whole when the match is not in it."""
    rng = np.random.default_rng(5)
    box = rng.integers(0, 6, (400, 3))
    for a, b, c in [(1, 2, 3), (0, 0, 0), (9, 9, 9)]:
        mask = (box[:, 0] != a) | (box[:, 1] != b) | (box[:, 2] != c)
        np.testing.assert_array_equal(_without_triple(box, a, b, c), box[mask])
    assert len(_without_triple(box, 9, 9, 9)) == len(box)
    assert len(_without_triple(box[:0].copy(), 1, 2, 3)) == 0


@pytest.mark.parametrize("n_away", [0, 3])
def test_box_kernel_counts_what_a_brute_force_count_finds(seed000_db: NavDatabase, n_away: int) -> None:
    """``_box_kernel``'s scan (written out in the kernel, session 42) against every star of the
    catalogue: per triple, how many points (body) have a star other than the triple within the
    chord, and farther than the away chord from every away point, under the triple's TRIAD
    attitude (``_sparse_attitudes``: ICRS -> body). With and without the neighbour short cut."""
    from service.core.sparse_proof import _box_kernel, _sparse_attitudes
    from service.core.star_index import field_grid, star_neighbours, star_vec64

    rng = np.random.default_rng(42)
    stars = star_vec64(seed000_db)
    nb = star_neighbours(seed000_db)
    no_nb = np.zeros((0, 1), np.int32)
    fg = field_grid(seed000_db, 2.0, any_star=True)
    tri_vec = rng.normal(size=(3, 3))
    tri_vec /= np.linalg.norm(tri_vec, axis=1, keepdims=True)
    points = rng.normal(size=(4, 3))
    points /= np.linalg.norm(points, axis=1, keepdims=True)
    away = points[:n_away] + rng.normal(scale=0.02, size=(n_away, 3))  # ~1.5 deg off: some stars near both
    away /= np.linalg.norm(away, axis=1, keepdims=True) if n_away else 1.0
    box = rng.integers(0, len(stars), (200, 3))
    box = box[[len(set(t)) == 3 for t in box.tolist()]].astype(np.int64)
    chord, away_chord = 2 * math.sin(math.radians(2.0) / 2), 2 * math.sin(math.radians(1.0) / 2)
    args = (tri_vec, points, np.ascontiguousarray(away.reshape(-1, 3)), box, chord, away_chord, fg.cell,
            fg.n_side, fg.keys, fg.starts, fg.stars, fg.vec, fg.columns, 0, np.zeros(1, np.uint64))
    rs = _sparse_attitudes(tri_vec, stars, box)
    want = np.zeros(len(box), np.int64)
    unaway = np.zeros(len(box), np.int64)  # the same count without the away test
    for k, r in enumerate(rs):
        p_icrs, a_icrs = points @ r, away.reshape(-1, 3) @ r  # body -> ICRS: r^T v
        ok = np.ones(len(stars), bool)
        ok[box[k]] = False
        if n_away:
            ok &= (np.linalg.norm(stars[:, None] - a_icrs[None], axis=2) > away_chord).all(axis=1)
        near = np.linalg.norm(stars[None] - p_icrs[:, None], axis=2) <= chord
        want[k] = int((near & ok[None]).any(axis=1).sum())
        ok[:] = True
        ok[box[k]] = False
        unaway[k] = int((near & ok[None]).any(axis=1).sum())
    assert want.sum() > 0 and (want < len(points)).any()
    assert (want < unaway).any() == bool(n_away)  # the away test decides some points
    np.testing.assert_array_equal(_box_kernel(*args, no_nb), want)
    np.testing.assert_array_equal(_box_kernel(*args, nb), want)
