"""Star-pair tables sorted by angular separation (the k-vector family's core).

pyramid, triangle and multifov read one pair table, stored once in the database's shared
``pairs/`` group (:class:`SharedPairs`): it covers the union of their limits, and each method
uses the rows within its own (:meth:`SharedPairs.rows`).
"""

from __future__ import annotations

import functools
import math
import threading
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
from numba import njit
from scipy.spatial import cKDTree

from ..geometry import chord_from_angle, cross
from ..types import FloatArray


def build_pair_table(vec: FloatArray, max_angle_rad: float, min_angle_rad: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """All star pairs with ``min < angle <= max``, sorted by angle.

    Returns ``pairs`` ``(M, 2)`` int32 (row indices, smaller first) and ``angles`` ``(M,)``
    float64 radians.
    """
    tree = cKDTree(vec)
    pairs = tree.query_pairs(float(chord_from_angle(max_angle_rad)), output_type="ndarray")
    if len(pairs) == 0:
        return np.zeros((0, 2), np.int32), np.zeros(0)
    chord = np.linalg.norm(vec[pairs[:, 0]] - vec[pairs[:, 1]], axis=1)
    ang = 2 * np.arcsin(np.clip(chord / 2, 0, 1))
    keep = ang > min_angle_rad
    pairs, ang = pairs[keep], ang[keep]
    order = np.argsort(ang, kind="stable")
    return np.sort(pairs[order], axis=1).astype(np.int32), ang[order]


@dataclass(frozen=True)
class PairLimits:
    """The pairs one method needs: separations in ``(min_angle_deg, max_angle_deg]``, degrees."""

    max_angle_deg: float
    min_angle_deg: float = 0.0


def pair_limits(config: Any, params: Mapping[str, Any]) -> PairLimits:
    """Limits of a pair-table method: ``max_angle_deg`` from its build parameters, else the
    database's largest field ``config.fov_max_deg`` (the image diagonal), degrees."""
    return PairLimits(float(params.get("max_angle_deg", config.fov_max_deg)))


@dataclass(frozen=True)
class SharedPairs:
    """One pair table serving several methods (the database's ``pairs/`` group).

    Attributes
    ----------
    pairs : (M, 2) int32
        Star rows, smaller first, sorted by separation.
    angles : (M,) float64
        Their separations, radians, ascending.
    limits : PairLimits
        What the table holds: the union of its users' limits, degrees.
    """

    pairs: np.ndarray
    angles: np.ndarray
    limits: PairLimits

    def rows(self, limits: PairLimits) -> tuple[int, int]:
        """Row range ``[start, end)`` of the pairs within ``limits`` (which must lie inside the
        table's): the pairs ``build_pair_table`` returns for those limits, in the same order
        (bar a pair within rounding of a limit). The whole table where the limits are the
        table's own."""
        own, whole = limits, self.limits
        if own.max_angle_deg > whole.max_angle_deg or own.min_angle_deg < whole.min_angle_deg:
            raise ValueError(f"pair limits {own} exceed the shared table's {whole}")
        start = 0
        if own.min_angle_deg > whole.min_angle_deg:
            start = int(np.searchsorted(self.angles, math.radians(own.min_angle_deg), side="right"))
        end = len(self.angles)
        if own.max_angle_deg < whole.max_angle_deg:
            end = int(np.searchsorted(self.angles, math.radians(own.max_angle_deg), side="right"))
        return start, end

    def view(self, limits: PairLimits) -> tuple[np.ndarray, np.ndarray]:
        """``(pairs, angles)`` within ``limits``: views of the shared arrays, no copy."""
        start, end = self.rows(limits)
        return self.pairs[start:end], self.angles[start:end]


def require_shared(shared: SharedPairs | None, method: str) -> SharedPairs:
    """``shared``, or a clear error for a method that reads the shared pair table but was
    built without one (outside ``navdb.build_database``)."""
    if shared is None:
        raise ValueError(f"{method} reads the shared pair table: build it with navdb.build_database")
    return shared


def build_shared_pairs(vec: FloatArray, limits: Iterable[PairLimits]) -> SharedPairs:
    """The pair table of stars ``vec`` ``(N, 3)`` covering every one of ``limits`` (the largest
    maximum and the smallest minimum separation)."""
    lim = list(limits)
    if not lim:
        raise ValueError("a shared pair table needs at least one user")
    union = PairLimits(max(x.max_angle_deg for x in lim), min(x.min_angle_deg for x in lim))
    max_rad, min_rad = math.radians(union.max_angle_deg), math.radians(union.min_angle_deg)
    pairs, angles = build_pair_table(vec, max_rad, min_rad)
    return SharedPairs(pairs, angles, union)


def directed_edges(pairs: np.ndarray, angles: np.ndarray, lo: float, hi: float) -> np.ndarray:
    """Catalogue pairs with angle in ``[lo, hi]``, in both orientations: ``(2K, 2)`` int64
    sorted by first column."""
    i, j = np.searchsorted(angles, [lo, hi], side="left")
    j = np.searchsorted(angles, hi, side="right")
    p = pairs[i:j].astype(np.int64)
    both = np.concatenate([p, p[:, ::-1]])
    return both[np.argsort(both[:, 0])]  # any order inside a vertex group will do; quicksort is 5x faster


def pattern_order(n: int) -> list[tuple[int, int, int]]:
    """Triangles of ``n`` stars in Mortari's pyramid order, which changes every star quickly
    so that one false star cannot spoil a long run of attempts."""
    out = []
    for dj in range(1, n - 1):
        for dk in range(1, n - dj):
            for i in range(0, n - dj - dk):
                out.append((i, i + dj, i + dj + dk))
    return out


@functools.lru_cache(maxsize=64)
def upper_pairs(n: int) -> tuple[np.ndarray, np.ndarray]:
    """``np.triu_indices(n, 1)``, kept per ``n`` (~15 us a call; read only)."""
    rows, cols = np.triu_indices(n, 1)
    rows.flags.writeable = cols.flags.writeable = False
    return rows, cols


def pair_windows(angles: np.ndarray, d: np.ndarray, tol: float) -> tuple[np.ndarray, np.ndarray]:
    """Row ranges ``[start, end)`` (``(n, n)`` each, symmetric) of the sorted pair ``angles``
    within ``tol`` of each observed pair angle ``d[i, j]`` (rad), looked up once a pair: a
    search of a 6-million-row table (the ``narrow`` member's) reads ~23 cold cache lines."""
    n = len(d)
    rows, cols = upper_pairs(n)
    vals = d[rows, cols]
    start = np.zeros((n, n), np.int64)
    end = np.zeros((n, n), np.int64)
    start[rows, cols] = start[cols, rows] = np.searchsorted(angles, vals - tol, side="left")
    end[rows, cols] = end[cols, rows] = np.searchsorted(angles, vals + tol, side="right")
    return start, end


def empty_triangles(obs: Any, pairs: np.ndarray, tol: float) -> set[tuple[int, int, int]]:
    """The triangles (observed rows, ascending) of this frame known to match no catalogue triple
    of the pair table ``pairs`` (its rows, in place) with the same handedness at side tolerance
    ``tol``: ``pyramid`` notes those it joined in vain, and ``triangle``, searching the same
    member's table after it, skips them (kept with the frame's observation)."""
    key = (pairs.__array_interface__["data"][0], len(pairs), float(tol))
    known = obs.__dict__.setdefault("_empty_triangles", {})
    got = known.get(key)
    if got is None:
        got = known[key] = set()
    return got


def join_triangles(e_ij: np.ndarray, e_ik: np.ndarray, keys_jk: np.ndarray, n_stars: int) -> np.ndarray:
    """Catalogue triples ``(a, b, c)`` with ``a-b`` in ``e_ij``, ``a-c`` in ``e_ik`` and ``b-c``
    among ``keys_jk`` (sorted ``b * n_stars + c`` keys, both orientations). Vectorised."""
    if len(e_ij) == 0 or len(e_ik) == 0 or len(keys_jk) == 0:
        return np.zeros((0, 3), np.int64)
    a_ik = e_ik[:, 0]
    lo = np.searchsorted(a_ik, e_ij[:, 0], side="left")
    hi = np.searchsorted(a_ik, e_ij[:, 0], side="right")
    counts = hi - lo
    total = int(counts.sum())
    if total == 0:
        return np.zeros((0, 3), np.int64)
    rows = np.repeat(np.arange(len(e_ij)), counts)
    offs = np.arange(total) - np.repeat(np.cumsum(counts) - counts, counts)
    a = e_ij[rows, 0]
    b = e_ij[rows, 1]
    c = e_ik[lo[rows] + offs, 1]
    ok = b != c
    a, b, c = a[ok], b[ok], c[ok]
    key = b * n_stars + c
    pos = np.minimum(np.searchsorted(keys_jk, key), len(keys_jk) - 1)
    hit = keys_jk[pos] == key
    return np.column_stack([a[hit], b[hit], c[hit]])


@njit(cache=True, nogil=True)
def _adjacency(pairs: np.ndarray, s: int, e: int, n_stars: int) -> tuple[np.ndarray, np.ndarray]:
    """Rows ``[s, e)`` of ``pairs`` in both orientations grouped by first star (a stable
    counting sort: forward rows, then reversed, in table order): star ``a``'s neighbours are
    ``adj[start[a]:start[a + 1]]``."""
    start = np.zeros(n_stars + 1, np.int64)
    for r in range(s, e):
        start[pairs[r, 0] + 1] += 1
        start[pairs[r, 1] + 1] += 1
    for a in range(n_stars):
        start[a + 1] += start[a]
    fill = start[:-1].copy()
    adj = np.empty(2 * (e - s), np.int64)
    for o in range(2):
        for r in range(s, e):
            a = pairs[r, o]
            adj[fill[a]] = pairs[r, 1 - o]
            fill[a] += 1
    return start, adj


LINKED_JOIN_MAX_ROWS = 3000
"""Windows of at most this many rows in all are joined through linked lists
(:func:`join_windows_linked`), larger ones by counting sort (:func:`join_windows_counting`).
The counting sort sweeps two arrays of the catalogue's size, ~40 us on 24,674 stars, whatever
the windows; the lists cost per row, but their random reads leave the cache as the windows
grow: 3 x 800 rows 57 -> 25 us, 3 x 1,200 59 -> 40, 3 x 1,600 67 -> 60, 3 x 2,400 81 -> 150
(narrow member; a one-off timing loop over windows of the pair table)."""
_HEADS = threading.local()


def join_windows(pairs: np.ndarray, s_ij: int, e_ij: int, s_ik: int, e_ik: int, s_jk: int, e_jk: int,
                 n_stars: int) -> np.ndarray:
    """:func:`join_triangles` of three windows of the pair table (rows ``[s, e)`` of ``pairs``,
    each taken in both orientations), in its order: triples ``(a, b, c)`` with ``a-b`` in the
    first window, ``a-c`` in the second and ``b-c`` in the third (see :func:`join_windows_counting`
    for the order), by whichever of the two compiled joins is faster for the windows' size."""
    if (e_ij - s_ij) + (e_ik - s_ik) + (e_jk - s_jk) > LINKED_JOIN_MAX_ROWS:
        return join_windows_counting(pairs, s_ij, e_ij, s_ik, e_ik, s_jk, e_jk, n_stars)
    heads = getattr(_HEADS, "arrays", None)
    if heads is None or len(heads[0]) < n_stars:  # per thread: the kernel uses them as scratch
        heads = _HEADS.arrays = (np.full(n_stars, -1, np.int64), np.full(n_stars, -1, np.int64))
    try:
        return join_windows_linked(pairs, s_ij, e_ij, s_ik, e_ik, s_jk, e_jk, heads[0], heads[1])
    except BaseException:  # a kernel stopped half-way (out of memory) leaves its lists behind
        _HEADS.arrays = None
        raise


@njit(cache=True, nogil=True)
def _link(pairs: np.ndarray, s: int, e: int, head: np.ndarray, nxt: np.ndarray, other: np.ndarray) -> None:
    """Rows ``[s, e)`` of ``pairs`` in both orientations as lists by first star: directed entry
    ``q = o * (e - s) + (r - s)`` (``o`` = 0 forward, 1 reversed) follows ``head[a]`` and
    ``nxt``, each star's list in entry order; ``other[q]`` is the entry's second star."""
    w = e - s
    for o in range(1, -1, -1):
        for r in range(e - 1, s - 1, -1):
            a = pairs[r, o]
            q = o * w + (r - s)
            nxt[q] = head[a]
            other[q] = pairs[r, 1 - o]
            head[a] = q


@njit(cache=True, nogil=True)
def _unlink(pairs: np.ndarray, s: int, e: int, head: np.ndarray) -> None:
    """``head`` back to all -1 after :func:`_link` of the same rows."""
    for r in range(s, e):
        head[pairs[r, 0]] = -1
        head[pairs[r, 1]] = -1


@njit(cache=True, nogil=True)
def join_windows_linked(pairs: np.ndarray, s_ij: int, e_ij: int, s_ik: int, e_ik: int, s_jk: int, e_jk: int,
                        head_ac: np.ndarray, head_bc: np.ndarray) -> np.ndarray:
    """:func:`join_windows_counting`'s triples, in its order, through linked lists: work per row
    of the windows, none per catalogue star. ``head_ac`` and ``head_bc`` (one entry per star)
    must hold -1 and are left so."""
    w_ab, w_ac, w_bc = e_ij - s_ij, e_ik - s_ik, e_jk - s_jk
    nxt_ac = np.empty(2 * w_ac, np.int64)
    nxt_bc = np.empty(2 * w_bc, np.int64)
    c_ac = np.empty(2 * w_ac, np.int64)
    c_bc = np.empty(2 * w_bc, np.int64)
    _link(pairs, s_ik, e_ik, head_ac, nxt_ac, c_ac)
    _link(pairs, s_jk, e_jk, head_bc, nxt_bc, c_bc)
    out = np.empty((16, 3), np.int64)
    key = np.empty((16, 2), np.int64)  # the a-b entry and the a-c entry of each triple
    n = 0
    for o in range(2):
        for r in range(s_ij, e_ij):
            a, b = pairs[r, o], pairs[r, 1 - o]
            qa, hb = head_ac[a], head_bc[b]
            if qa < 0 or hb < 0:
                continue
            while qa >= 0:
                c = c_ac[qa]
                if c != b:
                    t = hb
                    while t >= 0:
                        if c_bc[t] == c:
                            if n == len(out):
                                grown, grown_key = np.empty((2 * n, 3), np.int64), np.empty((2 * n, 2), np.int64)
                                grown[:n], grown_key[:n] = out, key
                                out, key = grown, grown_key
                            out[n, 0], out[n, 1], out[n, 2] = a, b, c
                            key[n, 0], key[n, 1] = o * w_ab + (r - s_ij), qa
                            n += 1
                            break
                        t = nxt_bc[t]
                qa = nxt_ac[qa]
    _unlink(pairs, s_ik, e_ik, head_ac)
    _unlink(pairs, s_jk, e_jk, head_bc)
    order = np.arange(n)
    for i in range(1, n):  # insertion sort by (a, a-b entry, a-c entry): a handful of triples
        x = order[i]
        j = i - 1
        while j >= 0 and (out[order[j], 0], key[order[j], 0], key[order[j], 1]) > (out[x, 0], key[x, 0], key[x, 1]):
            order[j + 1] = order[j]
            j -= 1
        order[j + 1] = x
    return out[order]


@njit(cache=True, nogil=True)
def join_windows_counting(pairs: np.ndarray, s_ij: int, e_ij: int, s_ik: int, e_ik: int, s_jk: int, e_jk: int,
                          n_stars: int) -> np.ndarray:
    """:func:`join_triangles` of three windows of the pair table (rows ``[s, e)`` of ``pairs``,
    each taken in both orientations), compiled and without sorting: each window as an adjacency
    list by star (a counting sort, stable), and ``c`` kept where it is a neighbour of both ``a``
    (``a-c`` window) and ``b`` (``b-c``; the lists hold ~1-3 stars, so a scan beats a hash
    probe: 0.7 against 3 ms for windows of 15,000-25,000 pairs). The triples come in the order
    :func:`join_triangles` gives for edges stably sorted by first star: by ``a``, then the
    ``a-b`` edge's position, then the ``a-c`` edge's. A window of the density box holds tens of
    thousands of pairs; the vectorised join spent milliseconds in its sorts."""
    ac_start, ac_adj = _adjacency(pairs, s_ik, e_ik, n_stars)  # a-c, by a
    bc_start, bc_adj = _adjacency(pairs, s_jk, e_jk, n_stars)  # b-c, by b
    ab_start, ab_adj = _adjacency(pairs, s_ij, e_ij, n_stars)  # a-b, by a: the stable order by first star
    out = np.empty((64, 3), np.int64)
    n = 0
    for a in range(n_stars):
        q0, q1 = ac_start[a], ac_start[a + 1]
        if q0 == q1:
            continue
        for k in range(ab_start[a], ab_start[a + 1]):
            b = ab_adj[k]
            t0, t1 = bc_start[b], bc_start[b + 1]
            if t0 == t1:  # b has no b-c edge (most often): no c to look for
                continue
            for q in range(q0, q1):
                c = ac_adj[q]
                if c == b:
                    continue
                joined = False
                for t in range(t0, t1):
                    if bc_adj[t] == c:
                        joined = True
                        break
                if not joined:
                    continue
                if n == len(out):  # grow by doubling: one sweep, not a count and a fill
                    grown = np.empty((2 * n, 3), np.int64)
                    grown[:n] = out
                    out = grown
                out[n, 0], out[n, 1], out[n, 2] = a, b, c
                n += 1
    return out[:n].copy()


def edge_keys(e: np.ndarray, n_stars: int) -> np.ndarray:
    """Sorted ``a * n_stars + b`` keys of directed edges."""
    return np.sort(e[:, 0] * n_stars + e[:, 1])


def same_handedness(vec: np.ndarray, tri_obs: np.ndarray, cand: np.ndarray) -> np.ndarray:
    """Mask of candidate triples whose orientation (sign of the triple product) matches the
    observed triangle's; a mirror image is never a match."""
    s_obs = float(np.sign(np.linalg.det(tri_obs)))
    return _handedness_mask(vec, np.ascontiguousarray(cand, dtype=np.int64), s_obs)


@njit(cache=True, nogil=True)
def _handedness_mask(vec: np.ndarray, cand: np.ndarray, s_obs: float) -> np.ndarray:
    """Compiled body of :func:`same_handedness` (its numpy steps took ~0.2 us a triple on the
    sparse proof's density boxes of thousands): ``sign(a . (b x c)) == s_obs`` per row."""
    out = np.empty(len(cand), np.bool_)
    for k in range(len(cand)):
        a, b, c = vec[cand[k, 0]], vec[cand[k, 1]], vec[cand[k, 2]]
        x0 = b[1] * c[2] - b[2] * c[1]
        x1 = b[2] * c[0] - b[0] * c[2]
        x2 = b[0] * c[1] - b[1] * c[0]
        t = a[0] * x0 + a[1] * x1 + a[2] * x2
        out[k] = (1.0 if t > 0 else -1.0 if t < 0 else 0.0) == s_obs
    return out


def same_handedness_many(vec: np.ndarray, obs: np.ndarray, obs_tris: np.ndarray, cand: np.ndarray) -> np.ndarray:
    """Like :func:`same_handedness` for many observed triangles: ``obs_tris[k]`` (rows of the
    observed vectors ``obs``) against catalogue triple ``cand[k]``."""
    oa, ob, oc = obs[obs_tris[:, 0]], obs[obs_tris[:, 1]], obs[obs_tris[:, 2]]
    va, vb, vc = vec[cand[:, 0]], vec[cand[:, 1]], vec[cand[:, 2]]
    s_obs = np.einsum("ij,ij->i", oa, cross(ob, oc))
    s_cat = np.einsum("ij,ij->i", va, cross(vb, vc))
    return np.sign(s_obs) == np.sign(s_cat)
