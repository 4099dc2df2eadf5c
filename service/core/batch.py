"""Many frames per call: recorded frames parsed and solved on all cores (forked workers).

This is the batch path of the engine, for ground processing of recordings (``skyfix solve``,
``skyfix reprocess``). A *frame* is one instant: one camera's centroids, or a rig's cameras.
"""

from __future__ import annotations

import gc
import multiprocessing as mp
import os
import pickle
import threading
from collections import deque
from collections.abc import Callable, Iterable, Iterator, Mapping, Sequence, Sized
from concurrent.futures import Future, ProcessPoolExecutor, ThreadPoolExecutor
from dataclasses import dataclass
from itertools import islice
from typing import Any

import orjson

from ._cores import usable_cores
from .camera import Camera
from .errors import InvalidInputError, SkyfixError
from .navdb.reader import NavDatabase, NavDatabaseSet
from .pipeline import DEFAULT_OPTIONS, SolveOptions, solve, solve_rig
from .types import Centroids, Solution
from .warmup import warm_up


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
    return list(solve_iter(frames, db, method=method, options=options, workers=workers, then=then,
                           return_errors=return_errors, pool=pool))


def solve_iter(frames: Iterable[Item], db: NavDatabase | NavDatabaseSet, *, method: str = "auto",
               options: SolveOptions = DEFAULT_OPTIONS, workers: int | None = None,
               then: Callable[[Any, Solution], Any] | None = None, return_errors: bool = False,
               pool: str = "process") -> Iterator[Any]:
    """:func:`solve_many`, yielding each answer, in order, as soon as it and those before it are
    ready: a caller that writes answers out does so while the workers go on solving. Same
    parameters as :func:`solve_many`; the workers are started on the first ``next()`` and
    stopped when the generator ends or is closed (a caller solving block after block keeps
    one :class:`SolvePool` instead)."""
    todo = list(frames)
    with SolvePool(db, method=method, options=options, workers=min(workers or usable_cores(), len(todo) or 1),
                   then=then, return_errors=return_errors, pool=pool) as solver:
        yield from solver.imap(todo)


