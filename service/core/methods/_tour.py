"""Shortest closed tours through small star sets: deterministic (exact or local search) and
the hybrid particle swarm of seed 004.

A tour starts and ends at node 0 (the centre star) and visits every other node once. Distances
are angles in radians, given as ``(n, n)`` matrices (or ``(B, n, n)`` batches of equal size).

- :func:`best_tours` is deterministic, over a batch, each tour by a compiled kernel
  (:mod:`._tour_kernel`): Held-Karp dynamic programming
  (exact) up to ``EXACT_MAX_NODES`` nodes; above that, the shortest of ``START_TOURS``
  nearest-neighbour tours (started from the centre and from the stars nearest it), each
  improved by best-improvement 2-opt and or-opt moves (segments of 1-3 stars, either
  orientation) until no move shortens it. The result depends on the geometry only, not on
  how the stars are numbered, so the catalogue side and the sky side agree whenever their
  star sets agree (and the local search reaches the exact optimum of 11-12 stars in 99% of
  random cases, 97% of 22-star ones measured against many more starts).
- :func:`pso_tour` is the paper's hybrid particle swarm (Mao et al., seed 004): particles are
  permutations; each iteration crosses every particle with its personal best and then with the
  global best (a random segment of the best is deleted from the particle and re-inserted whole
  at its position in the best), mutates it (an edge is chosen with probability proportional to
  its length and another star is moved in between its ends) and updates the personal best with
  simulated-annealing acceptance. Vectorised over the particles; seeded.
"""

from __future__ import annotations

import numpy as np

from ..types import FloatArray, IntArray
from ._tour_kernel import held_karp, local_search, nearest_neighbour

EXACT_MAX_NODES = 10
"""Tours of up to this many nodes (centre included) are solved exactly by Held-Karp."""
START_TOURS = 8
"""Larger tours: best local optimum of this many nearest-neighbour starts."""


def tour_length(dist: FloatArray, order: IntArray) -> FloatArray:
    """Closed-tour length of ``order`` ``(..., n)`` over ``dist`` ``(..., n, n)``."""
    d = np.asarray(dist)
    o = np.asarray(order)
    nxt = np.roll(o, -1, axis=-1)
    if d.ndim == 2:
        return np.asarray(d[o, nxt].sum(axis=-1))
    b = np.arange(d.shape[0])[:, None]
    return np.asarray(d[b, o, nxt].sum(axis=-1))


def first_three(dist: FloatArray, order: IntArray) -> tuple[IntArray, IntArray]:
    """The tour's second and third stars (nodes) for tours ``order`` ``(B, n)``: star 2 is
    whichever neighbour of the centre in the tour is nearer the centre (the direction the tour
    is read in), star 3 the next one in that direction (seed 004, 1.2 step 3)."""
    b = np.arange(order.shape[0])
    fwd, back = order[:, 1], order[:, -1]
    use_fwd = dist[b, 0, fwd] <= dist[b, 0, back]
    s2 = np.where(use_fwd, fwd, back)
    s3 = np.where(use_fwd, order[:, 2 % order.shape[1]], order[:, -2])
    return s2, s3


