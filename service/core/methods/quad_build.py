"""The ``quad`` pattern table: 4-star patterns of the brightest stars of every field, hashed.

For every field size ``d`` from the database's ``fov_min_deg`` to its ``fov_max_deg`` (a
geometric ladder, steps of at most ``scale_step``) the sky is covered by a lattice of field
centres ``d / lattice_div`` apart (a Fibonacci sphere). Each centre's field is the disc of
diameter ``d`` around it; its ``stars_per_field`` brightest stars give every 4-star pattern
they hold (``C(8, 4) = 70`` at most). So a camera of any field the database serves finds the
patterns of its own brightest stars in the table, whatever its limiting magnitude: the whole
field of the widest camera, at the star density of the narrowest.

A pattern's key is its shape and size: the six inter-star angles sorted, the five smaller ones
divided by the largest (``ratio_bin`` wide bins) and the largest itself (``edge_bin_rad`` wide
bins). Keys are hashed into an open-addressing table (linear probing, load <= ``MAX_LOAD``) of
int64 words: the pattern's row, bits of its key's hash and where each of its six values lies
inside its bin (``FINE_STEPS`` steps), so a probe reads no pattern of another key, nor one
whose values lie outside the query's tolerance. A key of more than ``SPILL_OVER`` patterns
(common shapes: up to 176 in the narrow member of the default set) keeps its entry words in a
separate ``spill`` list, and the table one word pointing at them: a probe scans a cluster of
the table until an empty slot, and such keys' runs made the narrow member's clusters long (a
query probe read 32 words there, 10 of them its own key's; session 18). A spill list is sorted
by the largest edge's fine step, so a probe reads only the part its tolerance reaches. Patterns
are stored once (deduplicated), their star rows sorted ascending.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from numba import njit

from ..skygrid import build_sky_grid

STARS_PER_FIELD = 8
"""Brightest stars of a lattice field that make its patterns."""
LATTICE_DIV = 4.0
"""Lattice spacing = field diameter / this."""
SCALE_STEP = 1.3
"""Largest ratio between consecutive field diameters of the ladder."""
RATIO_BIN = 0.05
"""Width of an edge-ratio bin."""
EDGE_BINS_PER_FOV = 48
"""The largest edge is binned ``fov_max / this`` wide."""
MAX_LOAD = 0.6
"""Most patterns per slot of the hash table."""
N_RATIO_BINS = int(math.ceil(1.0 / RATIO_BIN)) + 1
FINE_BITS = 4
FINE_STEPS = 1 << FINE_BITS
"""Steps of a value's position inside its bin, kept in the table."""
FINGER_BITS = 32 - 6 * FINE_BITS
SPILL_OVER = 4
"""A key with more patterns than this keeps them in the spill list, with one pointer word in
the table, so that a probe of another key that lands beside it does not scan them."""
INLINE_LAYOUT = f"ratio{N_RATIO_BINS}-fine{FINE_BITS}-finger{FINGER_BITS}"
"""The layout until session 18: every pattern in the table (no spill list); still read."""
LAYOUT = f"{INLINE_LAYOUT}-spill"
"""The table's word layout and key radix; a table of another layout cannot be read."""
KEY_MULT = np.uint64(0x9E3779B97F4A7C15)


def field_scales(fov_min_deg: float, fov_max_deg: float, step: float = SCALE_STEP) -> np.ndarray:
    """Field diameters (degrees) of the ladder, ``fov_min`` to ``fov_max``."""
    if fov_max_deg <= fov_min_deg:
        return np.array([float(fov_max_deg)])
    n = int(math.ceil(math.log(fov_max_deg / fov_min_deg) / math.log(step))) + 1
    return np.geomspace(fov_min_deg, fov_max_deg, n)


def fibonacci_sphere(n: int) -> np.ndarray:
    """``n`` nearly uniform unit vectors ``(n, 3)``."""
    i = np.arange(n, dtype=np.float64) + 0.5
    z = 1.0 - 2.0 * i / n
    phi = math.pi * (1.0 + math.sqrt(5.0)) * i
    s = np.sqrt(np.maximum(1.0 - z * z, 0.0))
    return np.column_stack([s * np.cos(phi), s * np.sin(phi), z])


