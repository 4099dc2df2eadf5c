"""Many frames per call: recorded frames parsed once, solved on a pool of threads.

This is the batch path of the engine, for ground processing of recordings (``skyfix solve``,
``skyfix reprocess``). A *frame* is one instant: one camera's centroids, or a rig's cameras.
"""

from __future__ import annotations

import os
from collections.abc import Iterable, Mapping, Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from typing import Any

from .camera import Camera
from .errors import InvalidInputError
from .navdb.reader import NavDatabase, NavDatabaseSet
from .pipeline import DEFAULT_OPTIONS, SolveOptions, solve, solve_rig
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
    views = ((Centroids.from_list(rec.get("centroids", [])), Camera.from_spec(camera), None),)
    return Frame(views, rec.get("id"), truth)


def solve_frame(frame: Frame, db: NavDatabase | NavDatabaseSet, *, method: str = "auto",
                options: SolveOptions = DEFAULT_OPTIONS) -> Solution:
    """Solve one :class:`Frame` (a single camera with :func:`solve`, a rig with :func:`solve_rig`)."""
    if frame.is_rig:
        return solve_rig(list(frame.views), db, method=method, options=options)
    centroids, camera, _ = frame.views[0]
    return solve(centroids, camera, db, method=method, options=options)


def solve_many(frames: Iterable[Frame], db: NavDatabase | NavDatabaseSet, *, method: str = "auto",
               options: SolveOptions = DEFAULT_OPTIONS, workers: int | None = None) -> list[Solution]:
    """Solve many frames; the answers come back in the order of ``frames``.

    Parameters
    ----------
    frames : iterable of Frame
    db : NavDatabase or NavDatabaseSet
        Opened once by the caller and shared by every thread (it is read-only).
    method : str
    options : SolveOptions
    workers : int, optional
        Threads to solve on (default: the cores this process may use). 1 solves in the
        calling thread.
    """
    todo = list(frames)
    if workers is None:
        workers = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)
    workers = max(1, min(workers, len(todo) or 1))
    if workers == 1:
        return [solve_frame(f, db, method=method, options=options) for f in todo]
    with ThreadPoolExecutor(max_workers=workers) as pool:
        return list(pool.map(lambda f: solve_frame(f, db, method=method, options=options), todo))


__all__ = ["Frame", "frame_from_record", "solve_frame", "solve_many"]