# ---- deterministic ---------------------------------------------------------------------------
def best_tours(
    dist: FloatArray, *, exact_max_nodes: int = EXACT_MAX_NODES, starts: int = START_TOURS
) -> tuple[IntArray, FloatArray]:
    """Shortest closed tours from node 0 of a batch ``(B, n, n)`` of distance matrices.

    Returns ``order`` ``(B, n)`` int64 (``order[:, 0] == 0``) and ``length`` ``(B,)``. Exact
    for ``n <= exact_max_nodes``; otherwise the best of ``starts`` 2-opt + or-opt local optima,
    started from nearest-neighbour tours from the centre and from the stars nearest it. The
    result does not depend on how the nodes are numbered (catalogue and sky number them
    differently), only on the geometry.
    """
    d = np.asarray(dist, dtype=np.float64)
    bsz, n = d.shape[0], d.shape[1]
    if bsz == 0:
        return np.zeros((0, n), np.int64), np.zeros(0)
    if n <= 3:
        order = np.broadcast_to(np.arange(n), (bsz, n)).copy()
        return order, tour_length(d, order)
    # number the nodes by distance from the centre: the start tours become label-free
    perm = np.argsort(d[:, 0, :], axis=1, kind="stable")
    b = np.arange(bsz)[:, None, None]
    ds = d[b, perm[:, :, None], perm[:, None, :]]
    if n <= exact_max_nodes:
        order = _held_karp(ds)
    else:
        k = min(starts, n)
        chunk = max(1, 2_000_000 // (n * n * k))  # bounds the repeated matrices: ~16 MB
        order = np.concatenate([_multi_start(ds[i:i + chunk], k) for i in range(0, bsz, chunk)])
    order = np.take_along_axis(perm, order, axis=1)
    return order, tour_length(d, order)


def _multi_start(d: FloatArray, k: int) -> IntArray:
    """Best local optimum over nearest-neighbour starts from nodes ``0..k-1``."""
    bsz, n = d.shape[0], d.shape[1]
    rep = np.repeat(d, k, axis=0)
    start = np.tile(np.arange(k), bsz)
    tours = _local_search(rep, _nearest_neighbour(rep, start))
    lengths = tour_length(rep, tours).reshape(bsz, k)
    # shortest; among (numerically) equal lengths the lowest start, so ties resolve alike
    best = np.argmax(lengths <= lengths.min(axis=1, keepdims=True) * (1 + 1e-12), axis=1)
    return tours.reshape(bsz, k, n)[np.arange(bsz), best]


def _held_karp(d: FloatArray) -> IntArray:
    """Exact shortest tours by dynamic programming over subsets (:func:`._tour_kernel.held_karp`)."""
    return held_karp(np.ascontiguousarray(d, dtype=np.float64))


def _nearest_neighbour(d: FloatArray, start: IntArray | None = None) -> IntArray:
    """Nearest-neighbour tours from node ``start`` (default 0), rotated to begin at node 0."""
    d = np.ascontiguousarray(d, dtype=np.float64)
    first = np.zeros(d.shape[0], np.int64) if start is None else np.ascontiguousarray(start, dtype=np.int64)
    return nearest_neighbour(d, first)


def _local_search(d: FloatArray, order: IntArray, max_rounds: int | None = None) -> IntArray:
    """Best-improvement 2-opt and or-opt until no move shortens any tour of the batch
    (:func:`._tour_kernel.local_search`; at most ``4 n^2`` moves a tour unless ``max_rounds``)."""
    n = order.shape[1]
    rounds = max_rounds if max_rounds is not None else 4 * n * n
    return local_search(np.ascontiguousarray(d, dtype=np.float64), np.ascontiguousarray(order, dtype=np.int64),
                        int(rounds))


# ---- hybrid particle swarm (seed 004) --------------------------------------------------------
def pso_tour(
    dist: FloatArray,
    *,
    particles: int = 80,
    iterations: int = 200,
    rng: np.random.Generator | int | None = None,
    t0_frac: float = 0.02,
    cooling: float = 0.97,
) -> tuple[IntArray, float]:
    """A short closed tour from node 0 by the hybrid particle swarm of seed 004.

    Parameters
    ----------
    dist : (n, n) float64
        Distance matrix, node 0 the centre star.
    particles, iterations : int
        The paper's 80 and 200.
    rng : numpy.random.Generator or int, optional
        Randomness (seeded for reproducible runs).
    t0_frac, cooling : float
        Simulated annealing: initial temperature as a fraction of the mean initial tour length,
        multiplied by ``cooling`` every iteration.

    Returns
    -------
    order : (n,) int64
        The best tour found (``order[0] == 0``).
    length : float
    """
    d = np.asarray(dist, dtype=np.float64)
    n = d.shape[0]
    if n <= 3:
        order = np.arange(n)
        return order, float(tour_length(d, order))
    gen = np.random.default_rng(rng)
    m = n - 1
    x = np.argsort(gen.random((particles, m)), axis=1) + 1  # current tours, centre implicit
    fit = _pso_lengths(d, x)
    pbest, pfit = x.copy(), fit.copy()
    g = int(np.argmin(pfit))
    best, best_len = pbest[g].copy(), float(pfit[g])
    temp = t0_frac * float(fit.mean())
    for _ in range(iterations):
        x = _crossover(x, pbest, gen)
        x = _crossover(x, np.broadcast_to(best, x.shape), gen)
        x = _mutate(d, x, gen)
        fit = _pso_lengths(d, x)
        delta = fit - pfit
        accept = (delta < 0) | (gen.random(particles) < np.exp(-np.maximum(delta, 0) / max(temp, 1e-300)))
        pbest[accept], pfit[accept] = x[accept], fit[accept]
        g = int(np.argmin(pfit))
        if pfit[g] < best_len:
            best, best_len = pbest[g].copy(), float(pfit[g])
        temp *= cooling
    order = np.concatenate([[0], best]).astype(np.int64)
    return order, float(tour_length(d, order))


def _pso_lengths(d: FloatArray, x: IntArray) -> FloatArray:
    """Closed-tour lengths of particles ``x`` ``(P, m)`` (the centre, node 0, implicit)."""
    return d[0, x[:, 0]] + d[x[:, :-1], x[:, 1:]].sum(axis=1) + d[x[:, -1], 0]


def _crossover(x: IntArray, best: IntArray, gen: np.random.Generator) -> IntArray:
    """Take a random segment of each particle's ``best``, delete its stars from the particle,
    and insert the segment whole at the position it has in ``best``."""
    p, m = x.shape
    a = gen.integers(0, m, p)
    b = gen.integers(0, m, p)
    lo, hi = np.minimum(a, b), np.maximum(a, b) + 1  # segment best[lo:hi]
    seglen = hi - lo
    pos = np.arange(m)
    n_nodes = m + 1
    pos_in_best = np.empty((p, n_nodes), np.int64)
    np.put_along_axis(pos_in_best, best, np.broadcast_to(pos, (p, m)), axis=1)
    at = np.take_along_axis(pos_in_best, x, axis=1)  # position of each of x's stars in best
    in_seg = (at >= lo[:, None]) & (at < hi[:, None])
    rank = np.cumsum(~in_seg, axis=1) - 1  # rank among the kept stars
    keys = np.where(in_seg, at, np.where(rank < lo[:, None], rank, rank + seglen[:, None]))
    out = np.empty_like(x)
    np.put_along_axis(out, keys, x, axis=1)
    return out


def _mutate(d: FloatArray, x: IntArray, gen: np.random.Generator) -> IntArray:
    """Pick an edge with probability proportional to its length (long edges are the likely
    detours) and move a random other star in between its two ends."""
    p, m = x.shape
    ends = np.concatenate([np.zeros((p, 1), np.int64), x, np.zeros((p, 1), np.int64)], axis=1)
    edge = d[ends[:, :-1], ends[:, 1:]]  # (p, m + 1): edge k joins slot k-1 and slot k
    cum = np.cumsum(edge, axis=1)
    u = np.asarray(gen.random(p))
    k = (cum < u[:, None] * cum[:, -1:]).sum(axis=1)
    k = np.minimum(k, m)
    q = gen.integers(0, m, p)  # the star to move (its slot)
    keys = np.broadcast_to(2.0 * np.arange(m), (p, m)).copy()
    keys[np.arange(p), q] = 2.0 * k - 1.0  # between slot k-1 and slot k
    return np.take_along_axis(x, np.argsort(keys, axis=1, kind="stable"), axis=1)
