"""Pair-window joins read from a triangle table (``_table_join``): the join's triples in the
join's order, on the default set's ``sparse`` member (``triangle``'s own box table) and the
``narrow`` member (its ``maxangle`` table); the sparse proof's density boxes, in any order."""

from __future__ import annotations

import math

import numpy as np
import pytest

from service.core.geometry import pairwise_angles
from service.core.methods import get_matcher
from service.core.methods._pairs import join_windows, same_handedness
from service.core.methods._table_join import pivot_join, table_join, triangle_table
from service.core.methods.maxangle_box import box_cells
from service.core.methods.triangle import TriangleMatcher
from service.core.navdb import BuildConfig, NavDatabase, build_database, open_database


def _triangles(member, reach_deg: float, noise: float, seed: int):
    """Observed triangles (3, 3) of ``member``'s stars with sides up to ``reach_deg``, each
    vector moved by ``noise`` (rad, per axis), without end."""
    vec = np.asarray(member.stars.vec)
    rng = np.random.default_rng(seed)
    while True:
        i = int(rng.integers(len(vec)))
        near = np.flatnonzero(vec @ vec[i] > math.cos(math.radians(reach_deg)))
        near = near[near != i]
        if len(near) >= 2:
            v = vec[[i, *rng.choice(near, 2, replace=False)]] + rng.normal(0.0, noise, (3, 3))
            yield v / np.linalg.norm(v, axis=1, keepdims=True), rng


def _joined(member, v: np.ndarray, w: float) -> np.ndarray:
    """``join_windows`` of the windows of ``v``'s sides (a-b, a-c, b-c) at ``w``, with its
    handedness filter: what ``pyramid`` and ``triangle`` did before the table."""
    pairs, angles = np.asarray(member.tables["pyramid"]["pairs"]), np.asarray(member.tables["pyramid"]["angles"])
    d = pairwise_angles(v)
    sides = np.array([d[0, 1], d[0, 2], d[1, 2]])
    s = np.searchsorted(angles, sides - w, side="left")
    e = np.searchsorted(angles, sides + w, side="right")
    cand = join_windows(pairs, int(s[0]), int(e[0]), int(s[1]), int(e[1]), int(s[2]), int(e[2]), len(member.stars))
    return cand[same_handedness(np.asarray(member.stars.vec), v, cand)] if len(cand) else cand


@pytest.mark.parametrize(("name", "reach_deg"), [("sparse", 4.3), ("narrow", 3.3)])
def test_table_join_gives_the_join_in_its_order(default_set_db, name: str, reach_deg: float) -> None:
    """Observed triangles at pattern tolerances and wider: the table's triples are the join's,
    in the join's order, pivot stars met in both orientations of their pairs included."""
    member = default_set_db.members[name]
    table = triangle_table(member)
    assert table is not None
    looked_up, several = 0, 0
    for v, rng in _triangles(member, reach_deg, 1e-5, 11):
        if looked_up >= 150:
            break
        w = float(rng.choice([2e-5, 2e-4, 1e-3]))  # pattern tolerances (0.25-2 px on 1-4 deg cameras), wider
        d = pairwise_angles(v)
        got = table_join(table, v, d[0, 1], d[0, 2], d[1, 2], w)
        if got is None:
            continue
        looked_up += 1
        want = _joined(member, v, w)
        np.testing.assert_array_equal(got, want.reshape(-1, 3))
        a, b = want[:, 0], want[:, 1]
        # a pivot star met in both orientations of its a-b pair: the order needs the orientation
        several += any(np.any(a[a == x] > b[a == x]) and np.any(a[a == x] < b[a == x]) for x in set(a.tolist()))
    assert several >= 5  # the order is tested, not only single answers


def test_pivot_join_gives_triangles_candidates(default_set_db) -> None:
    """``pivot_join`` (``triangle``'s candidates, pivot and columns in one compiled call) gives
    what the pair-window join gives through ``TriangleMatcher.triples``, order included, on the
    member that holds ``triangle`` (``sparse``)."""
    member = default_set_db.members["sparse"]
    table = triangle_table(member)
    joiner = TriangleMatcher(member)
    joiner.box_table = None  # the join itself
    looked_up, several = 0, 0
    for v, rng in _triangles(member, 3.3, 1e-5, 17):
        if looked_up >= 100:
            break
        w = float(rng.choice([2e-5, 2e-4, 1e-3]))
        got = pivot_join(table, v, w)
        if got is None:
            continue
        looked_up += 1
        np.testing.assert_array_equal(got, joiner.triples(v, w).reshape(-1, 3))
        several += len(got) >= 2
    assert several >= 10


def test_members_without_a_triangle_table_join(default_set_db) -> None:
    """``rig`` holds no ``maxangle`` or box table: its callers join; ``sparse`` reads its own box
    table, which reaches further than its ``maxangle`` table."""
    assert triangle_table(default_set_db.members["rig"]) is None
    sparse = default_set_db.members["sparse"]
    assert triangle_table(sparse)[0] is sparse.tables["triangle"]["box_key"]


