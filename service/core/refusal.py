"""Why a frame has no solution: the refusals decided before any search, and the reason of a
search that proved nothing (``Solution.reason``, ``methods_tried``, ``message``)."""

from __future__ import annotations

import functools
import math
import time
from collections.abc import Sequence

from .camera import Camera
from .methods import AUTO_ORDER
from .methods.capability import FAILURE_HINTS, cannot_serve, refusal_message, serving
from .navdb.reader import NavDatabase, NavDatabaseSet
from .types import Centroids, NoSolutionReason, Solution, SolveStatus, refused_solution_of

OUTSIDE_FACTOR = 2.0
"""A camera is outside a database (refused at once) when no member has both ``fov_min_deg /
OUTSIDE_FACTOR`` <= the camera's side and its diagonal <= ``fov_max_deg * OUTSIDE_FACTOR``. Within
a factor of 2 a camera still often solves (measured on the default database, 30 frames each, 0.5
px: 2.5 deg at V 8.5: 13/30; 36 deg at V 5.5: 17/30; 45 deg at V 5.0: 5/30), beyond it not (1.5
deg at V 9: 0/30; 60 deg at V 5: 0/30, each taking 3-700 ms to say so)."""


def refusal(frames: Sequence[tuple[Centroids, Camera, object]], db: NavDatabase | NavDatabaseSet,
            method: str, t0: float, sigma_px: float | None = None) -> Solution | None:
    """A ``no_solution`` for a frame no method can solve, decided before any warm-up or search
    (a few microseconds): fewer than 3 stars, a camera outside every member's range (see
    ``OUTSIDE_FACTOR``), or, given the declared centroid error ``sigma_px``, a named method
    that cannot serve the camera (:func:`method_refusal`). None if the frame is worth searching."""
    one = len(frames) == 1  # solve()'s frame: no generators (~1 us of a first sight's ~5)
    n = len(frames[0][0]) if one else sum(len(c) for c, _, _ in frames)
    if n < 3:
        return _refused(NoSolutionReason.TOO_FEW_STARS, method, t0,
                        f"{n} star(s) given; identification needs at least 3")
    cameras = (frames[0][1],) if one else tuple(cam for _, cam, _ in frames)
    key = (method, sigma_px, cameras)
    decided = db.__dict__.setdefault("_camera_refusals", {})
    got = decided.get(key, _UNDECIDED)
    if got is _UNDECIDED:  # once per opened database, camera geometry, method and sigma
        if len(decided) >= CAMERA_REFUSALS_KEPT:
            decided.clear()
        got = decided[key] = _camera_refusal(frames, db, method, sigma_px)
    return None if got is None else _refused(got[0], method, t0, got[1])


CAMERA_REFUSALS_KEPT = 256
_UNDECIDED = object()


def _camera_refusal(frames: Sequence[tuple[Centroids, Camera, object]], db: NavDatabase | NavDatabaseSet,
                    method: str, sigma_px: float | None) -> tuple[NoSolutionReason, str] | None:
    """:func:`refusal`'s decision for a frame's cameras (its stars aside): the reason and the
    message, or None."""
    if len(frames) == 1:
        cam = frames[0][1]
        diagonal, narrowest = cam.diagonal_fov_deg, min(cam.fov_deg, cam.fov_y_deg)
    else:
        diagonal = max(cam.diagonal_fov_deg for _, cam, _ in frames)
        narrowest = min(min(cam.fov_deg, cam.fov_y_deg) for _, cam, _ in frames)
    ranges = db.__dict__.get("_fov_ranges")
    if ranges is None:  # once per opened database
        members = list(db.members.values()) if isinstance(db, NavDatabaseSet) else [db]
        ranges = [(float(m.manifest["fov_min_deg"]), float(m.manifest["fov_max_deg"])) for m in members]
        db.__dict__["_fov_ranges"] = ranges
    for lo, hi in ranges:
        if narrowest >= lo / OUTSIDE_FACTOR and diagonal <= hi * OUTSIDE_FACTOR:
            if sigma_px is None or method == "auto":  # (method_refusal's None for auto)
                return None
            why = method_refusal([cam for _, cam, _ in frames], db, method, sigma_px)
            return None if why is None else (NoSolutionReason.CAMERA_OUTSIDE_DATABASE, why)
    served = ", ".join(f"{lo:g}-{hi:g}" for lo, hi in ranges)
    why = (f"camera of {narrowest:.3g} deg side and {diagonal:.3g} deg diagonal is outside the database's range "
           f"(side >= fov_min, diagonal <= fov_max: {served} deg)")
    return NoSolutionReason.CAMERA_OUTSIDE_DATABASE, f"{why}; {_build_hint(narrowest, diagonal)}"


def method_refusal(cameras: Sequence[Camera], db: NavDatabase | NavDatabaseSet, method: str,
                   sigma_px: float) -> str | None:
    """Why the named ``method`` cannot serve ``cameras`` on any member of ``db`` that holds it
    (:mod:`.methods.capability`; a rig is served when one camera is), naming the methods that
    can; None if it can, or for ``auto``. Kept per opened database and camera geometry."""
    if method == "auto":
        return None
    key = (method, sigma_px, tuple((c.width, c.height, c.f_px) for c in cameras))
    cache = db.__dict__.setdefault("_method_refusals", {})
    if key not in cache:
        members = list(db.members.values()) if isinstance(db, NavDatabaseSet) else [db]
        holding = [m for m in members if method in m.tables]
        whys = [cannot_serve(m, method, c, sigma_px) for m in holding for c in cameras]
        if not holding or any(w is None for w in whys):
            cache[key] = None
        else:
            alternatives = [a for m in holding for a in serving(m, cameras, sigma_px, AUTO_ORDER)]
            where = f"this camera ({cameras[0].fov_deg:.3g} deg) on this database"
            cache[key] = refusal_message(method, str(whys[0]), where, list(dict.fromkeys(alternatives)))
    return cache[key]


