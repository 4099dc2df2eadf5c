"""`Stream` and `AsyncStream`: frame-by-frame solving over the ``/v1/stream`` WebSocket.

The protocol (service/api/routes/stream.py): a text message is a `SolveRequest` as JSON, a
binary message is an image (solved with the connection's camera, given here as query
parameters); the server answers every message, in order, with a `SolveResult` or a
`StreamError` (``{"id", "code", "detail", "field"}``), and the stream goes on.

Resuming after a dropped connection: the stream keeps every frame it has sent and not yet
had answered (its *unacknowledged* queue, in send order). When the connection drops, it
reconnects with the retry policy's backoff and resends exactly those frames, in order;
answered frames are never sent again. Answers are matched to frames by their position on
their connection (the server answers in order) and checked against the frame's id; each
frame is delivered at most once, so an answer that arrives twice (read from the old
connection after the frame was resent on the new one) is dropped. Ids are compared by their
string form (``3`` and ``"3"`` are the same frame); frames without an id get a sequence number.
"""

from __future__ import annotations

import asyncio
import inspect
import json
import os
import time
from collections import OrderedDict, deque
from collections.abc import Iterator, Mapping
from pathlib import Path
from typing import Any
from urllib.parse import urlencode

import pydantic
from websockets.asyncio.client import ClientConnection as AsyncConnection
from websockets.asyncio.client import connect as async_connect
from websockets.exceptions import ConnectionClosed, InvalidHandshake, InvalidStatus, InvalidURI
from websockets.sync.client import ClientConnection as SyncConnection
from websockets.sync.client import connect as sync_connect

from ._client import API_KEY_HEADER, USER_AGENT
from ._config import DEFAULT_TIMEOUT_S, Retry, as_retry
from ._exceptions import (
    SkyfixClientError,
    SkyfixFrameError,
    SkyfixHTTPError,
    SkyfixProtocolError,
    SkyfixStreamError,
    SkyfixTimeoutError,
)
from .models import CameraSpec, FrameId, SolveRequest, SolveResult

__all__ = ["AsyncStream", "Stream"]

MAX_MESSAGE_BYTES = 16 * 1024 * 1024
_DELIVERED_MEMORY = 65_536  # ids remembered for de-duplication
# Close codes after which reconnecting cannot help: the server refused us or our data.
_FATAL_CLOSE = {1002, 1003, 1007, 1008, 1009, 1010}
_CONNECT_ERRORS = (OSError, TimeoutError, InvalidHandshake, InvalidURI)

# websockets >= 17.1 wants ``legacy=True`` for a sync connection managed outside a ``with`` block.
_SYNC_LEGACY: dict[str, Any] = (
    {"legacy": True} if "legacy" in inspect.signature(sync_connect).parameters else {}
)

FrameLike = SolveRequest | Mapping[str, Any]
ImageLike = bytes | str | os.PathLike[str]


def _key(frame_id: Any) -> str:
    return str(frame_id)


