"""The compiled tour kernels (:mod:`service.core.methods._tour_kernel`): exact tours are the
brute-force optimum, the local search ends where no 2-opt or or-opt move shortens the tour,
nearest-neighbour ties go to the lowest node."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from service.core.methods._tour import tour_length
from service.core.methods._tour_kernel import held_karp, local_search, nearest_neighbour


def _grid(n: int, seed: int, batch: int) -> np.ndarray:
    """Distances of points on a 4 x 4 integer grid: many equal lengths, the ties' test."""
    p = np.random.default_rng(seed).integers(0, 4, (batch, n, 2)).astype(float)
    p += np.random.default_rng(seed + 1).random((batch, n, 2)) * 1e-3 * (np.arange(n) > 0)[None, :, None]
    return np.linalg.norm(p[:, :, None] - p[:, None], axis=3)


def _moves(order: np.ndarray) -> list[np.ndarray]:
    """Every tour one 2-opt or or-opt move (segment 1-3, either way) from ``order``."""
    n, out = len(order), []
    for i, j in itertools.combinations(range(n), 2):
        if j >= i + 2 and not (i == 0 and j == n - 1):
            out.append(np.concatenate([order[:i + 1], order[i + 1:j + 1][::-1], order[j + 1:]]))
    for length in (1, 2, 3):
        for s in range(1, n - length + 1):
            seg, rest = order[s:s + length], np.concatenate([order[:s], order[s + length:]])
            for k in range(1, len(rest) + 1):
                for piece in (seg, seg[::-1]):
                    out.append(np.concatenate([rest[:k], piece, rest[k:]]))
    return out


@pytest.mark.parametrize("n", [3, 5, 7, 9])
def test_held_karp_is_the_brute_force_optimum(n: int) -> None:
    d = _grid(n, n, 6)
    order = held_karp(d)
    for b in range(len(d)):
        brute = min(tour_length(d[b], np.array((0, *p))) for p in itertools.permutations(range(1, n)))
        assert order[b, 0] == 0 and sorted(order[b]) == list(range(n))
        assert tour_length(d[b], order[b]) == pytest.approx(brute, abs=1e-12)


@pytest.mark.parametrize("n", [6, 11, 16])
def test_local_search_ends_at_a_local_optimum(n: int) -> None:
    d = _grid(n, 30 + n, 8)
    start = nearest_neighbour(d, np.zeros(len(d), np.int64))
    order = local_search(d, start, 4 * n * n)
    for b in range(len(d)):
        length = tour_length(d[b], order[b])
        assert order[b, 0] == 0 and sorted(order[b]) == list(range(n))
        assert length <= tour_length(d[b], start[b]) + 1e-12
        assert min(tour_length(d[b], m) for m in _moves(order[b]) if m[0] == 0) >= length - 1e-9


def test_nearest_neighbour_takes_the_lowest_of_equal_nodes() -> None:
    p = np.array([[0.0, 0.0], [1.0, 0.0], [-1.0, 0.0], [0.0, 1.0], [3.0, 3.0]])
    d = np.linalg.norm(p[:, None] - p[None], axis=2)[None]
    assert nearest_neighbour(d, np.array([0])).tolist() == [[0, 1, 3, 2, 4]]
    assert nearest_neighbour(d, np.array([4])).tolist() == [[0, 2, 3, 4, 1]]  # 4 -> 1 (tied with 3) -> 0 -> 2
