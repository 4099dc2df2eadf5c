"""Wire models -> engine arguments, in one place.

Every check that needs server state (configured cameras, the centroid limit) happens here
and raises ``InvalidInputError`` naming the field's dotted path; the route handlers only
call ``frame_call`` and hand the result to the solver.
"""

from __future__ import annotations

import json
import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, replace
from functools import partial
from typing import TypeVar

from pydantic import ValidationError

from client.models import AttitudeHint, CameraSpec, SolveRequest

from ..core import pipeline
from ..core.camera import Camera
from ..core.errors import InvalidInputError, UnknownMethodError
from ..core.methods import get_method
from ..core.navdb import NavDatabase, NavDatabaseSet
from ..core.pipeline import SolveOptions
from ..core.types import Centroids, Solution

NavDb = NavDatabase | NavDatabaseSet
"""One database, or a set whose member the engine picks per camera."""
Quat = tuple[float, float, float, float]
Hint = tuple[Quat, float]
SolveCall = Callable[[], Solution]
V = TypeVar("V", Camera, SolveOptions)


@dataclass(frozen=True, slots=True)
class CameraEntry:
    """A resolved camera and its mounting (body -> camera, ``[w, x, y, z]``; None = identity)."""

    camera: Camera
    mounting: Quat | None = None


def unit_quaternion(q: Sequence[float], field: str) -> Quat:
    """Normalise ``q``; refuse one far from unit length (a typo, not rounding)."""
    norm = math.sqrt(sum(v * v for v in q))
    if not 0.9 < norm < 1.1:
        raise InvalidInputError(field, f"quaternion norm is {norm:.3g}, expected 1 ([w, x, y, z])")
    w, x, y, z = (float(v) / norm for v in q)
    return (w, x, y, z)


INTERNED_KEPT = 256
"""Cameras and solve options kept by :func:`interned` (cleared when full)."""
_INTERNED: dict[Camera | SolveOptions, Camera | SolveOptions] = {}


def interned(value: V) -> V:
    """The object equal to ``value`` that an earlier request brought, else ``value`` itself.

    The engine keeps a camera's set-up (plan, first-pass arguments, probes) with the camera and
    options *objects* (``service.core.camera_setup``), and a request builds new ones from its
    JSON: interned, the frames of one camera find their set-up again and take the first pass from
    the centroids as given (~10% of a clean frame's engine time)."""
    try:
        got = _INTERNED.get(value)
    except TypeError:  # an unhashable value (not expected of these frozen dataclasses)
        return value
    if got is None:
        if len(_INTERNED) >= INTERNED_KEPT:
            _INTERNED.clear()
        _INTERNED[value] = got = value
    return got  # type: ignore[return-value]


def camera_entry(spec: CameraSpec, field: str) -> CameraEntry:
    """Build the engine camera, renaming the engine's ``camera.*`` fields to ``field.*``."""
    try:
        cam = interned(Camera.from_spec(spec.model_dump(exclude_none=True), field=field))
    except InvalidInputError as exc:
        sub = exc.field.split(".", 1)[1] if exc.field.startswith("camera.") else None
        raise InvalidInputError(f"{field}.{sub}" if sub else field, exc.message) from exc
    mount = spec.mounting_quaternion
    return CameraEntry(cam, None if mount is None else unit_quaternion(mount, f"{field}.mounting_quaternion"))


def resolve_camera(value: CameraSpec | str, field: str, named: Mapping[str, CameraEntry]) -> CameraEntry:
    """An inline spec, or the name of a configured camera."""
    if isinstance(value, CameraSpec):
        return camera_entry(value, field)
    if value not in named:
        known = ", ".join(sorted(named)) or "none configured"
        raise InvalidInputError(field, f"unknown camera {value[:64]!r} (configured: {known})")
    return named[value]


