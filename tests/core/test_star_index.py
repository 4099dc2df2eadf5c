"""The star indexes an opened database keeps (``service.core.star_index``)."""

from __future__ import annotations

import math

import numpy as np

from service.core.skygrid import build_sky_grid, collect_within, stars_within
from service.core.star_index import FIELD_CELL_DEG, field_grid, sky_grid, sky_mask, star_tree, star_vec64


def test_each_index_is_built_once_per_database(seed000_db) -> None:
    assert star_tree(seed000_db) is star_tree(seed000_db)
    assert sky_grid(seed000_db) is sky_grid(seed000_db)
    assert sky_mask(seed000_db, 1e-4) is sky_mask(seed000_db, 1e-4)
    assert sky_mask(seed000_db, 1e-4).reach >= 1e-4
    vec = star_vec64(seed000_db)
    assert vec is star_vec64(seed000_db)
    assert vec.dtype == np.float64 and vec.flags.c_contiguous and not vec.flags.writeable
    np.testing.assert_array_equal(vec, np.asarray(seed000_db.stars.vec, dtype=np.float64))


def test_field_grid_cell_follows_the_radius(seed000_db) -> None:
    """The largest cell of at most a 2.5th of the radius; the smallest for a small radius; up to
    2.5 radii for a test that stops at the first star."""
    assert math.degrees(field_grid(seed000_db, 1.0).cell) == FIELD_CELL_DEG[0]
    assert math.degrees(field_grid(seed000_db, 6.0).cell) == 2.0
    assert math.degrees(field_grid(seed000_db, 30.0).cell) == FIELD_CELL_DEG[-1]
    assert math.degrees(field_grid(seed000_db, 2.0, any_star=True).cell) == 4.0
    assert field_grid(seed000_db, 6.0) is field_grid(seed000_db, 7.0)  # the same cell, the same grid


def test_sky_grid_agrees_with_the_kd_tree(seed000_db) -> None:
    vec = np.asarray(seed000_db.stars.vec)
    grid = build_sky_grid(vec)
    rng = np.random.default_rng(3)
    pts = rng.normal(size=(4000, 3))
    pts /= np.linalg.norm(pts, axis=1, keepdims=True)
    pts[:1000] = vec[rng.integers(0, len(vec), 1000)] + rng.normal(scale=2e-3, size=(1000, 3))
    for chord in (1e-4, 1e-3, 6e-3):
        dist, _ = star_tree(seed000_db).query(pts, k=1, distance_upper_bound=chord)
        assert np.array_equal(stars_within(grid, pts, chord), np.isfinite(dist))


def test_every_field_grid_gathers_the_same_stars() -> None:
    """field_grid picks its cell by the query's radius; whatever the cell, a gathering holds
    exactly the stars within the chord (checked against a brute-force scan)."""
    gen = np.random.default_rng(4)
    vec = gen.normal(size=(20000, 3))
    vec /= np.linalg.norm(vec, axis=1, keepdims=True)
    grids = [build_sky_grid(vec, cell_rad=math.radians(c)) for c in FIELD_CELL_DEG]
    buf = np.empty(len(vec), np.int64)
    for radius_deg in (2.0, 6.0, 11.0, 21.0):
        chord = 2 * math.sin(math.radians(radius_deg) / 2)
        for p in vec[:20]:
            want = np.flatnonzero(np.linalg.norm(vec - p, axis=1) <= chord)
            for g in grids:
                n = collect_within(p[0], p[1], p[2], chord, g.cell, g.n_side, g.keys, g.starts, g.stars, g.vec,
                                   g.columns, buf)
                np.testing.assert_array_equal(np.sort(buf[:n]), want)


def test_star_neighbours_are_each_stars_nearest_others(seed000_db) -> None:
    """Every star's kept neighbours are its nearest other stars, nearest first (brute force on a
    sample), none of them itself."""
    from service.core.star_index import NEIGHBOURS, star_neighbours

    nb = star_neighbours(seed000_db)
    assert nb is star_neighbours(seed000_db)
    vec = np.asarray(seed000_db.stars.vec)
    assert nb.shape == (len(vec), NEIGHBOURS) and nb.dtype == np.int32 and not nb.flags.writeable
    rng = np.random.default_rng(4)
    for i in rng.choice(len(vec), 300, replace=False):
        d = np.linalg.norm(vec - vec[i], axis=1)
        d[i] = np.inf
        want = np.sort(d)[:NEIGHBOURS]
        assert i not in nb[i]
        np.testing.assert_allclose(d[nb[i]], want, rtol=0, atol=1e-12)