def _build_hint(side: float, diagonal: float) -> str:
    """The ``skyfix db build`` command of a database for a camera of this side and diagonal
    (deg); its magnitude limit keeps about seed 000's stars a frame (V 6.5 at 8.6 deg; star
    counts grow ~10^0.45 a magnitude), within V 4.5-9."""
    if math.ceil(diagonal * 10 + 2) / 10 >= 90:
        return "skyfix databases serve fields below 90 deg (diagonal)"
    mag = min(max(6.5 + math.log10((8.6 / max(side, 0.1)) ** 2) / 0.45, 4.5), 9.0)
    return f"a database that serves it: skyfix db build --out db/camera {_fov_flags(side, diagonal)} --mag-limit {mag:.1f}"


def _fov_flags(side: float, diagonal: float) -> str:
    """``skyfix db build``'s field flags for cameras of this narrowest side and widest diagonal
    (deg): the side rounded down, the diagonal up with 0.2 deg to spare."""
    return f"--fov-min {math.floor(side * 10) / 10:g} --fov-max {math.ceil(diagonal * 10 + 2) / 10:g}"


SPARSE_ADVICE_STARS = 5
"""A frame of 3 to this many stars that a database set (the default) could not prove is told how
to build a database for its camera(s): one holding every star to the camera's own limit, with no
density cap, proves some frames that sparse which the set's members cannot (seed 002's 4-deg
camera at 7 Mv, 0.5 px: 6 of 500 frames, all right; docs/benchmarks.md, the default database
against a database per camera; GF-7's rig at 5.5 Mv: 3-star frames, docs/methods.md, sparse rig
frames)."""


@functools.lru_cache(maxsize=256)
def sparse_advice(cameras: tuple[Camera, ...]) -> str:
    """How to build the database that may prove a sparse frame of ``cameras`` (one camera, or a
    rig: then with ``multifov``, whose cross-camera proof names 3-star rig frames; see
    :data:`SPARSE_ADVICE_STARS`). Kept per cameras (every sparse frame of a camera is told the
    same: ~2 us of a ~58-us refusal of a 5-star frame on seed 002)."""
    flags = _fov_flags(min(min(c.fov_deg, c.fov_y_deg) for c in cameras), max(c.diagonal_fov_deg for c in cameras))
    what, methods = ("this camera", "maxangle,pyramid,triangle") if len(cameras) == 1 else ("this rig", "multifov")
    return (f"a frame this sparse may be proven on a database built for {what}, holding every star to "
            "the camera's own limit (a deeper one predicts stars the camera does not see): skyfix db build "
            f"--out db/camera {flags} --methods {methods} --mag-limit V, with V the faintest (approximate V) "
            "magnitude the camera detects")


def _refused(reason: NoSolutionReason, method: str, t0: float, message: str) -> Solution:
    return Solution(SolveStatus.NO_SOLUTION, method, reason=reason, message=message,
                    timings_ms={"total": (time.perf_counter() - t0) * 1e3})


def no_solution(method: str, tried: list[str], trials: int, late: bool, timings: dict[str, float],
                unprovable: Sequence[str] = (), n_stars: int | None = None, advice: str = "") -> Solution:
    """The answer of a searched frame that nothing proved: why, and what ran. ``unprovable``:
    methods skipped because no answer of theirs could pass the coincidence bound on this frame of
    ``n_stars`` stars (when nothing else ran, that is the reason: too few stars); ``advice``, what
    might prove it (:func:`sparse_advice`), ends the message."""
    ran = tuple(dict.fromkeys(tried))
    reason, message = _refusal_text(method, ran, tuple(unprovable), trials, late, n_stars, advice)
    return refused_solution_of(tried[-1] if tried else method, reason, ran, message, timings)


@functools.lru_cache(maxsize=1024)
def _refusal_text(method: str, ran: tuple[str, ...], unprovable: tuple[str, ...], trials: int, late: bool,
                  n_stars: int | None, advice: str) -> tuple[NoSolutionReason, str]:
    """:func:`no_solution`'s reason and message, kept per arguments: most refusals of a camera
    repeat a few (the same methods, no pattern matched), and the message took ~4 of a refusal's
    ~6 us to format on this VM."""
    skipped = ", ".join(m for m in dict.fromkeys(unprovable) if m not in ran) if unprovable else ""  # on no member
    note = (f"; not run: {skipped} (even with all {n_stars} stars paired, no answer of theirs could pass "
            f"the coincidence bound on this camera)") if skipped else ""
    if late:
        reason, why = NoSolutionReason.TIME_LIMIT, "the time limit ended the search"
    elif not ran and skipped:
        reason, why = NoSolutionReason.TOO_FEW_STARS, f"{n_stars} stars are too few to prove an identification here"
    elif trials == 0:
        reason, why = NoSolutionReason.NO_PATTERN_MATCH, "no catalogue pattern matched the frame's"
    else:
        reason, why = (NoSolutionReason.NOT_PROVEN,
                       f"{trials} candidate attitude(s) checked, none proven beyond the coincidence bound")
    hint = f"; {FAILURE_HINTS[method]}" if method in FAILURE_HINTS else ""
    hint += f"; {advice}" if advice else ""
    return reason, f"{why} (methods tried: {', '.join(ran) or 'none'}){note}{hint}"


__all__ = ["OUTSIDE_FACTOR", "SPARSE_ADVICE_STARS", "method_refusal", "no_solution", "refusal", "sparse_advice"]