def parse_camera_field(text: str, field: str, named: Mapping[str, CameraEntry]) -> CameraEntry:
    """A form/query value: a JSON camera object, or a configured camera's name."""
    if text.lstrip().startswith("{"):
        try:
            spec = CameraSpec.model_validate(json.loads(text))
        except (ValueError, ValidationError) as exc:
            raise InvalidInputError(field, f"not a valid camera JSON object: {_first(exc)}") from exc
        return camera_entry(spec, field)
    return resolve_camera(text, field, named)


def centroids(rows: Sequence[Sequence[float]], field: str, limit: int) -> Centroids:
    """Centroid rows, at most ``limit`` of them."""
    if len(rows) > limit:
        raise InvalidInputError(field, f"{len(rows)} centroids, this server takes at most {limit}")
    return Centroids.from_list(rows, field_name=field)


def hint(h: AttitudeHint | None) -> Hint | None:
    return None if h is None else (unit_quaternion(h.quaternion, "attitude_hint.quaternion"), h.radius_deg)


def check_method(db: NavDb, name: str) -> None:
    """Raise ``UnknownMethodError`` (422, field ``method``) before any work is queued."""
    if name == "auto":
        return
    get_method(name)  # registered at all?
    held = db.any_methods if isinstance(db, NavDatabaseSet) else db.methods
    if name not in held:
        raise UnknownMethodError(name, ["auto", *held])


def frame_call(req: SolveRequest, db: NavDb, named: Mapping[str, CameraEntry], *,
               max_centroids: int, options: SolveOptions, track_hint: Hint | None = None) -> SolveCall:
    """The engine call for one request: a single camera, or a rig (``cameras``)."""
    check_method(db, req.method)
    prior = hint(req.attitude_hint) or track_hint
    if req.centroid_sigma_px is not None:
        options = replace(options, centroid_sigma_px=req.centroid_sigma_px)
    if req.fov_max_error_deg is not None:
        options = replace(options, fov_max_error_deg=req.fov_max_error_deg)
    if req.epoch is not None or req.observer_velocity_km_s is not None:
        velocity = req.observer_velocity_km_s
        options = replace(options, epoch=req.epoch,
                          observer_velocity_km_s=None if velocity is None else tuple(velocity))
    options = interned(options)
    if req.cameras is None:
        assert req.camera is not None and req.centroids is not None
        cam = resolve_camera(req.camera, "camera", named)
        cents = centroids(req.centroids, "centroids", max_centroids)
        return partial(pipeline.solve, cents, cam.camera, db, method=req.method, hint=prior, options=options)
    frames = []
    for i, frame in enumerate(req.cameras):
        entry = resolve_camera(frame.camera, f"cameras.{i}.camera", named)
        cents = centroids(frame.centroids, f"cameras.{i}.centroids", max_centroids)
        frames.append((cents, entry.camera, entry.mounting))
    return partial(pipeline.solve_rig, frames, db, method=req.method, hint=prior, options=options)


def image_camera(camera: CameraSpec | str | None, fov_deg: float | None, shape: tuple[int, ...],
                 named: Mapping[str, CameraEntry]) -> Camera:
    """Camera of an image: ``camera`` (a spec, JSON text or a name), or ``fov_deg`` + the image size."""
    height, width = int(shape[0]), int(shape[1])
    if camera is not None:
        entry = camera_entry(camera, "camera") if isinstance(camera, CameraSpec) else \
            parse_camera_field(camera, "camera", named)
        cam = entry.camera
        if (cam.width, cam.height) != (width, height):
            raise InvalidInputError("camera.width", f"camera is {cam.width}x{cam.height} px, "
                                                    f"the image {width}x{height}")
        return cam
    if fov_deg is None:
        raise InvalidInputError("camera", "give camera (JSON or a configured name) or fov_deg")
    if not 0 < fov_deg < 170:
        raise InvalidInputError("fov_deg", "field of view must be in (0, 170) degrees")
    return Camera.from_fov(fov_deg, width, height)


def _first(exc: Exception) -> str:
    if isinstance(exc, ValidationError) and exc.errors():
        e = exc.errors()[0]
        return f"{'.'.join(str(p) for p in e['loc'])}: {e['msg']}" if e["loc"] else str(e["msg"])
    return str(exc)
