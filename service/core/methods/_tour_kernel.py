"""Compiled kernels of :mod:`._tour`'s deterministic tours: Held-Karp, nearest-neighbour starts
and the 2-opt / or-opt local search, one tour at a time.

They make the moves the vectorised numpy versions made over a batch (the same first minimum
among equal gains, in the same order of move kinds, the same sums), so the tours, and the
``pso`` tables built from them, are the same; a tour of a batch never depended on the others.
The numpy versions held a batch's ``(B, L, m, m)`` and ``(B, n, n)`` intermediates and ran
~90 rounds of array calls a chunk: 8.9 s of seed 004's 9.6 s table build (session 37).
Distances are angles (rad), ``(B, n, n)`` batches, nodes numbered by distance from node 0.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from ..types import FloatArray, IntArray


@njit(cache=True, nogil=True)
def held_karp(d: FloatArray) -> IntArray:
    """Exact shortest closed tours from node 0 of each ``(n, n)`` matrix of ``d`` ``(B, n, n)``
    (``n >= 2``): ``(B, n)`` int64, ``order[:, 0] == 0``. Among equal costs the lowest
    predecessor (and last node), as ``np.argmin`` took them."""
    bsz, n = d.shape[0], d.shape[1]
    m = n - 1
    full = (1 << m) - 1
    order = np.zeros((bsz, n), np.int64)
    cost = np.empty((1 << m, m))
    parent = np.zeros((1 << m, m), np.int8)
    pop = np.zeros(1 << m, np.int64)
    for mask in range(1, 1 << m):
        pop[mask] = pop[mask >> 1] + (mask & 1)
    for b in range(bsz):
        cost[:, :] = np.inf
        for j in range(m):
            cost[1 << j, j] = d[b, 0, j + 1]
        for size in range(2, m + 1):
            for mask in range(1, 1 << m):
                if pop[mask] != size:
                    continue
                for j in range(m):
                    if mask & (1 << j) == 0:
                        continue
                    prev = mask ^ (1 << j)
                    best = np.inf
                    k_best = 0
                    first = True
                    for k in range(m):
                        g = cost[prev, k] + d[b, k + 1, j + 1]
                        if first or g < best:
                            best, k_best, first = g, k, False
                    cost[mask, j] = best
                    parent[mask, j] = k_best
        last = 0
        best = np.inf
        for j in range(m):
            t = cost[full, j] + d[b, j + 1, 0]
            if j == 0 or t < best:
                best, last = t, j
        mask = full
        for pos in range(m, 0, -1):
            order[b, pos] = last + 1
            nxt = parent[mask, last]
            mask ^= 1 << last
            last = nxt
    return order


@njit(cache=True, nogil=True)
def nearest_neighbour(d: FloatArray, start: IntArray) -> IntArray:
    """Nearest-neighbour tours of ``d`` ``(B, n, n)`` from node ``start[b]``, rotated to begin
    at node 0; ties to the lowest node."""
    bsz, n = d.shape[0], d.shape[1]
    out = np.zeros((bsz, n), np.int64)
    tour = np.zeros(n, np.int64)
    visited = np.zeros(n, np.bool_)
    for b in range(bsz):
        visited[:] = False
        cur = start[b]
        tour[0] = cur
        visited[cur] = True
        for pos in range(1, n):
            best = np.inf
            arg = 0
            for j in range(n):
                v = np.inf if visited[j] else d[b, cur, j]
                if v < best:
                    best, arg = v, j
            cur = arg
            tour[pos] = cur
            visited[cur] = True
        zero = 0
        for pos in range(n):
            if tour[pos] == 0:
                zero = pos
                break
        for pos in range(n):
            out[b, pos] = tour[(pos + zero) % n]
    return out


@njit(cache=True, nogil=True)
def local_search(d: FloatArray, order: IntArray, rounds: int) -> IntArray:
    """Best-improvement 2-opt and or-opt (segments of 1-3, either orientation) on each tour of
    ``order`` ``(B, n)`` over ``d`` ``(B, n, n)`` until no move shortens it, at most ``rounds``
    moves. The best move of a round is the first minimum in the order 2-opt ``(i, j)``, then
    or-opt by segment length, forward before reversed, each by ``(s, k)``; a later kind
    replaces it only if strictly better."""
    bsz, n = order.shape
    out = order.copy()
    p = np.empty((n, n))
    e = np.empty(n)
    tour = np.empty(n, np.int64)
    for b in range(bsz):
        o = out[b]
        for _ in range(rounds):
            for x in range(n):
                for y in range(n):
                    p[x, y] = d[b, o[x], o[y]]
            for c in range(n):
                e[c] = p[c, (c + 1) % n]
            best = np.inf
            arg = 0
            kind = 0
            for i in range(n):
                for j in range(i + 2, n):
                    if i == 0 and j == n - 1:
                        continue
                    delta = p[i, j] + p[(i + 1) % n, (j + 1) % n] - e[i] - e[j]
                    if delta < best:
                        best, arg = delta, i * n + j
            for length in range(1, 4):
                if length > n - 2:
                    break
                for r in range(2):
                    cand = np.inf
                    cand_arg = 0
                    for s in range(1, n - length + 1):
                        tail = s + length - 1
                        after = (s + length) % n
                        gain = e[s - 1] + e[tail] - p[s - 1, after]
                        for k in range(n):
                            if not (k < s - 1 or k > tail):
                                continue
                            if r == 0:
                                delta = p[k, s] + p[tail, (k + 1) % n] - e[k] - gain
                            else:
                                delta = p[k, tail] + p[s, (k + 1) % n] - e[k] - gain
                            if delta < cand:
                                cand, cand_arg = delta, (s - 1) * n + k
                    if cand < best:
                        best, arg, kind = cand, cand_arg, 2 * length - 1 + r
            total = 0.0
            for c in range(n):
                total += e[c]
            if not best < -1e-12 * max(total, 1e-9):
                break
            a, c = arg // n, arg % n
            if kind == 0:  # 2-opt: positions a+1..c reversed
                for q in range(n):
                    tour[q] = o[a + 1 + c - q] if a + 1 <= q <= c else o[q]
            else:  # or-opt: positions a+1..a+L moved between c and c+1 (c outside them), reversed if kind is even
                seg_len = (kind + 1) // 2
                w = 0
                for q in range(n):
                    if a + 1 <= q <= a + seg_len:
                        continue
                    tour[w] = o[q]
                    w += 1
                    if q == c:
                        for t in range(seg_len):
                            tour[w] = o[a + 1 + t] if kind % 2 == 1 else o[a + seg_len - t]
                            w += 1
            o[:] = tour
    return out
