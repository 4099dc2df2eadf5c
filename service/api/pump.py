"""One WebSocket stream's message pump: bounded read-ahead, answers in order, graceful drain.

A reader task takes messages off the connection while the frame before is being solved, but
never more than ``max_in_flight`` messages that are not yet answered: when that many are
waiting it stops reading, uvicorn's small queue fills, and uvicorn stops reading the socket
(TCP back-pressure). Sending an answer waits while the client does not read (the transport's
write buffer is bounded), so a client that sends and never reads holds at most
``max_in_flight`` frames and one buffer of answers in the server, however much it sends.

Frames are answered one at a time, in order (a stream's frames may depend on each other:
tracking, config messages). When the worker drains (``Lifecycle.begin_drain``), the reader
stops, the frames already read are answered, and the stream is closed with 1001; the client
resends what was not answered on a new connection (the SDK's resume does).
"""

from __future__ import annotations

import json
import logging
import math
import time
from collections.abc import Awaitable, Callable

import anyio
from starlette.websockets import WebSocket, WebSocketDisconnect

from .lifecycle import CLOSE_GOING_AWAY, Lifecycle
from .logs import log_event

Handler = Callable[[str | None, bytes | None], Awaitable[str]]
DRAIN_REASON = "server is shutting down; reconnect and resend unanswered frames"
log = logging.getLogger("skyfix.access")


async def pump(ws: WebSocket, handle: Handler, *, max_in_flight: int, lifecycle: Lifecycle | None) -> None:
    """Serve ``ws`` until the client leaves or the worker drains; ``handle`` turns a message into its answer."""
    slots = anyio.Semaphore(max_in_flight)
    to_answer, queued = anyio.create_memory_object_stream[dict](math.inf)  # bounded by ``slots``
    reading = anyio.CancelScope()
    state = {"gone": False, "drained": False}
    request_id = getattr(ws.state, "request_id", None)

    async def read() -> None:
        async with to_answer:
            with reading:
                try:
                    while True:
                        await slots.acquire()
                        msg = await ws.receive()
                        if msg["type"] == "websocket.disconnect":
                            state["gone"] = True
                            return
                        to_answer.send_nowait(msg)  # no await: a drain cannot drop a message read
                except WebSocketDisconnect:
                    state["gone"] = True

    async def watch_drain() -> None:
        if lifecycle is not None:
            await lifecycle.wait_drain()
            state["drained"] = True
            reading.cancel()

    async with anyio.create_task_group() as tg:
        tg.start_soon(read)
        tg.start_soon(watch_drain)
        try:
            async with queued:
                async for msg in queued:
                    if state["gone"]:
                        break
                    t0 = time.perf_counter()
                    answer = await handle(msg.get("text"), msg.get("bytes"))
                    await ws.send_text(answer)
                    slots.release()
                    if log.isEnabledFor(logging.INFO):
                        _log_frame(request_id, msg, answer, time.perf_counter() - t0)
        except WebSocketDisconnect:
            state["gone"] = True
        tg.cancel_scope.cancel()
    if state["drained"] and not state["gone"]:
        try:
            await ws.close(CLOSE_GOING_AWAY, DRAIN_REASON)
        except (WebSocketDisconnect, RuntimeError, OSError):
            pass


def _log_frame(request_id: str | None, msg: dict, answer: str, seconds: float) -> None:
    try:
        body = json.loads(answer)
    except ValueError:
        body = {}
    kind = "image" if msg.get("bytes") is not None else "json"
    fields = {"event": "frame", "request_id": request_id, "kind": kind, "frame": body.get("id"),
              "status": body.get("status") or ("config" if "type" in body or "track" in body else "error"),
              "code": body.get("code"), "ms": round(seconds * 1e3, 3)}
    log_event({k: v for k, v in fields.items() if v is not None})
