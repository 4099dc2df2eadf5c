"""Many frames per call: recorded frames parsed and solved on all cores (forked workers).

This is the batch path of the engine, for ground processing of recordings (``skyfix solve``,
``skyfix reprocess``). A *frame* is one instant: one camera's centroids, or a rig's cameras.
"""

from __future__ import annotations

import multiprocessing as mp
import os
import pickle
import threading
from collections.abc import Callable, Iterable, Mapping, Sequence
from concurrent.futures import ProcessPoolExecutor, ThreadPoolExecutor
from dataclasses import dataclass
from typing import Any

import orjson

from .camera import Camera
from .errors import InvalidInputError, SkyfixError
from .navdb.reader import NavDatabase, NavDatabaseSet
from .pipeline import DEFAULT_OPTIONS, SolveOptions, solve, solve_rig, warm_up
from .types import Centroids, Solution


@dataclass(frozen=True, slots=True)
class Frame:
    """One instant to solve.

    Attributes
    ----------
    views : tuple of (Centroids, Camera, mounting quaternion [w, x, y, z] or None)
        One entry for a single camera (mounting None), one per camera for a rig.
    id : Any
        The recording's ``id`` of the frame (echoed in the result), or None.
    truth : dict or None
        The recording's ``truth`` object, if any (never used to solve).
    """

    views: tuple[tuple[Centroids, Camera, Sequence[float] | None], ...]
    id: Any = None
    truth: Mapping[str, Any] | None = None

    @property
    def is_rig(self) -> bool:
        """True when the frame came as ``cameras: [...]`` (a rig), even of one camera."""
        return len(self.views) != 1 or self.views[0][2] is not None


def frame_from_record(rec: Mapping[str, Any]) -> Frame:
    """Parse one recorded frame (the README's JSON Lines format) into a :class:`Frame`.

    Raises ``InvalidInputError`` naming the field on anything malformed.
    """
    if not isinstance(rec, Mapping):
        raise InvalidInputError("frame", "expected a JSON object")
    truth = rec.get("truth")
    if rec.get("cameras"):
        cams = rec["cameras"]
        if not isinstance(cams, list):
            raise InvalidInputError("cameras", "expected a list of {camera, centroids} objects")
        views = []
        for i, c in enumerate(cams):
            if not isinstance(c, Mapping) or not isinstance(c.get("camera"), Mapping):
                raise InvalidInputError(f"cameras[{i}].camera", "expected an object")
            views.append((Centroids.from_list(c.get("centroids", []), field_name=f"cameras[{i}].centroids"),
                          Camera.from_spec(c["camera"], field=f"cameras[{i}].camera"),
                          c["camera"].get("mounting_quaternion")))
        return Frame(tuple(views), rec.get("id"), truth)
    camera = rec.get("camera")
    if not isinstance(camera, Mapping):
        raise InvalidInputError("camera", "a camera object is required")
    views = ((Centroids.from_list(rec.get("centroids", [])), _camera(camera), None),)
    return Frame(views, rec.get("id"), truth)


_CAMERAS: dict[tuple[Any, ...], Camera] = {}


def _camera(spec: Mapping[str, Any]) -> Camera:
    """``Camera.from_spec(spec)``, kept per spec: a recording repeats one camera on every line
    (parsing and checking it again costs ~5 us a frame). A spec holding a list (distortion) is
    not kept."""
    try:
        key = tuple(spec.items())
        camera = _CAMERAS.get(key)
    except TypeError:  # unhashable values
        return Camera.from_spec(spec)
    if camera is None:
        camera = Camera.from_spec(spec)
        if len(_CAMERAS) >= 64:
            _CAMERAS.clear()
        _CAMERAS[key] = camera
    return camera


def solve_frame(frame: Frame, db: NavDatabase | NavDatabaseSet, *, method: str = "auto",
                options: SolveOptions = DEFAULT_OPTIONS) -> Solution:
    """Solve one :class:`Frame` (a single camera with :func:`solve`, a rig with :func:`solve_rig`)."""
    if frame.is_rig:
        return solve_rig(list(frame.views), db, method=method, options=options)
    centroids, camera, _ = frame.views[0]
    return solve(centroids, camera, db, method=method, options=options)


@dataclass(frozen=True, slots=True)
class FrameError:
    """An item :func:`solve_many` could not parse or solve (with ``return_errors``): the
    error's text and the field it names, if any (plain data, so it crosses process bounds)."""

    message: str
    field: str | None = None


Item = Frame | Mapping[str, Any] | str | bytes
"""What :func:`solve_many` takes: a :class:`Frame`, a parsed record, or one JSON Lines line."""


