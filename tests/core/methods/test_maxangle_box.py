"""The density box read from a ``cells`` triangle table (``maxangle_box.box_cells``): the wide
boxes of the sparse proof (hundreds of cells, read in passes) hold exactly the pair-window join's
triples, and a box past the table's limits is refused. (``test_table_join`` checks the join's
order and the narrow boxes.)"""

from __future__ import annotations

import math

import numpy as np

from service.core.geometry import pairwise_angles
from service.core.methods._table_join import triangle_table
from service.core.methods.maxangle_box import box_cells

from .test_table_join import _joined, _triangles


def test_wide_boxes_are_the_join(default_set_db) -> None:
    """Boxes 1.5-3e-3 rad wide about triangles of 2-4.3 deg sides on the ``sparse`` member's box
    table: ~150-600 cells each (the sparse proof's second box), the join's triples as a set."""
    member = default_set_db.members["sparse"]
    table = triangle_table(member)
    read, triples, cells = 0, 0, 0
    for v, rng in _triangles(member, 4.3, 2e-5, 3):
        if read >= 12:
            break
        d = pairwise_angles(v)
        sides = sorted([d[0, 1], d[0, 2], d[1, 2]])
        if sides[0] < math.radians(2.0):
            continue
        w = float(rng.uniform(1.5e-3, 3e-3))
        ok, got = box_cells(*table[:6], v, float(d[0, 1]), float(d[0, 2]), float(d[1, 2]), w, *table[6:])
        if not ok:
            continue
        want = _joined(member, v, w)
        assert sorted(map(tuple, got.tolist())) == sorted(map(tuple, want.reshape(-1, 3).tolist()))
        read += 1
        triples += len(want)
        cell = table[7] / table[6]
        cells += (2 * w / cell) ** 2  # (b and c apart: the full square of cells)
    assert read >= 12 and triples > 12 * 200 and cells / read > 150


def test_box_past_the_table_is_refused(default_set_db) -> None:
    """A side within ``w`` of the table's reach (``d_max``, 4.5 deg here): (False, no triples)."""
    member = default_set_db.members["sparse"]
    table = triangle_table(member)
    d_max = table[8]
    v, _ = next(_triangles(member, 2.0, 0.0, 1))
    d = pairwise_angles(v)
    ok, got = box_cells(*table[:6], v, float(d[0, 1]), float(d[0, 2]), d_max - 1e-4, 2e-4, *table[6:])
    assert not ok and got.shape == (0, 3)
    ok, got = box_cells(*table[:6], np.ascontiguousarray(v), float(d[0, 1]), float(d[0, 2]), float(d[1, 2]), 1e-4,
                        *table[6:])
    assert ok and len(got) >= 1  # the triangle's own stars
