"""The search plan: which members of a database (set) to search, with which methods, in what
order, and the member an answer is refined against (:func:`search_plan`, kept per database and
camera). :mod:`service.core.pipeline` walks it."""

from __future__ import annotations

from .camera import Camera
from .errors import UnknownMethodError
from .methods import WIDE_FIELD_DEG, WIDE_NOISY_PX, get_method, resolve
from .navdb.reader import NavDatabase, NavDatabaseSet

PLAN_CACHE_SIZE = 256
"""Search plans kept per opened database (one per camera geometry, method and sigma seen)."""


def search_plan(db: NavDatabase | NavDatabaseSet, cameras: list[Camera], method: str, sigma_px: float | None
                ) -> tuple[list[tuple[NavDatabase, list[str]]], NavDatabase]:
    """The members and methods to search, in order (:func:`member_order`), and the member to
    refine an answer against, for these cameras; kept per database, as every frame of a camera
    asks the same (choosing them costs ~30 us a frame)."""
    key = (method, sigma_px, tuple(cameras))  # cameras are hashable values: a camera's fields fix its plan
    cache = db.__dict__.setdefault("_plans", {})
    got = cache.get(key)
    if got is not None:
        return got
    # a camera seen for the first time (each real image brings its own) most often shares its
    # plan with one seen before: kept by what the plan depends on (~5 us against ~20 to choose)
    shape = _plan_shape(db, cameras, method, sigma_px)
    shapes = db.__dict__.setdefault("_plan_shapes", {})
    plan = shapes.get(shape)
    if plan is None:
        plan = _choose(db, cameras, method, sigma_px)
        if len(shapes) >= PLAN_CACHE_SIZE:
            shapes.clear()
        shapes[shape] = plan
    if len(cache) >= PLAN_CACHE_SIZE:
        cache.clear()
    cache[key] = plan
    return plan


def _plan_shape(db: NavDatabase | NavDatabaseSet, cameras: list[Camera], method: str, sigma_px: float | None
                ) -> tuple:
    """Everything :func:`_choose` reads of the cameras and the centroid error: the members that
    fit the widest camera, whether the field is wide and the error large (``resolve``'s order),
    rig or not, and which members' ``maxangle`` tables hold the first camera's diagonal
    (:func:`covered_fallbacks`)."""
    diagonal = cameras[0].diagonal_fov_deg
    if len(cameras) == 1:  # every solve() frame: each field once (~2 us of a first sight's ~6)
        fov = widest_fov = cameras[0].fov_deg
        widest_diagonal = diagonal
    else:
        widest = max(cameras, key=lambda c: c.diagonal_fov_deg)
        widest_fov, widest_diagonal = widest.fov_deg, widest.diagonal_fov_deg
        fov = max(cam.fov_deg for cam in cameras)
    fitting: tuple[int, ...] = ()
    if isinstance(db, NavDatabaseSet):
        fitting = tuple(map(id, db.for_camera(widest_fov, widest_diagonal)))
    noisy = sigma_px is None or sigma_px >= WIDE_NOISY_PX
    covered = tuple([diagonal <= reach for reach in _reaches(db)])
    return method, len(cameras) > 1, fitting, fov >= WIDE_FIELD_DEG, noisy, covered


def _reaches(db: NavDatabase | NavDatabaseSet) -> tuple[float, ...]:
    """:func:`maxangle_reach_deg` of each member (of ``db`` alone for one database), kept."""
    got = db.__dict__.get("_maxangle_reaches")
    if got is None:
        members = db.members.values() if isinstance(db, NavDatabaseSet) else [db]
        got = db.__dict__["_maxangle_reaches"] = tuple(maxangle_reach_deg(m) for m in members)
    return got


