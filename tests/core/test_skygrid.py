"""Sky grid queries (``skygrid``): the stars within a chord of points, against brute force."""

from __future__ import annotations

import numpy as np

from service.core.skygrid import build_sky_grid, fields_within


def _sky(n: int, seed: int) -> np.ndarray:
    v = np.random.default_rng(seed).normal(size=(n, 3))
    return v / np.linalg.norm(v, axis=1, keepdims=True)


def test_fields_within_is_every_star_within_each_chord() -> None:
    """Each point's rows are exactly the stars within its chord (any order), concatenated in
    the points' order with their offsets; a point with none gives an empty run."""
    vec = _sky(20_000, 1)
    grid = build_sky_grid(vec, cell_rad=np.radians(4.0))
    points = _sky(6, 2)
    chords = np.array([0.02, 0.1, 0.3, 0.05, 1e-6, 0.2])
    near, off = fields_within(grid, points, chords)
    assert off[0] == 0 and off[-1] == len(near) and np.all(np.diff(off) >= 0)
    for c in range(len(points)):
        want = np.flatnonzero(np.sum((vec - points[c]) ** 2, axis=1) <= chords[c] ** 2)
        assert sorted(near[off[c]:off[c + 1]].tolist()) == want.tolist()
    assert off[5] == off[4]  # the 1e-6 chord holds no star
    assert off[3] - off[2] > 300  # a wide one holds many (~2% of the sky)
