"""The star indexes of an opened database, built on first use and kept on it.

Every kernel that asks "which catalogue stars lie near this direction?" reads one of these: a
k-d tree (:func:`star_tree`), the sky grid of the screens (:func:`sky_grid`), the grids that
gather a field (:func:`field_grid`), the masks that prove a spot of sky empty
(:func:`sky_mask`), each star's nearest neighbours (:func:`star_neighbours`), and the star
vectors as the kernels take them (:func:`star_vec64`). Each is
built once per opened database (a ``NavDatabase`` or a member of a set) and kept in its
``__dict__``; the frames of every camera share them.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.spatial import cKDTree

from .navdb.reader import NavDatabase
from .skygrid import SkyGrid, build_sky_grid
from .skymask import SkyMask, build_sky_mask


def star_tree(db: NavDatabase) -> cKDTree:
    """A k-d tree over the database's star vectors, built once per opened database."""
    cache = db.__dict__.setdefault("_cache", {})
    if "tree" not in cache:
        cache["tree"] = cKDTree(np.asarray(db.stars.vec))
    return cache["tree"]


def sky_grid(db: NavDatabase) -> SkyGrid:
    """The database's stars on a :class:`~service.core.skygrid.SkyGrid`, built once per
    opened database."""
    cache = db.__dict__.setdefault("_cache", {})
    if "grid" not in cache:
        cache["grid"] = build_sky_grid(np.asarray(db.stars.vec))
    return cache["grid"]


MASK_REACH_STEP = 2.0 ** 0.25
"""Sky masks are built for reaches on this geometric ladder (the first at or above the screen's
chord), so the few chords a database meets share a handful of masks."""
MASKS_PER_DATABASE = 16


def sky_mask(db: NavDatabase, chord: float) -> SkyMask:
    """The database's :class:`~service.core.skymask.SkyMask` for screens of ``chord`` (unit-vector
    distance) or less, built once per opened database and reach (~0.5 ms, 197 kB)."""
    cache = db.__dict__.setdefault("_cache", {})
    reach = MASK_REACH_STEP ** math.ceil(math.log(max(chord, 1e-12), MASK_REACH_STEP))
    key = ("sky_mask", reach)
    mask = cache.get(key)
    if mask is None:
        masks = [k for k in list(cache) if isinstance(k, tuple) and k[0] == "sky_mask"]
        if len(masks) >= MASKS_PER_DATABASE:
            for k in masks:
                cache.pop(k, None)  # another thread may be clearing them too
        mask = cache[key] = build_sky_mask(np.asarray(db.stars.vec), reach * (1.0 + 1e-9))
    return mask


FIELD_CELL_DEG = (1.0, 2.0, 4.0, 8.0)
"""Cells (deg) of the grids that gather a field's catalogue stars: a query of radius ``R`` uses
the largest at most ``R / 2.5`` (at least the first). A cell about the query's size keeps the
scan short: a 10.8-deg gathering of 55 stars took 4.5 us on 1-deg cells (~480 columns looked
at), 1.5 us on 4-deg ones."""


def field_grid(db: NavDatabase, radius_deg: float = 0.0, *, any_star: bool = False) -> SkyGrid:
    """The database's stars on the grid of :data:`FIELD_CELL_DEG` cells suited to gathering
    every star within ``radius_deg`` of a point (built once per opened database and cell); with
    ``any_star``, to asking whether any star there qualifies, which stops at the first one: cells
    up to 2.5 radii (the ball spans at most two a side). The sparse proof's in-image test of
    ~2,000 attitudes, a 2-deg ball: 1-deg cells 20.6 ms, 2-deg 18.6, 4-deg 16.3, 8-deg 17.3."""
    cell = FIELD_CELL_DEG[0]
    for c in FIELD_CELL_DEG:
        if c <= (radius_deg * 2.5 if any_star else radius_deg / 2.5):
            cell = c
    cache = db.__dict__.setdefault("_cache", {})
    key = ("field_grid", cell)
    if key not in cache:
        cache[key] = build_sky_grid(np.asarray(db.stars.vec), cell_rad=math.radians(cell))
    return cache[key]


def star_vec64(db: NavDatabase) -> np.ndarray:
    """The star vectors as contiguous float64, as the kernels take them (once per opened
    database)."""
    cache = db.__dict__.setdefault("_cache", {})
    if "vec64" not in cache:
        vec = np.ascontiguousarray(db.stars.vec, dtype=np.float64).view()  # a view: its flags are its own
        vec.flags.writeable = False  # as the memory map's own: one compiled signature for both
        cache["vec64"] = vec
    return cache["vec64"]


NEIGHBOURS = 4
"""Neighbours :func:`star_neighbours` keeps per star."""


def star_neighbours(db: NavDatabase) -> np.ndarray:
    """Each star's :data:`NEIGHBOURS` nearest other stars, nearest first: rows ``(N, NEIGHBOURS)``
    int32 (-1 where the database holds fewer), built once per opened database (~20 ms for 25,000
    stars)."""
    cache = db.__dict__.setdefault("_cache", {})
    got = cache.get("neighbours")
    if got is None:
        n = len(db.stars.vec)
        got = np.full((n, NEIGHBOURS), -1, np.int32)
        k = min(NEIGHBOURS + 1, n)
        if k > 1:
            _, idx = star_tree(db).query(np.asarray(db.stars.vec), k=k)
            own = idx == np.arange(n)[:, None]  # each star's own row, first unless a duplicate ties it
            once = own.sum(axis=1) == 1
            got[once, :k - 1] = idx[once][~own[once]].reshape(-1, k - 1)
            for i in np.flatnonzero(~once):  # (duplicated stars: the own row may be missing)
                others = [int(j) for j in idx[i] if j != i and j < n][:NEIGHBOURS]
                got[i, :len(others)] = others
        got.flags.writeable = False
        cache["neighbours"] = got
    return got