class _StreamState:
    """The unacknowledged queue, the per-connection order of messages, and the memory of
    answered ids; shared by both streams. ``gen`` numbers the connections."""

    def __init__(self) -> None:
        self.pending: OrderedDict[str, tuple[FrameId, str | bytes]] = OrderedDict()
        self.delivered: OrderedDict[str, None] = OrderedDict()
        self.inflight: dict[int, deque[str]] = {}
        self.duplicates = 0
        self.unexpected = 0
        self.resent = 0
        self._next_id = 0

    def new_id(self) -> int:
        while True:
            self._next_id += 1
            key = _key(self._next_id)
            if key not in self.pending and key not in self.delivered:
                return self._next_id

    def prepare(self, frame: FrameLike) -> tuple[str, FrameId, str]:
        """Register a centroid frame as unacknowledged: its key, id (assigned if missing), JSON."""
        request = frame if isinstance(frame, SolveRequest) else SolveRequest.model_validate(dict(frame))
        if request.id is None:
            request = request.model_copy(update={"id": self.new_id()})
        payload = request.model_dump_json(exclude_none=True)
        return self._register(request.id, payload), request.id, payload

    def prepare_image(self, data: bytes, frame_id: FrameId) -> tuple[str, FrameId]:
        """Register an image frame (binary message; the id stays on this side)."""
        if frame_id is None:
            frame_id = self.new_id()
        return self._register(frame_id, data), frame_id

    def _register(self, frame_id: FrameId, payload: str | bytes) -> str:
        key = _key(frame_id)
        if key in self.pending:
            raise ValueError(f"frame id {frame_id!r} is already awaiting an answer")
        self.pending[key] = (frame_id, payload)
        self.delivered.pop(key, None)  # an id may be reused once answered
        return key

    def sent(self, gen: int, key: str) -> None:
        self.inflight.setdefault(gen, deque()).append(key)

    def reconnected(self, gen: int) -> list[tuple[str, str | bytes]]:
        """Forget connections older than the previous one; the frames to resend on ``gen``."""
        for old in [g for g in self.inflight if g < gen - 1]:
            del self.inflight[old]
        self.inflight[gen] = deque()
        return [(key, payload) for key, (_, payload) in self.pending.items()]

    def unacknowledged(self) -> list[FrameId]:
        return [frame_id for frame_id, _ in self.pending.values()]

    def take(self, gen: int, text: str | bytes) -> SolveResult | SkyfixFrameError | None:
        """Acknowledge the frame an answer on connection ``gen`` is for; None for a duplicate."""
        try:
            body = json.loads(text)
        except (json.JSONDecodeError, UnicodeDecodeError) as exc:
            raise SkyfixProtocolError(f"stream: not JSON: {str(text)[:200]!r}") from exc
        if not isinstance(body, dict):
            raise SkyfixProtocolError(f"stream: expected a JSON object, got {str(text)[:200]!r}")
        queue = self.inflight.get(gen)
        if not queue:
            self.unexpected += 1
            return None
        key = queue.popleft()
        if key not in self.pending:  # answered already, on another connection
            self.duplicates += 1
            return None
        frame_id, payload = self.pending[key]
        echoed = body.get("id")
        if isinstance(payload, str) and echoed is not None and _key(echoed) != key:
            raise SkyfixProtocolError(f"stream: answer for frame {echoed!r} where {frame_id!r} was due")
        del self.pending[key]
        self.delivered[key] = None
        while len(self.delivered) > _DELIVERED_MEMORY:
            self.delivered.popitem(last=False)
        if body.get("status") in ("solved", "no_solution"):
            try:
                result = SolveResult.model_validate(body)
            except pydantic.ValidationError as exc:
                raise SkyfixProtocolError(f"stream: not a SolveResult: {exc}") from exc
            result.id = frame_id
            return result
        if "detail" in body:
            code = body.get("code")
            field = body.get("field")
            return SkyfixFrameError(frame_id, str(body["detail"]), field if isinstance(field, str) else None,
                                    code if isinstance(code, int) else None)
        raise SkyfixProtocolError(f"stream: unexpected message {str(text)[:200]!r}")


def _handshake_error(exc: InvalidStatus) -> SkyfixHTTPError:
    response = exc.response
    detail = response.reason_phrase or "handshake refused"
    field = None
    try:
        body = json.loads(response.body or b"")
        if isinstance(body, dict) and isinstance(body.get("detail"), str):
            detail = body["detail"]
            field = body.get("field") if isinstance(body.get("field"), str) else None
    except (json.JSONDecodeError, UnicodeDecodeError):
        pass
    return SkyfixHTTPError(response.status_code, detail, field)


def _read_image(image: ImageLike) -> bytes:
    return bytes(image) if isinstance(image, bytes | bytearray | memoryview) else Path(image).read_bytes()


