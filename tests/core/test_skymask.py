"""The sky mask never hides a star within its reach, and clears most of the sky."""

from __future__ import annotations

import numpy as np
import pytest
from numba import njit

from service.core.screen import screen_hits
from service.core.skygrid import build_sky_grid, has_star_within
from service.core.skymask import build_sky_mask, may_hold_star
from service.core.star_index import sky_mask


@njit(cache=False)
def _both(points, chord, n, words, cell, n_side, keys, starts, stars, vec, columns):
    out = np.zeros((len(points), 2), np.bool_)
    for i in range(len(points)):
        p = points[i]
        out[i, 0] = may_hold_star(p[0], p[1], p[2], n, words)
        out[i, 1] = has_star_within(p[0], p[1], p[2], chord, cell, n_side, keys, starts, stars, vec, columns,
                                    -1, -1, -1)
    return out


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def _near(stars: np.ndarray, chord: float, rng: np.random.Generator, k: int) -> np.ndarray:
    """Points at up to ``chord`` from random stars (on the rim too)."""
    s = stars[rng.integers(len(stars), size=k)]
    t = _unit(np.cross(s, _unit(rng.normal(size=(k, 3)))))
    frac = rng.uniform(0, 1, k)
    frac[::2] = 0.999999
    ang = 2 * np.arcsin(chord / 2) * frac
    return _unit(s * np.cos(ang)[:, None] + t * np.sin(ang)[:, None])


@pytest.mark.parametrize("chord", [2e-5, 6.6e-4, 3e-3, 2e-2])
def test_every_point_near_a_star_is_marked(chord: float) -> None:
    rng = np.random.default_rng(7)
    stars = _unit(rng.normal(size=(4000, 3)))
    # stars on the cube's edges and corners, where the gnomonic faces meet and stretch most
    edges = _unit(np.array([[1, 1, 0], [1, -1, 1], [-1, 1, 1], [0, 1, -1], [1, 0, 1e-4], [-1, -1, -1]], float))
    stars = np.vstack([stars, edges, _unit(edges + 3 * chord)])
    mask = build_sky_mask(stars, chord)
    grid = build_sky_grid(stars)
    points = np.vstack([_near(stars, chord, rng, 20000), _near(stars[-12:], chord, rng, 5000)])
    got = _both(points, chord, mask.n, mask.words, grid.cell, grid.n_side, grid.keys, grid.starts, grid.stars,
                grid.vec, grid.columns)
    assert got[:, 1].mean() > 0.99  # the points are near stars...
    assert not (got[:, 1] & ~got[:, 0]).any()  # ...and the mask says so wherever the scan does


def test_most_of_the_sky_is_cleared(seed000_db) -> None:
    vec = np.asarray(seed000_db.stars.vec, dtype=np.float64)  # Hipparcos to V 6.5
    chord = 6.6e-4  # seed 000's screen at 1 px
    mask = build_sky_mask(vec, chord)
    grid = build_sky_grid(vec)
    points = _unit(np.random.default_rng(3).normal(size=(50000, 3)))
    got = _both(points, chord, mask.n, mask.words, grid.cell, grid.n_side, grid.keys, grid.starts, grid.stars,
                grid.vec, grid.columns)
    assert not (got[:, 1] & ~got[:, 0]).any()
    assert got[:, 0].mean() < 0.03  # ~1% of the sky is marked at this reach


def test_a_database_keeps_a_mask_per_rung_of_reach(seed000_db) -> None:
    db = seed000_db
    a = sky_mask(db, 1.0e-3)
    assert a.reach >= 1.0e-3 and a.reach < 1.0e-3 * 2 ** 0.25 * 1.001
    assert sky_mask(db, 1.01e-3) is a
    assert sky_mask(db, 3e-3) is not a


def test_a_screen_refuses_a_mask_of_smaller_reach() -> None:
    stars = _unit(np.random.default_rng(1).normal(size=(100, 3)))
    with pytest.raises(ValueError, match="reach"):
        screen_hits(stars, np.array([[0, 1, 2]]), np.array([[0, 1, 2]]), np.arange(5), build_sky_grid(stars),
                    1e-3, build_sky_mask(stars, 5e-4))