class SolvePool:
    """Workers that solve frames, started once and fed block after block (``skyfix solve``).

    Parameters are those of :func:`solve_many`. With ``pool="process"`` (and POSIX fork, from
    a single-threaded process) the workers are forked here, after the database is warmed up,
    so each starts with the compiled kernels and indexes and shares the memory-mapped
    database's pages; their task (database, method, options, ``then``) is inherited through the
    fork and only the frames and the answers are pickled. Otherwise threads; ``workers=1``
    solves in the calling thread. Use as a context manager, or call :meth:`close`.
    """

    def __init__(self, db: NavDatabase | NavDatabaseSet, *, method: str = "auto",
                 options: SolveOptions = DEFAULT_OPTIONS, workers: int | None = None,
                 then: Callable[[Any, Solution], Any] | None = None, return_errors: bool = False,
                 pool: str = "process") -> None:
        global _TASK
        if pool not in ("process", "thread"):
            raise ValueError(f"pool must be 'process' or 'thread', not {pool!r}")
        if not db.__dict__.get("_warm"):
            warm_up(db)  # once, before any worker exists
        self.workers = max(1, workers or usable_cores())
        self._task = _make_task(db, method, options, then, return_errors)
        self._procs: ProcessPoolExecutor | None = None
        self._threads: ThreadPoolExecutor | None = None
        if self.workers == 1:
            return
        # fork only a single-threaded process: a thread holding a lock at the fork would leave
        # the lock held forever in the child
        if pool == "process" and "fork" in mp.get_all_start_methods() and threading.active_count() == 1:
            _TASK = self._task
            gc.collect()
            gc.freeze()  # the workers never collect what they inherit: no copy-on-write of its pages
            try:
                # an executor, not mp.Pool: a worker that dies (killed, out of memory) raises
                # BrokenProcessPool in the caller instead of leaving it waiting forever
                self._procs = ProcessPoolExecutor(self.workers, mp_context=mp.get_context("fork"))
                for f in [self._procs.submit(os.getpid) for _ in range(self.workers)]:
                    f.result()  # every worker forked (with the task above) before it is reset
            finally:
                _TASK = None
                gc.unfreeze()  # in this process only
        else:
            self._threads = ThreadPoolExecutor(max_workers=self.workers)

    def imap(self, frames: Iterable[Item]) -> Iterator[Any]:
        """Solve ``frames``, yielding the answers in order as they are ready. Frames go to the
        workers in chunks, at most :data:`CHUNKS_IN_FLIGHT` per worker at a time, so an
        iterable is read only as fast as it is solved. Closing the generator early cancels
        the chunks not yet started."""
        if self._procs is None and self._threads is None:
            yield from map(self._task, frames)
            return
        size = CHUNK
        if isinstance(frames, Sized):  # small chunks for a small block: every worker gets some
            size = max(1, min(CHUNK, -(-len(frames) // (CHUNKS_PER_WORKER * self.workers))))
        items = iter(frames)
        chunks = iter(lambda: list(islice(items, size)), [])
        for answers in self._in_order(((_run_local, (chunk,)) for chunk in chunks), CHUNKS_IN_FLIGHT):
            yield from answers

    def map_file(self, path: str | os.PathLike[str], fold: Callable[[Iterator[tuple[int, Any]]], Any]
                 ) -> Iterator[Any]:
        """Solve every non-blank line of the JSON Lines file ``path`` (a regular file), in byte
        ranges that the workers read themselves: only each range's bounds go to a worker and
        only ``fold``'s value comes back, so the calling process does almost nothing per frame
        (:meth:`imap` pickles every line out and every answer back: ~9 us a frame of this
        process's core; on the 2-core VM of docs/performance.md, session 38, frames/s stayed
        within the machine's spread).

        ``fold(pairs)`` runs in the worker on an iterator of ``(byte offset of the line,
        answer)``, in file order, one range at a time; it may stop early (the range's later
        lines are then not solved). It must be a module-level function (it is pickled by name).
        Yields each range's ``fold`` value in file order. The ranges
        (:func:`file_ranges`) shrink toward the end of the file so that the workers finish
        together; at most :data:`RANGES_IN_FLIGHT` per worker are held at a time. Closing the
        generator early cancels the ranges not yet started."""
        path = os.fspath(path)
        ranges = file_ranges(os.stat(path).st_size, self.workers)
        if self._procs is None and self._threads is None:
            for start, end in ranges:
                yield _fold_local(self._task, path, start, end, fold)
            return
        yield from self._in_order(((_fold_local, (path, start, end, fold)) for start, end in ranges),
                                  RANGES_IN_FLIGHT)

    def _in_order(self, jobs: Iterator[tuple[Callable[..., Any], tuple[Any, ...]]], per_worker: int) -> Iterator[Any]:
        """``fn(task, *args)`` of each job ``(fn, args)``, in the jobs' order, on the workers (a
        forked worker's task is the one it inherited, :func:`_in_worker`); at most ``per_worker``
        jobs per worker submitted at a time, and ``jobs`` read only as they are submitted. An
        exception a forked worker carried back is raised here; closing early cancels the jobs not
        yet started."""
        pending: deque[Future[Any]] = deque()
        try:
            while True:
                while len(pending) < per_worker * self.workers:
                    job = next(jobs, None)
                    if job is None:
                        break
                    fn, args = job
                    pending.append(self._procs.submit(_in_worker, fn, *args) if self._procs is not None
                                   else self._threads.submit(fn, self._task, *args))  # type: ignore[union-attr]
                if not pending:
                    return
                answer = pending.popleft().result()
                if isinstance(answer, _Raised):
                    raise answer.error
                yield answer
        finally:
            for f in pending:
                f.cancel()

    def close(self) -> None:
        """Stop the workers (waiting for the chunks they hold)."""
        for ex in (self._procs, self._threads):
            if ex is not None:
                ex.shutdown(wait=True, cancel_futures=True)
        self._procs = self._threads = None

    def __enter__(self) -> SolvePool:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


CHUNK = 128
"""Frames a worker takes at a time (~15 ms of solving on the 12-deg camera): each chunk costs
one round trip (~0.1 ms)."""
CHUNKS_PER_WORKER = 16
"""A block of known length is cut into at least this many chunks per worker, so that both
workers stay busy to its end."""
CHUNKS_IN_FLIGHT = 4
"""Chunks queued per worker: enough that a worker never waits for the next."""


RANGE_MAX_BYTES = 1 << 20
"""Largest byte range of a file a worker takes at a time (:meth:`SolvePool.map_file`; about
1,000 frames of the 12-deg camera, ~0.13 s of solving)."""
RANGE_MIN_BYTES = 1 << 15
"""Smallest range (but the file's last): at the end of a file the last ranges cost a worker
at most this much more time than the other (~30 frames, 4 ms)."""
RANGES_IN_FLIGHT = 2
"""Ranges held per worker: its next one is queued while it solves one."""


def file_ranges(size: int, workers: int) -> list[tuple[int, int]]:
    """Byte ranges ``[start, end)`` covering a file of ``size`` bytes, for ``workers`` workers:
    each a ``1 / (2 * workers)`` share of what remains (guided scheduling), within
    :data:`RANGE_MIN_BYTES` and :data:`RANGE_MAX_BYTES`. A range holds the lines that *start*
    in it (:func:`_range_answers`)."""
    out, start = [], 0
    while start < size:
        step = min(RANGE_MAX_BYTES, max(RANGE_MIN_BYTES, (size - start) // (2 * workers)))
        out.append((start, min(size, start + step)))
        start += step
    return out


def _range_answers(task: Callable[[Item], Any], path: str, start: int, end: int) -> Iterator[tuple[int, Any]]:
    """``(offset, task(line))`` for each non-blank line of ``path`` that starts at a byte offset in
    ``[start, end)`` (a line that starts before ``start`` belongs to the range before)."""
    with open(path, "rb") as f:
        pos = start
        if start > 0:
            f.seek(start - 1)
            pos = start - 1 + len(f.readline())  # the rest of the line that started before
        while pos < end:
            line = f.readline()
            if not line:
                return
            if line.strip():
                yield pos, task(line)
            pos += len(line)


def _fold_local(task: Callable[[Item], Any], path: str, start: int, end: int,
                fold: Callable[[Iterator[tuple[int, Any]]], Any]) -> Any:
    """``fold`` over ``task``'s answers on the lines of ``path`` that start in ``[start, end)``."""
    return fold(_range_answers(task, path, start, end))


def _in_worker(fn: Callable[..., Any], *args: Any) -> Any:
    """In a forked worker: ``fn(task, *args)`` with the task it inherited; an exception comes back
    as a :class:`_Raised`, to be raised in the caller."""
    assert _TASK is not None, "a forked worker of a SolvePool"
    try:
        return fn(_TASK, *args)
    except Exception as exc:  # noqa: BLE001 - re-raised in the caller
        try:
            pickle.loads(pickle.dumps(exc))
        except Exception:  # noqa: BLE001 - an exception that cannot cross processes
            exc = RuntimeError(f"{type(exc).__name__}: {exc}")
        return _Raised(exc)


def _make_task(db: NavDatabase | NavDatabaseSet, method: str, options: SolveOptions,
               then: Callable[[Any, Solution], Any] | None, return_errors: bool) -> Callable[[Item], Any]:
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

    return task


_TASK: Callable[[Item], Any] | None = None
"""The task of the :class:`SolvePool` being started: its forked workers inherit it, so only
frames go to a worker and only answers come back."""


@dataclass(frozen=True)
class _Raised:
    """An exception raised in a forked worker, carried back to be raised in the caller."""

    error: BaseException


def _run_local(task: Callable[[Item], Any], chunk: list[Item]) -> list[Any]:
    """``task`` on each item of ``chunk``."""
    return [task(item) for item in chunk]


__all__ = ["Frame", "FrameError", "SolvePool", "file_ranges", "frame_from_record", "solve_frame", "solve_iter",
           "solve_many"]