def build_quad_table(vec: np.ndarray, rank: np.ndarray, fov_min_deg: float, fov_max_deg: float,
                     params: dict[str, Any]) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
    """The pattern table of stars ``vec`` ``(N, 3)`` with brightness ``rank`` (0 = brightest).

    Returns the arrays ``patterns (P, 4)`` (star rows, uint16 when N < 65536) and ``table (C,)``
    int64 (see :func:`slot_word`; 0 = empty), and the parameters used (degrees, bin widths).
    """
    per_field = int(params.get("stars_per_field", STARS_PER_FIELD))
    div = float(params.get("lattice_div", LATTICE_DIV))
    ratio_bin = RATIO_BIN  # the key's radix (N_RATIO_BINS) is fixed by the layout
    edge_bin = math.radians(fov_max_deg) / float(params.get("edge_bins_per_fov", EDGE_BINS_PER_FOV))
    vec = np.ascontiguousarray(vec, dtype=np.float64)
    rank = np.ascontiguousarray(rank, dtype=np.int64)
    n = len(vec)
    found = []
    scales = field_scales(fov_min_deg, fov_max_deg)
    for d in scales:
        radius = math.radians(d) / 2
        chord = 2 * math.sin(radius / 2)
        spacing = math.radians(d) / div
        centres = fibonacci_sphere(max(12, int(4 * math.pi / spacing**2)))
        grid = build_sky_grid(vec, cell_rad=chord)
        found.append(_field_patterns(centres, chord, per_field, rank, grid.cell, grid.n_side, grid.keys,
                                     grid.starts, grid.stars, vec, grid.columns))
    patterns = _unique_rows(np.concatenate(found), n)
    del found
    table, spill = _build_table(vec, patterns, ratio_bin, edge_bin)
    store = patterns.astype(np.uint16 if n < 65536 else np.int32)
    used = {"layout": LAYOUT, "stars_per_field": per_field, "lattice_div": div, "ratio_bin": ratio_bin,
            "edge_bin_rad": edge_bin, "scales_deg": [round(float(s), 4) for s in scales],
            "fov_max_deg": float(fov_max_deg), "n_patterns": int(len(patterns))}
    return {"patterns": store, "table": table, "spill": spill}, used


@njit(cache=True, nogil=True)
def _field_patterns(centres: np.ndarray, chord: float, per_field: int, rank: np.ndarray, cell: float,
                    n_side: int, keys: np.ndarray, starts: np.ndarray, stars: np.ndarray, vec: np.ndarray,
                    columns: np.ndarray) -> np.ndarray:
    """Every 4-star pattern ``(M, 4)`` (rows ascending) of each centre's ``per_field``
    brightest stars within ``chord``."""
    n_comb = per_field * (per_field - 1) * (per_field - 2) * (per_field - 3) // 24
    out = np.empty((len(centres) * n_comb, 4), np.int32)
    n_out = 0
    best = np.empty(per_field, np.int64)
    best_rank = np.empty(per_field, np.int64)
    r2 = chord * chord
    four = np.empty(4, np.int64)
    for c in range(len(centres)):
        px, py, pz = centres[c, 0], centres[c, 1], centres[c, 2]
        k = 0
        lo_x = max(int(math.floor((px - chord + 1.0) / cell)), 0)
        hi_x = min(int(math.floor((px + chord + 1.0) / cell)), n_side - 1)
        lo_y = max(int(math.floor((py - chord + 1.0) / cell)), 0)
        hi_y = min(int(math.floor((py + chord + 1.0) / cell)), n_side - 1)
        lo_z = max(int(math.floor((pz - chord + 1.0) / cell)), 0)
        hi_z = min(int(math.floor((pz + chord + 1.0) / cell)), n_side - 1)
        for ix in range(lo_x, hi_x + 1):
            for iy in range(lo_y, hi_y + 1):
                col = ix * n_side + iy
                for pos in range(columns[col], columns[col + 1]):
                    iz = keys[pos] - col * n_side
                    if iz < lo_z or iz > hi_z:
                        continue
                    for s in range(starts[pos], starts[pos + 1]):
                        row = stars[s]
                        dx, dy, dz = vec[row, 0] - px, vec[row, 1] - py, vec[row, 2] - pz
                        if dx * dx + dy * dy + dz * dz > r2:
                            continue
                        rk = rank[row]
                        if k == per_field and rk >= best_rank[k - 1]:
                            continue
                        j = k if k < per_field else per_field - 1
                        while j > 0 and best_rank[j - 1] > rk:  # insertion, brightest first
                            best_rank[j] = best_rank[j - 1]
                            best[j] = best[j - 1]
                            j -= 1
                        best_rank[j] = rk
                        best[j] = row
                        if k < per_field:
                            k += 1
        for a in range(k):
            for b in range(a + 1, k):
                for cc in range(b + 1, k):
                    for d in range(cc + 1, k):
                        four[0], four[1], four[2], four[3] = best[a], best[b], best[cc], best[d]
                        four.sort()
                        for i in range(4):
                            out[n_out, i] = four[i]
                        n_out += 1
    return out[:n_out].copy()


