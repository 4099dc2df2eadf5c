"""A worker's connections: a limit on how many are served at once, and a graceful drain.

``Lifecycle`` (one per app, in ``app.state.lifecycle``) counts the HTTP requests and
WebSocket streams in progress. ``ConnectionLimit`` (ASGI middleware) refuses work past
``max_connections``: REST gets 503 with ``Retry-After``, a WebSocket handshake is accepted and
closed at once with 1013 (try again later) and a reason, so that clients see why; streams
already open are not touched. ``/v1/health`` and ``/metrics`` are never refused (operators
need them most when the server is full).

Drain (SIGTERM, or a rolling restart): ``DrainingServer`` (a ``uvicorn.Server``) does not
stop at once on the first SIGTERM/SIGINT. It stops accepting connections (the other workers
take them) and tells every ``Lifecycle`` to drain: each stream
stops reading, answers the frames it has read, and closes with 1001 (going away); new streams
are closed with 1001 at once; REST keeps being served. When no stream is left (or after
``drain_timeout_s``) uvicorn's own shutdown runs, which lets REST requests in flight finish.
A second SIGINT stops at once.
"""

from __future__ import annotations

import asyncio
import signal
import time
import weakref
from types import FrameType

import uvicorn
from starlette.responses import JSONResponse
from starlette.types import ASGIApp, Receive, Scope, Send

from .metrics import Metrics

EXEMPT_PATHS = frozenset({"/v1/health", "/metrics"})
ACCEPT_GRACE_S = 0.5
"""After a draining worker stops accepting, time for requests on connections it has just
accepted to arrive (uvicorn's shutdown closes connections that have sent no request yet)."""
CLOSE_GOING_AWAY = 1001
CLOSE_TRY_AGAIN_LATER = 1013
_LIVE: weakref.WeakSet[Lifecycle] = weakref.WeakSet()


class Lifecycle:
    """Open connections and the drain flag of one app (one worker)."""

    def __init__(self, max_connections: int) -> None:
        self.max_connections = max_connections
        self.active = 0
        self.streams = 0
        self.draining = False
        self._events: weakref.WeakKeyDictionary[asyncio.AbstractEventLoop, asyncio.Event] = (
            weakref.WeakKeyDictionary())
        _LIVE.add(self)

    def begin_drain(self) -> None:
        """Stop taking stream frames; runs on the event loop."""
        self.draining = True
        for event in self._events.values():
            event.set()

    async def wait_drain(self) -> None:
        """Return when the drain begins."""
        loop = asyncio.get_running_loop()
        event = self._events.get(loop)
        if event is None:
            event = self._events[loop] = asyncio.Event()
            if self.draining:
                event.set()
        await event.wait()


def drain_all() -> list[Lifecycle]:
    """Begin the drain of every app in this process; the apps."""
    apps = list(_LIVE)
    for lc in apps:
        lc.begin_drain()
    return apps


class ConnectionLimit:
    """ASGI middleware: count connections in ``lifecycle``, refuse those past its limit."""

    def __init__(self, app: ASGIApp, lifecycle: Lifecycle, metrics: Metrics) -> None:
        self.app = app
        self.lc = lifecycle
        self.metrics = metrics

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        kind = scope["type"]
        if kind not in ("http", "websocket") or scope["path"] in EXEMPT_PATHS:
            await self.app(scope, receive, send)
            return
        lc = self.lc
        full = lc.active >= lc.max_connections
        if kind == "websocket" and (full or lc.draining):
            code, reason = ((CLOSE_GOING_AWAY, "server is shutting down; reconnect") if lc.draining else
                            (CLOSE_TRY_AGAIN_LATER, f"server full: {lc.max_connections} connections; retry later"))
            self.metrics.rejected(kind, "draining" if lc.draining else "limit")
            await _refuse_websocket(receive, send, code, reason)
            return
        if full:
            self.metrics.rejected(kind, "limit")
            response = JSONResponse({"detail": f"server full: {lc.max_connections} connections in progress; "
                                     "retry later", "field": None}, status_code=503, headers={"Retry-After": "1"})
            await response(scope, receive, send)
            return
        lc.active += 1
        lc.streams += kind == "websocket"
        self.metrics.open_connections.inc()
        try:
            await self.app(scope, receive, send)
        finally:
            lc.active -= 1
            lc.streams -= kind == "websocket"
            self.metrics.open_connections.dec()


async def _refuse_websocket(receive: Receive, send: Send, code: int, reason: str) -> None:
    """Accept the handshake and close at once with ``code`` and ``reason`` (a bare refusal is a 403)."""
    if (await receive())["type"] != "websocket.connect":
        return
    await send({"type": "websocket.accept"})
    await send({"type": "websocket.close", "code": code, "reason": reason})


class DrainingServer(uvicorn.Server):
    """``uvicorn.Server`` whose first SIGTERM/SIGINT drains the streams before shutting down."""

    def __init__(self, config: uvicorn.Config, drain_timeout_s: float = 10.0) -> None:
        super().__init__(config)
        self.drain_timeout_s = drain_timeout_s
        self._drain_asked = False
        self._deadline: float | None = None
        self._grace_end = 0.0
        self._apps: list[Lifecycle] = []

    def handle_exit(self, sig: int, frame: FrameType | None) -> None:
        if self.should_exit or sig not in (signal.SIGTERM, signal.SIGINT):
            super().handle_exit(sig, frame)
            return
        if self._drain_asked:  # Ctrl+C reaches the workers and the supervisor, which then sends SIGTERM:
            if sig == signal.SIGINT:  # only a second SIGINT cuts the drain short
                super().handle_exit(sig, frame)
            return
        self._captured_signals.append(sig)  # re-raised after the shutdown, as uvicorn does
        self._drain_asked = True  # acted on in on_tick, on the event loop (not in the signal handler)

    async def on_tick(self, counter: int) -> bool:
        if self._drain_asked and not self.should_exit:
            now = time.monotonic()
            if self._deadline is None:
                self._deadline = now + self.drain_timeout_s
                self._grace_end = now + ACCEPT_GRACE_S
                for server in self.servers:  # stop accepting: other workers take new connections
                    server.close()
                self._apps = drain_all()
            streams_done = all(lc.streams == 0 for lc in self._apps)
            if (streams_done and now >= self._grace_end) or now > self._deadline:
                self.should_exit = True
        return await super().on_tick(counter)
