"""Recorded frames: JSON Lines, one `RecordedFrame` a line (see docs/client.md).

```python
from client.recording import RecordingWriter, read_recording

with RecordingWriter("run.jsonl") as rec:
    rec.write({"id": 1, "time": "2026-01-01T00:00:00Z", "camera": cam, "centroids": rows})

for frame in read_recording("run.jsonl"):
    ...
```

An ``image`` is a path relative to the recording's directory. Reading refuses absolute paths
and paths that lead outside that directory (``..``, or a symlink pointing out), so replaying
a recording cannot be made to read or upload an arbitrary file.
"""

from __future__ import annotations

import os
from collections.abc import Iterator, Mapping
from pathlib import Path, PurePosixPath
from typing import IO, Any

import pydantic

from ._exceptions import RecordingError
from .models import RecordedFrame

__all__ = ["RecordingWriter", "read_recording", "resolve_image"]


def resolve_image(recording: str | os.PathLike[str], image: str) -> Path:
    """The absolute path of a frame's ``image``; raises `RecordingError` when it is absolute
    or escapes the recording's directory (after following symlinks)."""
    base = Path(recording).resolve().parent
    return _resolve_under(base, image, str(recording), None)


def _resolve_under(base: Path, image: str, where: str, line: int | None) -> Path:
    if not image or "\x00" in image:
        raise RecordingError("empty or invalid image path", path=where, line=line)
    posix = PurePosixPath(image.replace("\\", "/"))
    if posix.is_absolute() or Path(image).is_absolute() or Path(image).drive:
        raise RecordingError(f"image path {image!r} must be relative to the recording", path=where, line=line)
    resolved = (base / Path(*posix.parts)).resolve()
    if not resolved.is_relative_to(base):
        raise RecordingError(f"image path {image!r} leads outside the recording's directory",
                             path=where, line=line)
    return resolved


def read_recording(path: str | os.PathLike[str]) -> Iterator[RecordedFrame]:
    """Yield the frames of a JSON Lines recording, in file order.

    Blank lines and lines starting with ``#`` are skipped. Raises `RecordingError` (naming the
    line) for a line that is not a frame, for a frame with neither centroids, image nor
    cameras, and for an image path outside the recording's directory. The image itself is
    not opened here; `resolve_image` gives its absolute path.
    """
    where = str(path)
    base = Path(path).resolve().parent
    try:
        handle = open(path, encoding="utf-8")  # noqa: SIM115 - closed below
    except OSError as exc:
        raise RecordingError(f"cannot open: {exc.strerror or exc}", path=where) from exc
    with handle:
        for lineno, text in enumerate(handle, start=1):
            stripped = text.strip()
            if not stripped or stripped.startswith("#"):
                continue
            try:
                frame = RecordedFrame.model_validate_json(stripped)
            except pydantic.ValidationError as exc:
                first = exc.errors()[0]
                loc = ".".join(str(p) for p in first.get("loc", ()))
                raise RecordingError(f"{first['msg']}" + (f" at {loc}" if loc else ""),
                                     path=where, line=lineno) from exc
            _check_frame(frame, base, where, lineno)
            yield frame


def _check_frame(frame: RecordedFrame, base: Path, where: str, line: int) -> None:
    given = [frame.centroids is not None, frame.image is not None, frame.cameras is not None]
    if sum(given) != 1:
        raise RecordingError("a frame needs exactly one of centroids, image or cameras",
                             path=where, line=line)
    if frame.cameras is None and frame.camera is None and frame.image is None:
        raise RecordingError("a centroid frame needs a camera", path=where, line=line)
    rows = list(frame.centroids or []) + [r for cam in frame.cameras or [] for r in cam.centroids]
    if any(len(r) not in (2, 3) for r in rows):
        raise RecordingError("centroid rows are [x, y] or [x, y, flux]", path=where, line=line)
    if frame.image is not None:
        _resolve_under(base, frame.image, where, line)
    if frame.truth is not None and frame.truth.quaternion is not None:
        q = frame.truth.quaternion
        norm = sum(c * c for c in q) ** 0.5
        if len(q) != 4 or not 0.5 < norm < 1.5:
            raise RecordingError("truth.quaternion must be a unit [w, x, y, z]", path=where, line=line)


class RecordingWriter:
    """Write frames to a JSON Lines recording, one line per `write`, flushed as it goes.

    ``image`` paths must be relative to the recording's directory and stay inside it (the
    same rule `read_recording` enforces); `add_image` copies a file in and returns the
    relative path to put in the frame.

    **Parameters:** ``path``; ``append`` (add to an existing recording instead of
    replacing it).
    """

    def __init__(self, path: str | os.PathLike[str], *, append: bool = False) -> None:
        self.path = Path(path)
        self.count = 0
        self._base = self.path.resolve().parent
        self._base.mkdir(parents=True, exist_ok=True)
        self._handle: IO[str] | None = open(self.path, "a" if append else "w", encoding="utf-8")  # noqa: SIM115

    def __enter__(self) -> RecordingWriter:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()

    def close(self) -> None:
        if self._handle is not None:
            self._handle.close()
            self._handle = None

    def write(self, frame: RecordedFrame | Mapping[str, Any]) -> RecordedFrame:
        """Validate and append one frame; returns it as a `RecordedFrame`."""
        if self._handle is None:
            raise RecordingError("recording is closed", path=str(self.path))
        try:
            model = frame if isinstance(frame, RecordedFrame) else RecordedFrame.model_validate(dict(frame))
        except pydantic.ValidationError as exc:
            raise RecordingError(f"not a frame: {exc.errors()[0]['msg']}", path=str(self.path)) from exc
        _check_frame(model, self._base, str(self.path), self.count + 1)
        line = model.model_dump_json(exclude_none=True)
        self._handle.write(line + "\n")
        self._handle.flush()
        self.count += 1
        return model

    def add_image(self, source: str | os.PathLike[str], name: str | None = None, *,
                  subdir: str = "images") -> str:
        """Copy an image file next to the recording (under ``subdir``); the relative path."""
        src = Path(source)
        rel = PurePosixPath(subdir) / (name or src.name) if subdir else PurePosixPath(name or src.name)
        dest = _resolve_under(self._base, str(rel), str(self.path), None)
        dest.parent.mkdir(parents=True, exist_ok=True)
        dest.write_bytes(src.read_bytes())
        return str(rel)