def _unique_rows(rows: np.ndarray, n: int) -> np.ndarray:
    """Distinct rows of ``rows`` ``(M, 4)`` of values below ``n``, as int64."""
    bits = max(int(n - 1).bit_length(), 1)
    if len(rows) == 0:
        return np.zeros((0, 4), np.int64)
    if 4 * bits <= 63:  # one int64 a pattern: a fast 1-D unique
        packed = np.zeros(len(rows), np.int64)
        for i in range(4):
            packed = (packed << bits) | rows[:, i].astype(np.int64)
        packed.sort()  # sort and drop repeats: numpy 2's np.unique hashes first, 11x slower here (5.2 s for 6.3e6)
        packed = packed[np.concatenate(([True], packed[1:] != packed[:-1]))]
        mask = (1 << bits) - 1
        return np.column_stack([(packed >> (bits * (3 - i))) & mask for i in range(4)])
    return np.unique(rows.astype(np.int64), axis=0)


@njit(cache=True, nogil=True, inline="always")
def row_angle(vec: np.ndarray, a: int, b: int) -> float:
    """Angle between the unit vectors ``vec[a]`` and ``vec[b]`` (radians), accurate at small
    angles. Rows, not row views, are passed: a view costs atomic reference counts in a loop."""
    dx, dy, dz = vec[a, 0] - vec[b, 0], vec[a, 1] - vec[b, 1], vec[a, 2] - vec[b, 2]
    return 2.0 * math.asin(min(math.sqrt(dx * dx + dy * dy + dz * dz) / 2.0, 1.0))


@njit(cache=True, nogil=True, inline="always")
def sorted_edges(vec: np.ndarray, ids: np.ndarray, out: np.ndarray) -> None:
    """The six angles between stars ``vec[ids[0..3]]``, ascending, into ``out`` (6,). Sorted by
    insertion as they come: ``out.sort()`` was a call into numba's sort, with a reference count
    of ``out`` taken and given back, on every candidate of a search."""
    n = 0
    for i in range(4):
        for j in range(i + 1, 4):
            v = row_angle(vec, ids[i], ids[j])
            m = n
            while m > 0 and out[m - 1] > v:
                out[m] = out[m - 1]
                m -= 1
            out[m] = v
            n += 1


@njit(cache=True, nogil=True, inline="always")
def combine_key(q: np.ndarray) -> np.int64:
    """One int64 of the edge bin ``q[5]`` and the five ratio bins ``q[0..4]``."""
    key = np.int64(q[5])
    for i in range(5):
        key = key * N_RATIO_BINS + q[i]
    return key


@njit(cache=True, nogil=True, inline="always")
def key_hash(key: np.int64) -> np.uint64:
    """64-bit mix of a key (Fibonacci hashing); the slot is its low bits, the finger its top."""
    h = np.uint64(key) * KEY_MULT
    return h ^ (h >> np.uint64(29))


@njit(cache=True, nogil=True)
def pattern_bins(e: np.ndarray, ratio_bin: float, edge_bin: float, q: np.ndarray, fine: np.ndarray) -> None:
    """Bins ``q`` (6,) of sorted edges ``e`` (5 ratios, then the largest edge) and each value's
    position inside its bin in ``FINE_STEPS`` steps, ``fine`` (6,)."""
    for i in range(6):
        x = e[i] / e[5] / ratio_bin if i < 5 else e[5] / edge_bin
        q[i] = int(x)
        fine[i] = min(int((x - q[i]) * FINE_STEPS), FINE_STEPS - 1)
        if i < 5 and q[i] >= N_RATIO_BINS:
            q[i], fine[i] = N_RATIO_BINS - 1, FINE_STEPS - 1


@njit(cache=True, nogil=True, inline="always")
def slot_word(pattern: int, h: np.uint64, fine: np.ndarray) -> np.int64:
    """A table slot: ``pattern + 1`` (high 32 bits), ``FINGER_BITS`` of the key's hash, and the
    six fine positions (``FINE_BITS`` each)."""
    sig = np.int64(h >> np.uint64(64 - FINGER_BITS))
    for i in range(6):
        sig = (sig << FINE_BITS) | fine[i]
    return (np.int64(pattern + 1) << 32) | sig


