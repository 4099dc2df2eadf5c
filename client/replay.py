"""Replay a recording against a running server and score the answers against its truth.

```python
from client.replay import replay

report = replay("run.jsonl", url="http://127.0.0.1:8000", rate_hz=10, concurrency=4)
print(report.identification_rate, report.wrong, report.latency_ms.p95)
```

Frames go out in recording order, at a fixed rate (frame ``i`` is due at ``start + i/rate``)
or as fast as possible, with at most ``concurrency`` frames in flight: parallel requests over
REST, a window of pipelined frames over the WebSocket. A frame the server cannot answer
(connection lost after the retries, request refused) is reported as ``failed`` with the
error, and the replay carries on with the next one; over the WebSocket, a connection that
cannot be resumed fails the frames still unanswered.
"""

from __future__ import annotations

import asyncio
import os
import time
from collections.abc import Callable, Sequence
from datetime import UTC, datetime
from pathlib import Path
from typing import Any
from urllib.parse import urlencode

import httpx
import pydantic

from ._aem import AemRecord
from ._client import AsyncClient, ws_url
from ._config import DEFAULT_TIMEOUT_S, DEFAULT_URL, Retry
from ._exceptions import SkyfixClientError, SkyfixFrameError, SkyfixHTTPError
from ._report import FrameReport, ReplayReport, WrongBars, score_frame, summarize
from ._stream import AsyncStream
from ._time import parse_frame_time
from .models import FrameId, RecordedFrame, SolveRequest, SolveResult
from .recording import read_recording, resolve_image

__all__ = ["aem_records", "replay", "replay_frames"]

OnResult = Callable[[FrameReport], None]


def _wire_ids(frames: Sequence[RecordedFrame]) -> list[FrameId]:
    """The id each frame is sent with: its own when the recording's ids are unique (as strings),
    else its index."""
    ids = [f.id for f in frames]
    keys = [str(i) for i in ids]
    if None in ids or len(set(keys)) != len(keys):
        return list(range(len(frames)))
    return ids


def _request(frame: RecordedFrame, wire_id: FrameId, method: str) -> SolveRequest:
    if frame.cameras is not None:
        return SolveRequest(id=wire_id, cameras=frame.cameras, method=method)
    return SolveRequest(id=wire_id, camera=frame.camera, centroids=frame.centroids, method=method)


class _Run:
    """Book-keeping shared by the REST and WebSocket replays."""

    def __init__(self, frames: Sequence[RecordedFrame], bars: WrongBars, on_result: OnResult | None,
                 rate_hz: float | None) -> None:
        self.frames = frames
        self.bars = bars
        self.on_result = on_result
        self.rate_hz = rate_hz
        self.reports: list[FrameReport | None] = [None] * len(frames)
        self.epochs: list[datetime | None] = [None] * len(frames)
        self.started = time.perf_counter()

    async def due(self, index: int) -> None:
        if self.rate_hz:
            delay = self.started + index / self.rate_hz - time.perf_counter()
            if delay > 0:
                await asyncio.sleep(delay)

    def sent(self, index: int) -> None:
        frame_time = self.frames[index].time
        try:
            parsed = parse_frame_time(frame_time)
        except ValueError:
            parsed = None
        self.epochs[index] = parsed or datetime.now(UTC)

    def _epoch(self, index: int) -> str | None:
        t = self.epochs[index]
        return t.isoformat() if t is not None else None

    def done(self, index: int, result: SolveResult, latency_s: float) -> None:
        frame = self.frames[index]
        report = FrameReport(index=index, id=frame.id, status=result.status, latency_ms=latency_s * 1e3,
                             epoch=self._epoch(index), method=result.method, n_stars=len(result.stars),
                             quaternion=result.quaternion)
        score_frame(report, frame, result, self.bars)
        self._store(index, report)

    def failed(self, index: int, error: str, latency_s: float | None = None) -> None:
        if self.reports[index] is not None:
            return
        report = FrameReport(index=index, id=self.frames[index].id, status="failed", error=error,
                             epoch=self._epoch(index),
                             latency_ms=None if latency_s is None else latency_s * 1e3)
        self._store(index, report)

    def _store(self, index: int, report: FrameReport) -> None:
        self.reports[index] = report
        if self.on_result is not None:
            self.on_result(report)

    def finish(self, error: str) -> list[FrameReport]:
        for i, rep in enumerate(self.reports):
            if rep is None:
                self.failed(i, error)
        return [r for r in self.reports if r is not None]


