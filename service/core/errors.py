"""Exceptions of the skyfix engine.

Expected failure (no stars identified) is data: ``SolveStatus.NO_SOLUTION``. Exceptions are
for misuse and for corrupt files::

    SkyfixError
    ├── InvalidInputError        bad centroids, camera, image or option (names the field)
    │   └── ImageDecodeError     bytes that are not a supported, intact image
    ├── UnknownMethodError       a method name the registry does not know
    └── DatabaseError            the navigation database cannot be used
        ├── DatabaseMissingError     no database at that path
        └── DatabaseCorruptError     wrong schema, truncated file, wrong shape or hash
"""

from __future__ import annotations


class SkyfixError(Exception):
    """Root of every error skyfix raises on purpose."""


class InvalidInputError(SkyfixError, ValueError):
    """An input is malformed; ``field`` names the offending field (dotted path)."""

    def __init__(self, field: str, message: str) -> None:
        super().__init__(f"{field}: {message}")
        self.field = field
        self.message = message

    def __reduce__(self) -> tuple[type, tuple[str, str]]:  # picklable: batch workers send it back
        return (type(self), (self.field, self.message))


class ImageDecodeError(InvalidInputError):
    """The bytes are not an image skyfix can decode (corrupt or unsupported format)."""


class UnknownMethodError(SkyfixError, KeyError):
    """A method name that is not registered."""

    def __init__(self, name: str, known: list[str]) -> None:
        super().__init__(name)
        self.name = name
        self.known = known

    def __reduce__(self) -> tuple[type, tuple[str, list[str]]]:  # picklable: batch workers send it back
        return (type(self), (self.name, self.known))

    def __str__(self) -> str:
        return f"unknown method {self.name!r}; known: {', '.join(self.known)}"


class DatabaseError(SkyfixError):
    """The navigation database cannot be used."""


class DatabaseMissingError(DatabaseError, FileNotFoundError):
    """No navigation database at the given path."""


class DatabaseCorruptError(DatabaseError):
    """The database exists but fails a schema, size, shape or hash check."""
