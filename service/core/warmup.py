"""Warming a database up: every matcher built, every kernel compiled (or loaded from numba's
cache) and the indexes made, before the first request (``skyfix serve``, ``skyfix solve``, the
batch and cluster workers; :func:`service.core.pipeline.solve` warms a database it meets cold)."""

from __future__ import annotations

import math
import mmap
import sys
from functools import partial

import numpy as np

from .attitude import matrix_from_radec_roll
from .camera import Camera
from .deeper import could_pair_more_deeper, recheck_could_be_strong
from .fallback_pass import fallbacks
from .first_pass import deeper_arrays, settle
from .geometry import pairwise_angles
from .hidden import hidden_neighbours
from .methods import get_matcher
from .methods._table_join import table_join
from .methods.quad import QUERY_STARS
from .methods.rig_proof import THIRD_STAR_REACH_DEG, cross_triples, sky_limits
from .navdb.reader import NavDatabase, NavDatabaseSet
from .pipeline import _ONE_CAMERA, FEW_STARS_MAX_TRIALS, SolveOptions, _observation, solve, solve_rig
from .plan import RIG_METHOD, search_plan
from .sparse_proof import warm_up_screens
from .star_index import FIELD_CELL_DEG, field_grid, sky_grid, star_tree
from .types import Centroids, SolveStatus
from .verify import Verified

MADV_POPULATE_READ = 22
"""Linux (5.14 and later): fault a mapping's pages in, as reads (Python names it from 3.12)."""
PAGE_BYTES = mmap.PAGESIZE


def map_pages(db: NavDatabase | NavDatabaseSet) -> int:
    """Map every page of ``db``'s memory-mapped arrays into this process; returns their bytes.

    A frame's look-ups land on pages of tables of tens of megabytes that no frame touched
    before; each first touch is a page fault (~1 us from the page cache, a disk read if it was
    dropped). Seed 000 at 2 px, a frame whose searches read thousands of table pages took 10-11
    ms the first time and 4 ms after; with the pages mapped at the warm-up, 6.5 ms. Mapping the
    default set's 626 MB from the page cache takes ~60 ms, from a cold disk the time to read it
    (``madvise(MADV_POPULATE_READ)``; one byte read a page where that is missing). The pages stay
    the operating system's to drop."""
    members = db.members.values() if isinstance(db, NavDatabaseSet) else [db]
    maps: dict[int, mmap.mmap] = {}
    arrays: list[np.ndarray] = []
    for member in members:
        stars = member.stars
        arrays += [a for a in (stars.vec, stars.mag, stars.hip, stars.pm) if a is not None]
        arrays += [a for tables in member.tables.values() for a in tables.values()]
    loose: list[np.ndarray] = []
    for a in arrays:
        m = _mapping_of(a)
        if m is not None:
            maps.setdefault(id(m), m)
    total = 0
    for m in maps.values():
        total += len(m)
        try:
            if not sys.platform.startswith("linux"):
                raise OSError("MADV_POPULATE_READ is Linux's")
            m.madvise(MADV_POPULATE_READ)
        except (OSError, ValueError, AttributeError):
            loose.append(np.frombuffer(m, dtype=np.uint8))
    for page_bytes in loose:  # one byte a page
        int(page_bytes[::PAGE_BYTES].max(initial=0))
    return total


def _mapping_of(a: np.ndarray) -> mmap.mmap | None:
    """The ``mmap`` behind a view of a memory-mapped ``.npy`` array, if any."""
    base = a
    while base is not None:
        m = getattr(base, "_mmap", None)
        if isinstance(m, mmap.mmap):
            return m
        base = getattr(base, "base", None)
    return None


def warm_up(db: NavDatabase | NavDatabaseSet, *, reverse: bool = False) -> None:
    """Map the pages of ``db``'s arrays (:func:`map_pages`), build every matcher, the star k-d
    tree and sky grid of ``db`` (or of each member of a set), and solve one frame of its own
    stars with each method, so that numba's kernels are compiled (or loaded from its on-disk
    cache) and the first request of a server worker is as fast as the rest.

    ``reverse``: for a second process warming up the same database on a fresh install
    (``.ci/run``). It compiles the finish of a proven answer (:func:`_settle`) and the compiled
    fallbacks (:func:`_fallbacks`) first, while the first process compiles quad's search and the
    first pass, then the rest in the opposite order; each loads the other's kernels from
    numba's cache. One process alone compiles for ~135 s on this 2-core VM; the two together
    took 114-120 s when the second simply ran the steps backwards (both compiled the finish at
    once, ~35 s into the first pass) and 95-97 s in this order (``/work/s28/pair_warm.sh``)."""
    db.__dict__["_warm"] = True
    map_pages(db)
    members = list(db.members.values()) if isinstance(db, NavDatabaseSet) else [db]
    for member in members:
        member.__dict__["_warm"] = True
    if not reverse:
        steps = [*(partial(_methods, member) for member in members), partial(_auto, db, members),
                 partial(_rigs, db, members), partial(_screens, members)]
    else:  # the finish of a proven answer first (the forward order reaches it inside the compiled
        # first pass after quad's search, ~35 s in: both processes compiled it at once), then
        # what the forward order reaches last
        steps = [partial(_settle, db, members[0]), partial(_fallbacks, db, members[0]),
                 partial(_screens, members), partial(_rigs, db, members), partial(_auto, db, members),
                 *(partial(_methods, member) for member in reversed(members))]
    for step in steps:
        step()


