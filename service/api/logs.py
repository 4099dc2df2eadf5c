"""Structured access logs: one JSON line per HTTP request and per stream frame, with a request id.

The id is the client's ``X-Request-ID`` when it is a plain token (1-128 characters of
``A-Za-z0-9._:-``), else a new random one; it is sent back in the ``X-Request-ID`` response
header (on a WebSocket, in the handshake response) and is on every line of that request or
stream. Lines go to the ``skyfix.access`` logger; ``skyfix serve`` writes them to stderr
(``configure``), at ``--log-level info`` or below.

A request's line: ``{"ts", "event": "request", "request_id", "method", "route", "status",
"ms", "client", "pid"}`` (``route`` is the route template, never the raw path). A stream
frame's: ``{"ts", "event": "frame", "request_id", "kind", "frame", "status", "ms", "pid"}``.
"""

from __future__ import annotations

import json
import logging
import os
import re
import sys
import time
import uuid
from typing import Any

from starlette.types import ASGIApp, Message, Receive, Scope, Send

HEADER = "x-request-id"
_TOKEN = re.compile(r"^[A-Za-z0-9._:\-]{1,128}$")
log = logging.getLogger("skyfix.access")


def log_event(fields: dict[str, Any]) -> None:
    """Write one JSON line (a ``ts`` and the worker's ``pid`` are added)."""
    log.info(json.dumps({"ts": round(time.time(), 3), **fields, "pid": os.getpid()}, separators=(",", ":")))


def configure(level: str | int = "info") -> None:
    """Send ``skyfix.access`` lines, bare, to stderr at ``level`` (a worker calls this at start)."""
    handler = logging.StreamHandler(sys.stderr)
    handler.setFormatter(logging.Formatter("%(message)s"))
    log.handlers[:] = [handler]
    named = logging.getLevelName(level.upper()) if isinstance(level, str) else level
    log.setLevel(named if isinstance(named, int) else logging.DEBUG)  # uvicorn's "trace": everything
    log.propagate = False


def request_id(scope: Scope) -> str:
    """The client's ``X-Request-ID`` if it is a plain token, else a new one."""
    for name, value in scope.get("headers", ()):
        if name == b"x-request-id":
            text = value.decode("latin-1")
            if _TOKEN.match(text):
                return text
            break
    return uuid.uuid4().hex


class RequestLog:
    """ASGI middleware: give each request or stream its id, echo it, and log each HTTP request."""

    def __init__(self, app: ASGIApp) -> None:
        self.app = app

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] not in ("http", "websocket"):
            await self.app(scope, receive, send)
            return
        rid = request_id(scope)
        scope.setdefault("state", {})["request_id"] = rid
        header = (HEADER.encode(), rid.encode())
        status = 500
        t0 = time.perf_counter()

        async def send_with_id(message: Message) -> None:
            nonlocal status
            if message["type"] in ("http.response.start", "websocket.accept"):
                message = {**message, "headers": [*message.get("headers", ()), header]}
                status = int(message.get("status", 101))
            await send(message)

        try:
            await self.app(scope, receive, send_with_id)
        finally:
            if log.isEnabledFor(logging.INFO):
                route = getattr(scope.get("route"), "path", None)
                fields = {"event": "request" if scope["type"] == "http" else "stream", "request_id": rid,
                          "method": scope.get("method", "WS"), "route": route if isinstance(route, str)
                          else "unmatched", "status": status, "ms": round((time.perf_counter() - t0) * 1e3, 3),
                          "client": (scope.get("client") or ("", 0))[0]}
                log_event(fields)
