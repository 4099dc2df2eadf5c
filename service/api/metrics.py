"""Prometheus metrics of one worker, in the text exposition format (written by hand).

Why not ``prometheus_client``: we need three counters and one histogram, and its
multi-process mode (the only way to add up ``--workers N``) needs a shared scratch directory
and cleanup on restart. Each worker here reports its own series with a ``worker`` label
(the pid); sum over it in PromQL, or run one worker per container for exact totals.

All updates happen on the event loop thread, so plain dicts need no lock.
"""

from __future__ import annotations

import bisect
import os
import time
from collections import Counter
from typing import Any

from starlette.types import ASGIApp, Message, Receive, Scope, Send

_METHODS = frozenset({"GET", "HEAD", "POST", "PUT", "PATCH", "DELETE", "OPTIONS"})
SOLVE_BUCKETS_S = (0.0005, 0.001, 0.002, 0.005, 0.01, 0.02, 0.05, 0.1, 0.2, 0.5, 1.0, 2.0, 5.0, 10.0)


class Metrics:
    """Request counts by route and status, solve outcomes, and a solve-latency histogram."""

    def __init__(self) -> None:
        self.started = time.time()
        self.requests: Counter[tuple[str, str, int]] = Counter()
        self.solves: Counter[tuple[str, str]] = Counter()
        self.ws_frames: Counter[str] = Counter()
        self.solve_buckets = [0] * (len(SOLVE_BUCKETS_S) + 1)
        self.solve_sum_s = 0.0

    def request(self, route: str, method: str, status: int) -> None:
        self.requests[(route, method, status)] += 1

    def solve(self, method: str, outcome: str, seconds: float | None = None) -> None:
        """Count one solve (``solved`` / ``no_solution`` / ``timeout``) and its wall time."""
        self.solves[(method, outcome)] += 1
        if seconds is not None:
            self.solve_buckets[bisect.bisect_left(SOLVE_BUCKETS_S, seconds)] += 1
            self.solve_sum_s += seconds

    def render(self) -> str:
        """The exposition text (``text/plain; version=0.0.4``)."""
        w = f'worker="{os.getpid()}"'
        out = [
            "# HELP skyfix_http_requests_total HTTP requests by route template and status.",
            "# TYPE skyfix_http_requests_total counter",
        ]
        for (route, method, status), n in sorted(self.requests.items()):
            out.append(f'skyfix_http_requests_total{{{w},route="{route}",method="{method}",status="{status}"}} {n}')
        out += ["# HELP skyfix_solves_total Solves by method used and outcome.",
                "# TYPE skyfix_solves_total counter"]
        for (method, outcome), n in sorted(self.solves.items()):
            out.append(f'skyfix_solves_total{{{w},method="{_esc(method)}",outcome="{outcome}"}} {n}')
        out += ["# HELP skyfix_stream_messages_total WebSocket messages by kind.",
                "# TYPE skyfix_stream_messages_total counter"]
        for kind, n in sorted(self.ws_frames.items()):
            out.append(f'skyfix_stream_messages_total{{{w},kind="{kind}"}} {n}')
        out += ["# HELP skyfix_solve_seconds Wall time of a solve, queueing in the thread pool included.",
                "# TYPE skyfix_solve_seconds histogram"]
        cum = 0
        for le, n in zip((*SOLVE_BUCKETS_S, "+Inf"), self.solve_buckets, strict=True):
            cum += n
            out.append(f'skyfix_solve_seconds_bucket{{{w},le="{le}"}} {cum}')
        out.append(f"skyfix_solve_seconds_sum{{{w}}} {self.solve_sum_s:.6f}")
        out.append(f"skyfix_solve_seconds_count{{{w}}} {cum}")
        out += ["# HELP skyfix_start_time_seconds Unix time this worker started.",
                "# TYPE skyfix_start_time_seconds gauge",
                f"skyfix_start_time_seconds{{{w}}} {self.started:.3f}"]
        return "\n".join(out) + "\n"


def _esc(s: str) -> str:
    return s.replace("\\", "\\\\").replace('"', '\\"').replace("\n", "\\n")


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