def _describe(exc: BaseException) -> str:
    if isinstance(exc, pydantic.ValidationError):
        err = exc.errors()[0]
        loc = ".".join(str(p) for p in err.get("loc", ()))
        return f"invalid frame: {loc + ': ' if loc else ''}{err['msg']}"
    if isinstance(exc, SkyfixHTTPError):
        return f"HTTP {exc.status}: {exc.detail}" + (f" (field {exc.field})" if exc.field else "")
    return f"{type(exc).__name__}: {exc}"


async def _replay_rest(run: _Run, wire_ids: list[FrameId], recording: Path | None, *, url: str,
                       api_key: str | None, timeout: float | None, retries: Retry | int | None,
                       method: str, concurrency: int, transport: httpx.AsyncBaseTransport | None) -> int:
    sem = asyncio.Semaphore(concurrency)

    async def one(client: AsyncClient, index: int) -> None:
        frame = run.frames[index]
        t0 = time.perf_counter()
        try:
            if frame.image is not None:
                if recording is None:
                    raise SkyfixClientError("image frames need the recording's path")
                path = resolve_image(recording, frame.image)
                result = await client.solve_image(path, camera=frame.camera, id=wire_ids[index],
                                                  method=method)
            else:
                result = await client.solve(_request(frame, wire_ids[index], method))
        except (SkyfixClientError, OSError, ValueError) as exc:  # ValueError: a frame the API refuses
            run.failed(index, _describe(exc), time.perf_counter() - t0)
        else:
            run.done(index, result, time.perf_counter() - t0)
        finally:
            sem.release()

    async with AsyncClient(url, api_key=api_key, timeout=timeout, retries=retries, transport=transport,
                           max_connections=max(concurrency, 1)) as client:
        tasks = []
        for index in range(len(run.frames)):
            await run.due(index)
            await sem.acquire()
            run.sent(index)
            tasks.append(asyncio.create_task(one(client, index)))
        await asyncio.gather(*tasks)
    return 0


async def _replay_ws(run: _Run, wire_ids: list[FrameId], recording: Path | None, *, url: str,
                     api_key: str | None, timeout: float | None, retries: Retry | int | None, method: str,
                     concurrency: int, session: str | None = None) -> int:
    index_of = {str(w): i for i, w in enumerate(wire_ids)}
    window = asyncio.Semaphore(concurrency)
    sent_at: dict[int, float] = {}
    # Image frames are binary messages solved with the connection's camera: the first one's.
    image_camera = next((f.camera for f in run.frames if f.image is not None), None)
    query = "?" + urlencode({"session": session}) if session else ""  # publish to /ui/live viewers
    stream = AsyncStream(ws_url(url) + query, api_key=api_key, timeout=timeout, retries=retries, method=method,
                         camera=image_camera)
    requests: dict[int, SolveRequest] = {}
    unsendable: set[int] = set()
    for index, frame in enumerate(run.frames):
        if frame.image is not None:
            if recording is None or frame.camera != image_camera:
                run.failed(index, "over --ws, image frames must share one camera (the first image's)")
                unsendable.add(index)
            continue
        try:
            requests[index] = _request(frame, wire_ids[index], method)
        except ValueError as exc:
            run.failed(index, _describe(exc))
            unsendable.add(index)

    async def sender() -> None:
        for index, frame in enumerate(run.frames):
            if index in unsendable:
                continue
            await run.due(index)
            await window.acquire()
            run.sent(index)
            sent_at[index] = time.perf_counter()
            if frame.image is not None:
                assert recording is not None
                await stream.send_image(resolve_image(recording, frame.image), id=wire_ids[index])
            else:
                await stream.send(requests[index])

    async def receiver() -> None:
        received = 0
        while received + len(unsendable) < len(run.frames):
            try:
                result = await stream.recv()
            except SkyfixFrameError as exc:
                index = index_of.get(str(exc.frame_id))
                if index is not None:
                    run.failed(index, _describe(exc), time.perf_counter() - sent_at.get(index, run.started))
                received += 1
                window.release()
                continue
            index = index_of.get(str(result.id))
            if index is None:
                continue
            run.done(index, result, time.perf_counter() - sent_at[index])
            received += 1
            window.release()

    try:
        await stream.connect()
        send_task = asyncio.create_task(sender())
        recv_task = asyncio.create_task(receiver())
        done, _ = await asyncio.wait({send_task, recv_task}, return_when=asyncio.FIRST_EXCEPTION)
        for task in done:
            if task.exception() is not None:
                send_task.cancel()
                recv_task.cancel()
                await asyncio.gather(send_task, recv_task, return_exceptions=True)
                raise task.exception()  # type: ignore[misc]
        await asyncio.gather(send_task, recv_task)
    except SkyfixClientError as exc:
        run.finish(_describe(exc))
    finally:
        await stream.aclose()
    return stream.reconnects