def _fallbacks(db: NavDatabase | NavDatabaseSet, member: NavDatabase) -> None:
    """The compiled fallbacks (:func:`~.fallback_pass.fallbacks`: quad's search on the other
    members, then ``maxangle``'s) called as the pipeline calls them after a first pass that
    proved nothing, on 8 random points of ``member``'s field."""
    camera = Camera.from_fov(float(member.manifest["fov_min_deg"]), 1024, 1024)
    rng = np.random.default_rng(0)
    frame = Centroids(rng.uniform(0, 1023, (8, 2)), rng.uniform(1, 100, 8))
    obs = _observation([(frame, camera, None)], _ONE_CAMERA)
    plan = search_plan(db, [camera], "auto", 1.0)[0]
    options = SolveOptions()
    fallbacks(obs, plan, 0, FEW_STARS_MAX_TRIALS, 1.0, None, options.max_false_prob, options.max_stars,
              math.inf, len(obs) <= QUERY_STARS)


def _settle(db: NavDatabase | NavDatabaseSet, member: NavDatabase) -> None:
    """The compiled finish of an answer a fallback proved (:func:`~.first_pass.settle`), on a
    frame of ``member``'s own stars with its true pairs."""
    camera = Camera.from_fov(float(member.manifest["fov_min_deg"]), 1024, 1024)
    row = int(np.argmin(np.asarray(member.stars.mag)))
    frame, rows, r = _own_frame(member, camera, row)
    deepest = search_plan(db, [camera], "auto", 1.0)[1]
    obs = _observation([(frame, camera, None)], _ONE_CAMERA)  # brightest first: the frame's order
    found = Verified(np.arange(len(rows), dtype=np.int64), rows, r, 1e-20, 1)
    settle(obs, member, deepest, found, 1.0, None, SolveOptions().max_false_prob)


def _methods(member: NavDatabase) -> None:
    """Every matcher of ``member``, its k-d tree and sky grid, and a frame solved by each method."""
    star_tree(member)
    sky_grid(member)
    camera = Camera.from_fov(float(member.manifest["fov_min_deg"]), 1024, 1024)
    for name in member.methods:
        get_matcher(member, name)
        if name == "multifov":
            continue  # a rig method; its kernels are the verifier's, warmed by the others
        for centroids in own_frames(member, camera):
            if solve(centroids, camera, member, method=name).status is SolveStatus.SOLVED:
                break


def _auto(db: NavDatabase | NavDatabaseSet, members: list[NavDatabase]) -> None:
    """``auto`` as users call it, on the whole database: the compiled first pass, the kernels of
    frames of 4 and 3 stars (the screen of a 4-star triangle, the sparse proof) and of a frame
    the first pass cannot prove (quad's search on the other members, the fallback). Without
    these the first such requests compiled them on a fresh install: 4 s, 0.7 s, 1.7 s and 3 s,
    past the 500 ms time limit."""
    rng = np.random.default_rng(0)
    for member in members:
        camera = Camera.from_fov(float(member.manifest["fov_min_deg"]), 1024, 1024)
        frame = own_frames(member, camera, n_tries=1)[0]
        for n in (len(frame), 4, 3):
            solve(Centroids(frame.xy[:n], frame.flux[:n]), camera, db)
        solve(Centroids(rng.uniform(0, 1023, (12, 2)), rng.uniform(1, 100, 12)), camera, db)
        solve(Centroids(rng.uniform(0, 1023, (8, 2)), rng.uniform(1, 100, 8)), camera, db)  # the compiled fallbacks