def _assert_boxes_are_the_join(member: NavDatabase, max_side_deg: float, min_read: int) -> None:
    """Random observed triangles of ``member``'s stars (sides up to ``max_side_deg``): each density
    box from ``box_triples`` holds exactly the join's triples, at three widths; at least
    ``min_read`` are read from the table and at least 10 are past it (joined)."""
    tri = get_matcher(member, "triangle")
    assert tri.box_table is not None
    read, joined, triples = 0, 0, 0
    for v, rng in _triangles(member, max_side_deg, 2e-5, 7):
        if read >= min_read and joined >= 10:
            break
        d = pairwise_angles(v)
        w = min(float(rng.choice([1e-4, 6e-4, 2e-3])), min(d[0, 1], d[0, 2], d[1, 2]) / 4)
        got = tri.box_triples(v, w)
        want = tri.triples(v, w, pivot_longest=True)
        assert sorted(map(tuple, got.tolist())) == sorted(map(tuple, want.tolist()))
        ok, _ = box_cells(*tri.box_table[:6], v, float(d[0, 1]), float(d[0, 2]), float(d[1, 2]), w,
                          *tri.box_table[6:])
        read += ok
        joined += not ok
        triples += len(want) if ok else 0
    assert triples > 10 * min_read  # boxes with triples in them, not only empty ones


def test_density_box_read_from_its_own_table_is_the_join(default_set_db) -> None:
    """The default set's ``sparse`` member: ``triangle``'s own box table (``box_d_max_deg`` 4.5)
    reaches further than its ``maxangle`` table (3.5 deg) and is the one read; its boxes are the
    pair-window join's, and past its reach the join answers."""
    member = default_set_db.members["sparse"]
    tri = get_matcher(member, "triangle")
    assert tri.box_table[0] is member.tables["triangle"]["box_key"]
    assert member.method_params("triangle")["box_d_max_deg"] > member.method_params("maxangle")["d_max_deg"]
    _assert_boxes_are_the_join(member, 5.5, 60)


def test_density_box_read_from_the_maxangle_table_is_the_join(tmp_path) -> None:
    """Without a box table of its own, ``triangle`` reads a ``maxangle`` table of every star of
    its member (the ``cells`` layout), with the same boxes as the join."""
    path = tmp_path / "narrow"
    build_database(path, BuildConfig(fov_min_deg=3.0, fov_max_deg=4.5, mag_limit=6.5, epoch=2026.0,
                                     methods=("maxangle", "triangle")))
    db = open_database(path)
    assert get_matcher(db, "triangle").box_table[0] is db.tables["maxangle"]["key"]
    _assert_boxes_are_the_join(db, 4.0, 40)


def _isosceles(member, side_deg: float, seed: int):
    """Observed triangles (3, 3) about ``member``'s stars, without end: half of them with two sides
    of ``side_deg`` (to ~1e-5 rad; the vertex order is ambiguous within a box), half with one of
    them 10-50% longer."""
    vec = np.asarray(member.stars.vec)
    rng = np.random.default_rng(seed)
    while True:
        a = vec[int(rng.integers(len(vec)))]
        e1 = np.cross(a, [0.0, 0.0, 1.0])
        e1 /= np.linalg.norm(e1)
        e2 = np.cross(a, e1)
        rho, phi = math.radians(side_deg), rng.uniform(0, 2 * math.pi)
        opening = rng.uniform(0.3, 2.5)  # the angle at a (rad)
        b = math.cos(rho) * a + math.sin(rho) * (math.cos(phi) * e1 + math.sin(phi) * e2)
        rho2 = rho * (1.0 if rng.random() < 0.5 else rng.uniform(1.1, 1.5))
        c = math.cos(rho2) * a + math.sin(rho2) * (math.cos(phi + opening) * e1 + math.sin(phi + opening) * e2)
        v = np.array([a, b, c]) + rng.normal(0.0, 3e-6, (3, 3))
        yield v / np.linalg.norm(v, axis=1, keepdims=True), rng


@pytest.mark.parametrize("name", ["sparse", "narrow"])
def test_boxes_of_near_isosceles_triangles_are_the_join(default_set_db, name: str) -> None:
    """Where two observed sides lie within 2 w of each other a record may match in two vertex
    orders (``box_cells`` tries all six; elsewhere only the one pairing sides by rank): the same
    triples as the join, in its order, both kinds of box met."""
    member = default_set_db.members[name]
    table = triangle_table(member)
    close, apart, both_orders = 0, 0, 0
    for tries, (v, rng) in enumerate(_isosceles(member, 1.2, 5)):
        if (close >= 40 and apart >= 20) or tries > 2000:
            break
        w = float(rng.choice([2e-4, 1e-3]))
        d = pairwise_angles(v)
        got = table_join(table, v, d[0, 1], d[0, 2], d[1, 2], w)
        if got is None:
            continue
        sides = np.sort([d[0, 1], d[0, 2], d[1, 2]])
        if min(np.diff(sides)) < 2 * w:
            close += 1
        else:
            apart += 1
        want = _joined(member, v, w)
        np.testing.assert_array_equal(got, want.reshape(-1, 3))
        both_orders += len({tuple(sorted(t)) for t in want.tolist()}) < len(want)
    assert close >= 40 and apart >= 20 and both_orders >= 3