def solve_many(frames: Iterable[Item], db: NavDatabase | NavDatabaseSet, *, method: str = "auto",
               options: SolveOptions = DEFAULT_OPTIONS, workers: int | None = None,
               then: Callable[[Any, Solution], Any] | None = None, return_errors: bool = False,
               pool: str = "process") -> list[Any]:
    """Solve many frames on all cores; the answers come back in the order of ``frames``.

    Parameters
    ----------
    frames : iterable of Frame, record (dict) or JSON line (str/bytes)
        Records and lines are parsed in the workers (:func:`frame_from_record`; lines with
        orjson: strict JSON, no NaN or Infinity literals).
    db : NavDatabase or NavDatabaseSet
        Opened once by the caller; warmed up here once, before the workers start, so every
        worker starts with the compiled kernels and indexes (it is read-only and
        memory-mapped: worker processes share its pages).
    method : str
    options : SolveOptions
    workers : int, optional
        Workers to solve on (default: the cores this process may use). 1 solves in the calling
        thread.
    then : callable, optional
        ``then(record, solution)`` runs in the worker and its value is returned instead of the
        solution (the CLI formats and scores there); ``record`` is the item, parsed if it was a
        JSON line.
    return_errors : bool
        An item whose parse or solve raises ``SkyfixError`` (or ``ValueError``, ``KeyError``,
        ``TypeError`` from a malformed line) gets a :class:`FrameError` in its place instead of
        raising.
    pool : {"process", "thread"}
        ``"process"`` (POSIX fork): each worker is a forked copy of this process, truly
        parallel (from a single-threaded process only; otherwise threads). ``"thread"``: a
        thread pool; the numba kernels release the GIL, but most of a frame's time is Python
        around them (docs/benchmarks.md, Batch), so threads gain little.
    """
    if pool not in ("process", "thread"):
        raise ValueError(f"pool must be 'process' or 'thread', not {pool!r}")
    todo = list(frames)
    if workers is None:
        workers = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)
    workers = max(1, min(workers, len(todo) or 1))
    if not db.__dict__.get("_warm"):
        warm_up(db)  # once, before any worker exists

    def task(item: Item) -> Any:
        try:
            rec = orjson.loads(item) if isinstance(item, (str, bytes)) else item
            frame = rec if isinstance(rec, Frame) else frame_from_record(rec)
            sol = solve_frame(frame, db, method=method, options=options)
            return sol if then is None else then(rec, sol)
        except (SkyfixError, ValueError, KeyError, TypeError) as exc:
            if not return_errors:
                raise
            return FrameError(str(exc), getattr(exc, "field", None))

    if workers == 1:
        return [task(f) for f in todo]
    # fork only a single-threaded process: a thread holding a lock at the fork would leave the
    # lock held forever in the child
    if pool == "process" and "fork" in mp.get_all_start_methods() and threading.active_count() == 1:
        return _fork_map(task, todo, workers)
    with ThreadPoolExecutor(max_workers=workers) as threads:
        return list(threads.map(task, todo))


_JOB: tuple[Callable[[Any], Any], Sequence[Any]] | None = None
"""The task and items of the running :func:`_fork_map`: forked workers inherit them, so only
chunk bounds go to a worker and only results come back (nothing else is pickled)."""


@dataclass(frozen=True)
class _Raised:
    """An exception raised in a forked worker, carried back to be raised in the caller."""

    error: BaseException


def _run_chunk(bounds: tuple[int, int]) -> list[Any] | _Raised:
    assert _JOB is not None
    fn, items = _JOB
    try:
        return [fn(item) for item in items[bounds[0]:bounds[1]]]
    except Exception as exc:  # noqa: BLE001 - re-raised in the caller
        try:
            pickle.loads(pickle.dumps(exc))
        except Exception:  # noqa: BLE001 - an exception that cannot cross processes
            exc = RuntimeError(f"{type(exc).__name__}: {exc}")
        return _Raised(exc)


def _fork_map(fn: Callable[[Any], Any], items: Sequence[Any], workers: int) -> list[Any]:
    """``[fn(x) for x in items]`` on ``workers`` forked processes, in order. Chunks of about
    1/8 of a worker's share balance slow frames against the cost of a round trip."""
    global _JOB
    size = max(16, -(-len(items) // (8 * workers)))
    bounds = [(lo, min(lo + size, len(items))) for lo in range(0, len(items), size)]
    _JOB = (fn, items)
    try:
        out: list[Any] = []
        # an executor, not mp.Pool: a worker that dies (killed, out of memory) raises
        # BrokenProcessPool here instead of leaving the caller waiting forever
        with ProcessPoolExecutor(workers, mp_context=mp.get_context("fork")) as procs:
            for chunk in procs.map(_run_chunk, bounds):
                if isinstance(chunk, _Raised):
                    raise chunk.error
                out.extend(chunk)
        return out
    finally:
        _JOB = None


__all__ = ["Frame", "FrameError", "frame_from_record", "solve_frame", "solve_many"]