@njit(cache=True, nogil=True)
def _pattern_words(vec: np.ndarray, patterns: np.ndarray, ratio_bin: float, edge_bin: float
                   ) -> tuple[np.ndarray, np.ndarray]:
    """Each pattern's key hash and its entry word (:func:`slot_word`)."""
    hashes = np.empty(len(patterns), np.uint64)
    words = np.empty(len(patterns), np.int64)
    e = np.empty(6)
    q = np.empty(6, np.int64)
    fine = np.empty(6, np.int64)
    for p in range(len(patterns)):
        sorted_edges(vec, patterns[p], e)
        pattern_bins(e, ratio_bin, edge_bin, q, fine)
        hashes[p] = key_hash(combine_key(q))
        words[p] = slot_word(p, hashes[p], fine)
    return hashes, words


SPILL_SIGN = np.int64(np.iinfo(np.int64).min)
"""The sign bit, which marks a pointer word (an entry word's pattern field is below 2**31)."""
SPILL_OFFSET_MASK = (1 << 31) - 1
"""A pointer word's offset into the spill list, above bit 32 (:func:`spill_words`)."""
SPILL_COUNT_MASK = (1 << 24) - 1
"""A pointer word's count of entries, its low bits."""


def spill_words(offsets: np.ndarray, counts: np.ndarray, hashes: np.ndarray) -> np.ndarray:
    """Table slots that point at keys' entries ``spill[offset:offset + count]``: the sign bit,
    ``offset`` (31 bits), ``FINGER_BITS`` of the key's hash (where an entry word has them) and
    ``count`` (24 bits)."""
    finger = (hashes >> np.uint64(64 - FINGER_BITS)).astype(np.int64)
    return SPILL_SIGN | (offsets.astype(np.int64) << 32) | (finger << (6 * FINE_BITS)) | counts.astype(np.int64)


@njit(cache=True, nogil=True)
def _place(hashes: np.ndarray, words: np.ndarray, cap: int) -> np.ndarray:
    """Open addressing (linear probing) of ``words`` at their hashes' low bits."""
    table = np.zeros(cap, np.int64)
    mask = np.uint64(cap - 1)
    for k in range(len(words)):
        s = hashes[k] & mask
        while table[s] != 0:
            s = (s + np.uint64(1)) & mask
        table[s] = words[k]
    return table


def _build_table(vec: np.ndarray, patterns: np.ndarray, ratio_bin: float, edge_bin: float
                 ) -> tuple[np.ndarray, np.ndarray]:
    """The hash table and spill list of ``patterns`` (see :data:`SPILL_OVER`)."""
    if len(patterns) == 0:  # too few stars for a pattern: an empty table
        return np.zeros(16, np.int64), np.zeros(0, np.int64)
    hashes, words = _pattern_words(vec, patterns, ratio_bin, edge_bin)
    order = np.argsort(hashes, kind="stable")  # a key's patterns stay in row order
    sorted_hashes = hashes[order]
    first = np.flatnonzero(np.concatenate(([True], sorted_hashes[1:] != sorted_hashes[:-1])))
    counts = np.diff(np.append(first, len(order)))
    spilled = counts > SPILL_OVER
    if counts.max(initial=0) > SPILL_COUNT_MASK or counts[spilled].sum() > SPILL_OFFSET_MASK:
        raise ValueError("quad table: too many patterns share a key for the spill layout")
    starts = np.zeros(len(first), np.int64)
    starts[spilled] = np.cumsum(np.where(spilled, counts, 0))[spilled] - counts[spilled]
    by_edge = np.lexsort((words & (FINE_STEPS - 1), hashes))  # a key's patterns by their largest edge's fine step
    in_spill = np.repeat(spilled, counts)  # each sorted pattern: is its key's list in the spill?
    spill = words[by_edge[in_spill]]
    group = np.repeat(np.arange(len(first)), counts)  # each sorted pattern's key
    lead = np.zeros(len(order), bool)
    lead[first] = True
    keep = ~in_spill | lead  # inline patterns, and one pointer per spilled key
    main = words[order]
    pointer = np.flatnonzero(lead & in_spill)
    main[pointer] = spill_words(starts[group[pointer]], counts[group[pointer]], sorted_hashes[pointer])
    keep_rows = order[keep]  # placed in row order: a key's inline patterns are met in row order
    placed = np.argsort(keep_rows, kind="stable")
    main_hashes = sorted_hashes[keep][placed]
    main_words = main[keep][placed]
    cap = 1 << max(4, int(math.ceil(math.log2(max(len(main_words), 1) / MAX_LOAD))))
    return _place(main_hashes, main_words, cap), spill