class _StreamBase:
    def __init__(self, url: str, *, api_key: str | None, timeout: float | None, retries: Retry | int | None,
                 headers: Mapping[str, str] | None, max_size: int, track: bool,
                 camera: CameraSpec | Mapping[str, Any] | str | None, fov_deg: float | None,
                 method: str | None) -> None:
        query: dict[str, str] = {}
        if track:
            query["track"] = "true"
        if camera is not None:
            query["camera"] = camera if isinstance(camera, str) else (
                CameraSpec.model_validate(dict(camera)) if not isinstance(camera, CameraSpec) else camera
            ).model_dump_json(exclude_none=True)
        if fov_deg is not None:
            query["fov_deg"] = repr(float(fov_deg))
        if method is not None:
            query["method"] = method
        sep = "&" if "?" in url else "?"
        self.url = url + (sep + urlencode(query) if query else "")
        self.timeout = timeout
        self.retry = as_retry(retries)
        self.max_size = max_size
        self.reconnects = 0
        self._headers = dict(headers or {})
        if api_key:
            self._headers[API_KEY_HEADER] = api_key
        self._state = _StreamState()
        self._gen = 0

    @property
    def unacknowledged(self) -> list[FrameId]:
        """Ids of the frames sent and not yet answered, in send order."""
        return self._state.unacknowledged()

    @property
    def duplicates_dropped(self) -> int:
        """Answers dropped because their frame had already been answered."""
        return self._state.duplicates

    @property
    def frames_resent(self) -> int:
        """Frames sent again after a reconnect."""
        return self._state.resent

    def _connect_kwargs(self) -> dict[str, Any]:
        return {"additional_headers": self._headers, "user_agent_header": USER_AGENT,
                "open_timeout": self.timeout, "max_size": self.max_size, "proxy": None}

    def _retry_connect(self, failures: int, exc: Exception) -> float:
        """Wait before reconnect attempt ``failures + 1``; raise when retrying cannot help."""
        if isinstance(exc, InvalidStatus):
            err = _handshake_error(exc)
            if err.status not in self.retry.statuses:
                raise err from exc
        elif isinstance(exc, InvalidURI):
            raise SkyfixStreamError(f"{self.url}: {exc}") from exc
        if failures >= self.retry.attempts:
            raise SkyfixStreamError(
                f"{self.url}: could not (re)connect after {failures} attempts: {type(exc).__name__}: {exc}",
                self.unacknowledged,
            ) from exc
        return self.retry.delay_s(failures)

    def _check_close(self, exc: ConnectionClosed) -> None:
        rcvd = exc.rcvd
        if rcvd is not None and (rcvd.code in _FATAL_CLOSE or 4000 <= rcvd.code < 5000):
            raise SkyfixStreamError(f"{self.url}: server closed the stream: {rcvd.code} {rcvd.reason}",
                                    self.unacknowledged) from exc