def _rigs(db: NavDatabase | NavDatabaseSet, members: list[NavDatabase]) -> None:
    """The rig method's own kernels (its master votes, the cross-camera proof of a sparse frame)
    on a frame of a member's stars dealt out to two cameras of one pointing."""
    for member in members:
        if RIG_METHOD in member.methods:
            camera = Camera.from_fov(float(member.manifest["fov_min_deg"]), 1024, 1024)
            frame = own_frames(member, camera, n_tries=1)[0]
            ident = (1.0, 0.0, 0.0, 0.0)
            for n in (len(frame), 4):
                halves = [Centroids(frame.xy[k:n:2], frame.flux[k:n:2]) for k in (0, 1)]
                solve_rig([(h, camera, ident) for h in halves], db)
            # the sparse proof's third-star lookup, which those frames need not reach (loaded inside
            # a request, or compiled there on a cold cache, it took a worker's first sparse frame)
            sky = sky_limits(member)[0]
            nearest = np.argsort(-(sky.vec @ sky.vec[0]))[1:3]
            lookup = get_matcher(member, RIG_METHOD).lookup
            grid = sky.grid(THIRD_STAR_REACH_DEG)
            cross_triples(lookup, sky.vec, sky.vec[[0, *nearest]], (1e-4,) * 3, None, grid)


def _screens(members: list[NavDatabase]) -> None:
    """What only some frames reach, and the indexes a camera's first frame would build."""
    # the unique-triangle proof's box screens, which only a frame whose match proves locally
    # reaches: called directly on a member's own 3- and 4-star frame (a first use compiled
    # them inside a request: ~0.7-1 s)
    for member in members:
        camera = Camera.from_fov(float(member.manifest["fov_min_deg"]), 1024, 1024)
        frame = own_frames(member, camera, n_tries=1)[0]
        warm_up_screens(member, camera, frame)
        if "triangle" in member.methods:  # its density box and candidates read from a triangle table
            tri = get_matcher(member, "triangle")
            tri.box_triples(np.asarray(member.stars.vec[:3], np.float64), 1e-4)
            tri.triples(np.asarray(member.stars.vec[:3], np.float64), 1e-4)  # (pivot_join)
            tri._triangle_order(pairwise_angles(np.asarray(member.stars.vec[:4], np.float64)), 4, 1e-4)
        if "pyramid" in member.methods and get_matcher(member, "pyramid").table is not None:
            v = np.asarray(member.stars.vec[:3], np.float64)
            table_join(get_matcher(member, "pyramid").table, v, 0.01, 0.01, 0.01, 1e-4)
        # the deeper recheck's screen (could_pair_more_deeper), which only an answer found past the
        # first pass reaches (its first use in a request loaded it from numba's cache)
        nothing = Verified(np.zeros(0, np.int64), np.zeros(0, np.int64), np.eye(3), 1.0, 0)
        one = _observation([(frame, camera, None)], _ONE_CAMERA)
        could_pair_more_deeper(one, member, nothing, 2.5)
        recheck_could_be_strong(one, member, nothing, nothing.obs, 2.5, 1e-3)  # and its bound's test
        # the rows of its stars in each member a plan may refine its answers against (the deeper
        # recheck's map: the deepest fitting member, none shallower) and the stars the others hold
        # that it does not: built on a camera's first frame otherwise (~3 ms, 8-30 ms; the camera
        # that first needed a pair was not always one of the frames above)
        hidden_neighbours(member)
        # the grids that gather a field's stars, one per cell size (field_grid picks the cell by
        # the field's radius): a camera whose field asks for a size the frames above did not
        # built it in its first request (~1 ms; the real image virgo.jpg, 20 deg, after 11-deg ones)
        for cell in FIELD_CELL_DEG:
            field_grid(member, cell * 2.5)
        for other in members:
            if other is not member and other.mag_limit >= member.mag_limit:
                deeper_arrays(member, other)


def own_frames(db: NavDatabase, camera: Camera, n_tries: int = 4) -> list[Centroids]:
    """Noise-free frames of ``db``'s own brightest stars around a few of them (for
    :func:`warm_up`)."""
    mag = np.asarray(db.stars.mag, dtype=np.float64)
    return [_own_frame(db, camera, int(row))[0] for row in np.argsort(mag)[: 50 : 50 // n_tries]]


def _own_frame(db: NavDatabase, camera: Camera, row: int) -> tuple[Centroids, np.ndarray, np.ndarray]:
    """A noise-free frame of ``db``'s brightest stars around star ``row``, brightest first; the
    star rows of its centroids and its attitude (ICRS -> camera, 3x3)."""
    stars = db.stars
    mag = np.asarray(stars.mag, dtype=np.float64)
    v = np.asarray(stars.vec[row], dtype=np.float64)
    ra = math.degrees(math.atan2(v[1], v[0])) % 360
    dec = math.degrees(math.asin(max(-1.0, min(1.0, v[2]))))
    r = matrix_from_radec_roll(ra, dec, 0.0)
    reach = math.radians(camera.diagonal_fov_deg)
    near = np.asarray(star_tree(db).query_ball_point(v, reach), dtype=np.int64)
    xy, inside = camera.vector_to_pixel(np.asarray(stars.vec[near]) @ r.T)
    near, xy = near[inside], xy[inside]
    order = np.argsort(mag[near])[:20]
    return Centroids(xy[order], 10.0 ** (-0.4 * mag[near][order])), near[order], r
