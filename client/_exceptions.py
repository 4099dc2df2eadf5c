"""Exceptions raised by the skyfix client.

Everything the client raises on purpose derives from one root:

```
SkyfixClientError
├── SkyfixTransportError      no usable answer from the server (after any retries)
│   ├── SkyfixConnectError    could not connect, or the connection dropped mid-request
│   └── SkyfixTimeoutError    the server did not answer in time
├── SkyfixHTTPError           the server answered 4xx/5xx: .status, .detail, .field
├── SkyfixFrameError          the server refused one streamed frame: .frame_id, .detail, .field
├── SkyfixStreamError         the WebSocket stream broke and could not be resumed
├── SkyfixProtocolError       the server answered something that is not skyfix JSON
└── RecordingError            a recording file is malformed or names a file outside its directory
```

"No solution" is not an exception: it is ``SolveResult.status == "no_solution"``.
"""

from __future__ import annotations

from typing import Any

__all__ = [
    "RecordingError",
    "SkyfixClientError",
    "SkyfixConnectError",
    "SkyfixFrameError",
    "SkyfixHTTPError",
    "SkyfixProtocolError",
    "SkyfixStreamError",
    "SkyfixTimeoutError",
    "SkyfixTransportError",
]


class SkyfixClientError(Exception):
    """Root of every exception the skyfix client raises."""


class SkyfixTransportError(SkyfixClientError):
    """No usable answer from the server (connection refused, dropped, or timed out)."""


class SkyfixConnectError(SkyfixTransportError):
    """Could not connect to the server, or it closed the connection before answering."""


class SkyfixTimeoutError(SkyfixTransportError):
    """The server did not answer within the timeout."""


class SkyfixHTTPError(SkyfixClientError):
    """The server answered with an error status.

    **Attributes:** `status` (HTTP status code), `detail` (the server's message),
    `field` (the request field at fault, when the server names one).
    """

    def __init__(self, status: int, detail: str, field: str | None = None) -> None:
        self.status = status
        self.detail = detail
        self.field = field
        where = f" (field {field!r})" if field else ""
        super().__init__(f"HTTP {status}: {detail}{where}")

    def __repr__(self) -> str:
        return f"{type(self).__name__}(status={self.status!r}, detail={self.detail!r}, field={self.field!r})"

    def __reduce__(self) -> tuple[Any, ...]:
        return (type(self), (self.status, self.detail, self.field))


class SkyfixFrameError(SkyfixClientError):
    """The server refused one frame sent over the stream; the stream itself stays usable.

    **Attributes:** `frame_id`, `detail`, `field`, `status` (an HTTP-like code when the
    server gives one).
    """

    def __init__(self, frame_id: Any, detail: str, field: str | None = None,
                 status: int | None = None) -> None:
        self.frame_id = frame_id
        self.detail = detail
        self.field = field
        self.status = status
        where = f" (field {field!r})" if field else ""
        super().__init__(f"frame {frame_id!r} refused: {detail}{where}")

    def __repr__(self) -> str:
        return (
            f"{type(self).__name__}(frame_id={self.frame_id!r}, detail={self.detail!r}, "
            f"field={self.field!r}, status={self.status!r})"
        )

    def __reduce__(self) -> tuple[Any, ...]:
        return (type(self), (self.frame_id, self.detail, self.field, self.status))


class SkyfixStreamError(SkyfixClientError):
    """The WebSocket stream failed and could not be resumed (or was refused outright).

    **Attributes:** `unacknowledged`: ids of the frames sent but never answered.
    """

    def __init__(self, message: str, unacknowledged: list[Any] | None = None) -> None:
        self.unacknowledged = list(unacknowledged or [])
        super().__init__(message)

    def __reduce__(self) -> tuple[Any, ...]:
        return (type(self), (self.args[0], self.unacknowledged))


class SkyfixProtocolError(SkyfixClientError):
    """The server's answer is not the JSON skyfix speaks (wrong server, or a proxy page)."""


class RecordingError(SkyfixClientError, ValueError):
    """A recording is malformed, or one of its frames names a file outside its directory.

    **Attributes:** `path`, `line` (1-based, when the problem is on one line).
    """

    def __init__(self, message: str, *, path: str | None = None, line: int | None = None) -> None:
        self.path = path
        self.line = line
        where = f"{path}:{line}: " if path and line else (f"{path}: " if path else "")
        self.message = message
        super().__init__(f"{where}{message}")

    def __reduce__(self) -> tuple[Any, ...]:
        return (_rebuild_recording_error, (self.message, self.path, self.line))


def _rebuild_recording_error(message: str, path: str | None, line: int | None) -> RecordingError:
    return RecordingError(message, path=path, line=line)