class Stream(_StreamBase):
    """A blocking WebSocket stream of frames, resumed transparently after a dropped connection.

    ```python
    with Client(url).stream(track=True) as stream:
        for frame in frames:                                     # pipelined: send ahead ...
            stream.send({"id": frame.id, "camera": cam, "centroids": frame.centroids})
        for result in stream.results():                          # ... every frame answered once
            print(result.id, result.status)
    ```

    ``recv`` raises `SkyfixFrameError` for a frame the server refused (the stream stays
    usable), `SkyfixStreamError` when the connection cannot be resumed within the retry
    policy, and `SkyfixHTTPError` when the server refuses the connection (e.g. 403, wrong key).

    **Parameters:**

    * **url** - ``ws://host:port/v1/stream`` (`Client.stream` builds it).
    * **api_key**, **headers** - sent with every (re)connection.
    * **timeout** - seconds to connect, and to wait for an answer in `recv`.
    * **retries** - `Retry` policy (or number of retries) for connecting and reconnecting.
    * **track** - the server uses each solution as the attitude hint of the next frame.
    * **camera**, **fov_deg**, **method** - the connection's defaults (image frames need a camera
      or a FOV).
    * **max_size** - largest message accepted, bytes.
    """

    def __init__(self, url: str, *, api_key: str | None = None, timeout: float | None = DEFAULT_TIMEOUT_S,
                 retries: Retry | int | None = None, headers: Mapping[str, str] | None = None,
                 max_size: int = MAX_MESSAGE_BYTES, track: bool = False,
                 camera: CameraSpec | Mapping[str, Any] | str | None = None, fov_deg: float | None = None,
                 method: str | None = None) -> None:
        super().__init__(url, api_key=api_key, timeout=timeout, retries=retries, headers=headers,
                         max_size=max_size, track=track, camera=camera, fov_deg=fov_deg, method=method)
        self._ws: SyncConnection | None = None

    def __enter__(self) -> Stream:
        return self.connect()

    def __exit__(self, *exc_info: object) -> None:
        self.close()

    def connect(self) -> Stream:
        """Open the connection (retrying transient failures) if it is not open; returns ``self``."""
        if self._ws is not None:
            return self
        failures = 0
        while True:
            try:
                self._ws = sync_connect(self.url, **_SYNC_LEGACY, **self._connect_kwargs())
                self._gen += 1
                self._state.inflight[self._gen] = deque()
                return self
            except _CONNECT_ERRORS as exc:
                failures += 1
                time.sleep(self._retry_connect(failures, exc))

    def close(self) -> None:
        """Close the connection; unacknowledged frames stay queued for a later `connect`."""
        if self._ws is not None:
            self._ws.close()
            self._ws = None

    def _resume(self) -> None:
        self.close()
        while True:
            self.reconnects += 1
            self.connect()
            assert self._ws is not None
            try:
                for key, payload in self._state.reconnected(self._gen):
                    self._state.sent(self._gen, key)
                    self._ws.send(payload)
                    self._state.resent += 1
                return
            except ConnectionClosed as exc:
                self._check_close(exc)
                self.close()

    def _transmit(self, key: str, payload: str | bytes) -> None:
        self.connect()
        assert self._ws is not None
        try:
            self._state.sent(self._gen, key)  # before sending: the answer may come at once
            self._ws.send(payload)
        except ConnectionClosed as exc:
            self._check_close(exc)
            self._resume()  # resends this frame too: it is unacknowledged

    def send(self, frame: FrameLike) -> FrameId:
        """Send a centroid frame (a `SolveRequest` or its dict); returns its id."""
        key, frame_id, payload = self._state.prepare(frame)
        self._transmit(key, payload)
        return frame_id

    def send_image(self, image: ImageLike, *, id: FrameId = None) -> FrameId:
        """Send an image (bytes or a path) as a binary frame; returns its id."""
        key, frame_id = self._state.prepare_image(_read_image(image), id)
        self._transmit(key, self._state.pending[key][1])
        return frame_id

    def recv(self, timeout: float | None = None) -> SolveResult:
        """The next answer. ``timeout`` (default: the stream's) bounds the wait for a message."""
        wait = self.timeout if timeout is None else timeout
        while True:
            if not self._state.pending:
                raise SkyfixStreamError("no frame is awaiting an answer")
            if self._ws is None:
                self._resume()
            assert self._ws is not None
            gen = self._gen
            try:
                text = self._ws.recv(timeout=wait)
            except TimeoutError as exc:
                raise SkyfixTimeoutError(f"{self.url}: no answer within {wait} s") from exc
            except ConnectionClosed as exc:
                self._check_close(exc)
                self._resume()
                continue
            out = self._state.take(gen, text)
            if isinstance(out, SkyfixFrameError):
                raise out
            if out is not None:
                return out

    def results(self) -> Iterator[SolveResult]:
        """The answers until no frame is awaiting one (a refused frame raises `SkyfixFrameError`)."""
        while self._state.pending:
            yield self.recv()

    def solve(self, frame: FrameLike) -> SolveResult:
        """Send one frame and wait for its answer (only when nothing else is in flight)."""
        if self._state.pending:
            raise SkyfixClientError("solve() needs an idle stream; use send()/recv() to pipeline")
        self.send(frame)
        return self.recv()


