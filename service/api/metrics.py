"""Prometheus metrics (``prometheus_client``), exact across ``--workers N``.

Under ``skyfix serve`` the supervisor sets ``PROMETHEUS_MULTIPROC_DIR`` to a fresh directory
before it starts the workers; each worker then writes its counters to memory-mapped files
there, and ``GET /metrics`` on any worker adds up all of them (``MultiProcessCollector``), the
counts of workers that have died or been replaced included. Without that variable (the
in-process test server) each ``Metrics`` has its own registry.

Series: ``skyfix_http_requests_total{route,method,status}``, ``skyfix_solves_total{method,
outcome,reason}``, ``skyfix_stream_messages_total{kind}``, ``skyfix_solve_seconds`` (histogram),
``skyfix_rejected_total{kind,reason}`` (connection limit, drain), ``skyfix_open_connections``.
"""

from __future__ import annotations

import os
import time
from typing import Any

from prometheus_client import CollectorRegistry, Counter, Gauge, Histogram, generate_latest
from prometheus_client.multiprocess import MultiProcessCollector
from starlette.types import ASGIApp, Message, Receive, Scope, Send

_METHODS = frozenset({"GET", "HEAD", "POST", "PUT", "PATCH", "DELETE", "OPTIONS"})
SOLVE_BUCKETS_S = (0.0005, 0.001, 0.002, 0.005, 0.01, 0.02, 0.05, 0.1, 0.2, 0.5, 1.0, 2.0, 5.0, 10.0)
CONTENT_TYPE = "text/plain; version=0.0.4; charset=utf-8"


def multiprocess_dir() -> str | None:
    """The shared directory of the workers' metric files, if in multiprocess mode."""
    return os.environ.get("PROMETHEUS_MULTIPROC_DIR") or None


class _KindCounter:
    """``ws_frames[kind] += 1`` on a labelled counter (reads give this process's count)."""

    def __init__(self, counter: Counter) -> None:
        self._counter = counter
        self._seen: dict[str, float] = {}

    def __getitem__(self, kind: str) -> float:
        return self._seen.get(kind, 0.0)

    def __setitem__(self, kind: str, value: float) -> None:
        self._counter.labels(kind=kind).inc(value - self._seen.get(kind, 0.0))
        self._seen[kind] = value


class Metrics:
    """Request counts by route and status, solve outcomes by reason, and a solve-latency histogram."""

    def __init__(self) -> None:
        self.started = time.time()
        self.registry = CollectorRegistry(auto_describe=True)
        r = self.registry
        self._requests = Counter("skyfix_http_requests", "HTTP requests by route template and status.",
                                 ("route", "method", "status"), registry=r)
        self._solves = Counter("skyfix_solves", "Solves by method used, outcome and reason.",
                               ("method", "outcome", "reason"), registry=r)
        self._frames = Counter("skyfix_stream_messages", "WebSocket messages by kind.", ("kind",), registry=r)
        self._seconds = Histogram("skyfix_solve_seconds", "Wall time of a solve, queueing in the thread pool "
                                  "included.", buckets=SOLVE_BUCKETS_S, registry=r)
        self._rejected = Counter("skyfix_rejected", "Connections refused: kind http|websocket, reason "
                                 "limit|draining.", ("kind", "reason"), registry=r)
        self.open_connections = Gauge("skyfix_open_connections", "HTTP requests and WebSocket streams in "
                                      "progress.", registry=r, multiprocess_mode="livesum")
        start = Gauge("skyfix_start_time_seconds", "Unix time the oldest live worker started.", registry=r,
                      multiprocess_mode="livemin")
        start.set(self.started)
        self.ws_frames = _KindCounter(self._frames)

    def request(self, route: str, method: str, status: int) -> None:
        self._requests.labels(route=route, method=method, status=str(status)).inc()

    def solve(self, method: str, outcome: str, seconds: float | None = None, reason: str | None = None) -> None:
        """Count one solve (``solved`` / ``no_solution`` / ``timeout``), why, and its wall time."""
        self._solves.labels(method=method, outcome=outcome, reason=reason or outcome).inc()
        if seconds is not None:
            self._seconds.observe(seconds)

    def rejected(self, kind: str, reason: str) -> None:
        self._rejected.labels(kind=kind, reason=reason).inc()

    def render(self) -> str:
        """The exposition text (``text/plain; version=0.0.4``): all workers' totals in multiprocess mode."""
        if multiprocess_dir():
            registry = CollectorRegistry()
            MultiProcessCollector(registry)
            return generate_latest(registry).decode()
        return generate_latest(self.registry).decode()


class MetricsMiddleware:
    """Counts every HTTP response by route template (not raw path: bounded label values)."""

    def __init__(self, app: ASGIApp, metrics: Metrics) -> None:
        self.app = app
        self.metrics = metrics

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        status = 500

        async def send_status(message: Message) -> None:
            nonlocal status
            if message["type"] == "http.response.start":
                status = int(message["status"])
            await send(message)

        try:
            await self.app(scope, receive, send_status)
        finally:
            method = scope["method"] if scope["method"] in _METHODS else "other"
            self.metrics.request(_route(scope), method, status)


def _route(scope: dict[str, Any]) -> str:
    route = scope.get("route")
    path = getattr(route, "path", None)
    return path if isinstance(path, str) else "unmatched"