def _choose(db: NavDatabase | NavDatabaseSet, cameras: list[Camera], method: str, sigma_px: float | None
            ) -> tuple[list[tuple[NavDatabase, list[str]]], NavDatabase]:
    """:func:`search_plan`'s choice, made anew."""
    if isinstance(db, NavDatabaseSet):
        widest = max(cameras, key=lambda c: c.diagonal_fov_deg)
        fitting = db.for_camera(widest.fov_deg, widest.diagonal_fov_deg)
        # search the shallowest fitting member first (bright stars: few, fast, robust; of equal
        # depth the one made for the narrower range), then refine the answer against the
        # deepest one (more stars, a better attitude)
        members = sorted(fitting, key=lambda m: (m.mag_limit, m.max_fov_deg))
        deepest = max(fitting, key=lambda m: (m.mag_limit, -m.max_fov_deg))
        if method != "auto":  # a named method: the members that hold it (the set's `sparse` holds triangle)
            holding = [m for m in members if method in m.tables]
            if not holding:
                get_method(method)  # an unregistered name: its own error
                methods = sorted({name for m in members for name in m.methods})
                raise UnknownMethodError(method, ["auto", *methods])
            members = holding
    else:
        members, deepest = [db], db
    fov = max(cam.fov_deg for cam in cameras)
    method_lists = [resolve(m, method, fov_deg=fov, sigma_px=sigma_px) for m in members]
    if method == "auto" and len(cameras) > 1:
        method_lists = [rig_methods(ms) for ms in method_lists]
    elif method == "auto" and any(ms != [RIG_METHOD] for ms in method_lists):
        # one camera: a member that holds the rig method alone (the default set's ``rig``) is
        # left to rigs when another member serves the camera
        method_lists = [[] if ms == [RIG_METHOD] else ms for ms in method_lists]
        method_lists = covered_fallbacks(members, method_lists, cameras[0].diagonal_fov_deg)
    return member_order(members, method_lists), deepest


RIG_METHOD = "multifov"
"""The method made for rigs (several cameras on one body): it identifies each camera's
brightest star by votes within its own camera and joins the cameras through their known
mountings, so it proves frames that no single camera could, e.g. (2, 2) or (1, 3) stars per
camera (``python -m bench.bench_rig``)."""


def rig_methods(methods: list[str]) -> list[str]:
    """``auto``'s methods of one member for a rig frame: :data:`RIG_METHOD` right after the
    first (fast) method, so that it is the fallback that runs when the first pass misses."""
    if RIG_METHOD not in methods:
        return methods
    rest = [m for m in methods if m != RIG_METHOD]
    return [rest[0], RIG_METHOD, *rest[1:]] if rest else [RIG_METHOD]


def maxangle_reach_deg(member: NavDatabase) -> float:
    """The longest triangle side (degrees) ``member``'s ``maxangle`` table holds (0 without one)."""
    if "maxangle" not in member.tables:
        return 0.0
    return float(member.method_params("maxangle")["d_max_deg"])


def covered_fallbacks(members: list[NavDatabase], method_lists: list[list[str]], diagonal_deg: float
                      ) -> list[list[str]]:
    """``auto``'s methods per member for one camera of diagonal ``diagonal_deg``, without the
    fallbacks of a member searched after one whose ``maxangle`` table holds every triangle of
    the camera's field (``d_max`` at least the diagonal) while its own holds only part of it.

    The default set's ``mid`` sees the whole field of seed 000's 8.6-deg camera; ``narrow``,
    after it, holds triangles to 3.5 deg only. On that camera ``narrow``'s ``quad`` proved 33 of
    9,000 simulated frames that ``mid`` missed (0.5-2 px, 0-5 false stars), its ``maxangle`` and
    ``pyramid`` none, while its ``maxangle`` took ~0.26 ms of every random-point frame's ~1.2
    (session 20, docs/performance.md). Its ``quad`` stays: that is the first pass of each member.
    """
    covering = False
    out = []
    for member, methods in zip(members, method_lists, strict=True):
        reach = maxangle_reach_deg(member)
        if covering and reach < diagonal_deg and len(methods) > 1:
            methods = methods[:1]
        out.append(methods)
        covering = covering or ("maxangle" in methods and reach >= diagonal_deg)
    return out


def member_order(members: list[NavDatabase], method_lists: list[list[str]]) -> list[tuple[NavDatabase, list[str]]]:
    """The order of the search over a database set: every member's first method (the fast
    pass) before any member's fallbacks, so a frame that the first method of the second member
    solves does not wait for the first member's slow fallbacks, and a frame no one solves
    spends its fallback time only once the fast passes have all failed."""
    first = [(m, ms[:1]) for m, ms in zip(members, method_lists, strict=True) if ms]
    rest = [(m, ms[1:]) for m, ms in zip(members, method_lists, strict=True) if len(ms) > 1]
    return first + rest


def fallback_next(order: list[tuple[NavDatabase, list[str]]], i: int) -> None:
    """Move the fallback of ``order[i]``'s member to right after it, in place (see
    :data:`~service.core.pipeline.SMALL_FRAME_FALLBACK_FIRST`)."""
    member = order[i][0]
    for j in range(i + 1, len(order)):
        if order[j][0] is member:
            order.insert(i + 1, order.pop(j))
            return