async def replay_frames(
    frames: Sequence[RecordedFrame],
    *,
    url: str = DEFAULT_URL,
    recording: str | os.PathLike[str] | None = None,
    ws: bool = False,
    rate_hz: float | None = None,
    concurrency: int = 1,
    api_key: str | None = None,
    timeout: float | None = DEFAULT_TIMEOUT_S,
    retries: Retry | int | None = None,
    method: str = "auto",
    session: str | None = None,
    bars: WrongBars | None = None,
    on_result: OnResult | None = None,
    transport: httpx.AsyncBaseTransport | None = None,
) -> ReplayReport:
    """Replay ``frames`` against the server at ``url`` and score them; see the module docstring.

    ``recording`` is the file the frames came from (image paths are relative to it); ``session``
    (WebSocket only) names the stream session whose viewers see every frame (``/ui/live``);
    ``on_result`` is called with each frame's `FrameReport` as it completes; ``transport``
    (REST only) replaces the network, e.g. ``httpx.ASGITransport(app)``.
    """
    if concurrency < 1:
        raise ValueError("concurrency must be at least 1")
    if rate_hz is not None and rate_hz <= 0:
        raise ValueError("rate_hz must be positive (None = as fast as possible)")
    bars = bars or WrongBars()
    run = _Run(frames, bars, on_result, rate_hz)
    wire_ids = _wire_ids(frames)
    source = Path(recording) if recording else None
    try:
        if ws:
            reconnects = await _replay_ws(run, wire_ids, source, url=url, api_key=api_key, timeout=timeout,
                                          retries=retries, method=method, concurrency=concurrency,
                                          session=session)
        else:
            reconnects = await _replay_rest(run, wire_ids, source, url=url, api_key=api_key, timeout=timeout,
                                            retries=retries, method=method, concurrency=concurrency,
                                            transport=transport)
    finally:
        wall_s = time.perf_counter() - run.started
    per_frame = run.finish("not answered")
    return summarize(per_frame, wall_s=wall_s, bars=bars, recording=str(recording) if recording else None,
                     url=url, transport="ws" if ws else "rest", rate_hz=rate_hz, concurrency=concurrency,
                     reconnects=reconnects)


def replay(recording: str | os.PathLike[str], **options: Any) -> ReplayReport:
    """Read ``recording`` and `replay_frames` it (blocking); keyword options as there."""
    frames = list(read_recording(recording))
    return asyncio.run(replay_frames(frames, recording=recording, **options))


def aem_records(report: ReplayReport) -> list[AemRecord]:
    """The solved attitudes of a replay, with their frame times, for `write_aem`."""
    out = []
    for f in report.per_frame:
        if f.status == "solved" and f.quaternion is not None and f.epoch is not None:
            q = f.quaternion
            out.append(AemRecord(datetime.fromisoformat(f.epoch), (q[0], q[1], q[2], q[3])))
    return out