class AsyncStream(_StreamBase):
    """The `Stream` API for asyncio; ``send`` and ``recv`` may run in different tasks.

    ```python
    async with AsyncClient(url).stream() as stream:
        await stream.send(request)
        result = await stream.recv()
    ```
    """

    def __init__(self, url: str, *, api_key: str | None = None, timeout: float | None = DEFAULT_TIMEOUT_S,
                 retries: Retry | int | None = None, headers: Mapping[str, str] | None = None,
                 max_size: int = MAX_MESSAGE_BYTES, track: bool = False,
                 camera: CameraSpec | Mapping[str, Any] | str | None = None, fov_deg: float | None = None,
                 method: str | None = None) -> None:
        super().__init__(url, api_key=api_key, timeout=timeout, retries=retries, headers=headers,
                         max_size=max_size, track=track, camera=camera, fov_deg=fov_deg, method=method)
        self._ws: AsyncConnection | None = None
        self._lock = asyncio.Lock()
        self._has_pending = asyncio.Event()

    async def __aenter__(self) -> AsyncStream:
        return await self.connect()

    async def __aexit__(self, *exc_info: object) -> None:
        await self.aclose()

    async def _open(self) -> AsyncConnection:
        failures = 0
        while True:
            try:
                ws = await async_connect(self.url, **self._connect_kwargs())
                self._gen += 1
                self._state.inflight[self._gen] = deque()
                return ws
            except _CONNECT_ERRORS as exc:
                failures += 1
                await asyncio.sleep(self._retry_connect(failures, exc))

    async def connect(self) -> AsyncStream:
        """Open the connection (retrying transient failures) if it is not open; returns ``self``."""
        async with self._lock:
            if self._ws is None:
                self._ws = await self._open()
        return self

    async def aclose(self) -> None:
        """Close the connection; unacknowledged frames stay queued for a later `connect`."""
        ws, self._ws = self._ws, None
        if ws is not None:
            await ws.close()

    async def _resume(self, broken: AsyncConnection | None) -> None:
        """Replace ``broken`` by a new connection and resend the unacknowledged frames, unless
        another task already did."""
        async with self._lock:
            while self._ws is broken:
                if broken is not None:
                    await broken.close()
                self.reconnects += 1
                ws = await self._open()
                self._ws = ws
                try:
                    for key, payload in self._state.reconnected(self._gen):
                        self._state.sent(self._gen, key)
                        await ws.send(payload)
                        self._state.resent += 1
                except ConnectionClosed as exc:
                    self._check_close(exc)
                    broken = ws

    async def _transmit(self, key: str, payload: str | bytes) -> None:
        if self._ws is None:
            await self.connect()
        async with self._lock:
            self._has_pending.set()
            ws = self._ws
            assert ws is not None
            try:
                self._state.sent(self._gen, key)  # before sending: the answer may come at once
                await ws.send(payload)
                return
            except ConnectionClosed as exc:
                self._check_close(exc)
        await self._resume(ws)  # resends this frame too

    async def send(self, frame: FrameLike) -> FrameId:
        """Send a centroid frame; returns its id (assigned if missing)."""
        key, frame_id, payload = self._state.prepare(frame)
        await self._transmit(key, payload)
        return frame_id

    async def send_image(self, image: ImageLike, *, id: FrameId = None) -> FrameId:
        """Send an image (bytes or a path) as a binary frame; returns its id."""
        key, frame_id = self._state.prepare_image(_read_image(image), id)
        await self._transmit(key, self._state.pending[key][1])
        return frame_id

    async def recv(self, timeout: float | None = None) -> SolveResult:
        """The next answer; waits for a frame to be sent if none is awaiting an answer."""
        wait = self.timeout if timeout is None else timeout
        while True:
            if not self._state.pending:
                self._has_pending.clear()
                await self._has_pending.wait()
                continue
            ws, gen = self._ws, self._gen
            if ws is None:
                await self._resume(None)
                continue
            try:
                text = await asyncio.wait_for(ws.recv(), wait)
            except TimeoutError as exc:
                raise SkyfixTimeoutError(f"{self.url}: no answer within {wait} s") from exc
            except ConnectionClosed as exc:
                self._check_close(exc)
                await self._resume(ws)
                continue
            out = self._state.take(gen, text)
            if isinstance(out, SkyfixFrameError):
                raise out
            if out is not None:
                return out

    async def solve(self, frame: FrameLike) -> SolveResult:
        """Send one frame and wait for its answer (only when nothing else is in flight)."""
        if self._state.pending:
            raise SkyfixClientError("solve() needs an idle stream; use send()/recv() to pipeline")
        await self.send(frame)
        return await self.recv()
