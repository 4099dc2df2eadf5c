"""Run engine calls off the event loop, under a time limit, and count them.

CPU work goes to a bounded thread pool (``anyio.to_thread.run_sync`` with a
``CapacityLimiter``; numpy releases the GIL in its kernels). A solve that passes the time limit
is answered with 504 and abandoned: Python cannot kill a thread, so it runs to its end in the
background. If abandoned solves pile up (as many as the pool has threads), new work is refused
with 503 until they finish, so a flood of pathological frames cannot oversubscribe the CPU.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from typing import TypeVar

import anyio
from anyio import to_thread

from ..core.pipeline import DEFAULT_OPTIONS, SolveOptions
from ..core.types import Solution
from .errors import ApiError, SolveTimeoutError
from .metrics import Metrics

T = TypeVar("T")


class Solver:
    """The worker's gateway to the engine: ``await solver.solve(call)``.

    ``options`` are the engine's solve options (its own search time limit among them).
    """

    def __init__(self, *, threads: int, timeout_s: float, metrics: Metrics,
                 options: SolveOptions = DEFAULT_OPTIONS) -> None:
        self.threads = threads
        self.options = options
        self.timeout_s = timeout_s
        self.metrics = metrics
        self._limiter = anyio.CapacityLimiter(threads)
        self._lock = threading.Lock()
        self._running = 0

    async def run(self, fn: Callable[[], T]) -> T:
        """``fn()`` in the thread pool, within the time limit (504 past it, 503 if saturated)."""
        if self._running >= 2 * self.threads:
            raise ApiError(503, "server busy: earlier solves are still running past their time limit",
                           headers={"Retry-After": "1"})
        try:
            with anyio.fail_after(self.timeout_s):
                return await to_thread.run_sync(self._counted, fn, abandon_on_cancel=True,
                                                limiter=self._limiter)
        except TimeoutError:
            raise SolveTimeoutError(self.timeout_s) from None

    async def solve(self, call: Callable[[], Solution]) -> Solution:
        """Run one solve and record its outcome and wall time."""
        t0 = time.perf_counter()
        try:
            sol = await self.run(call)
        except SolveTimeoutError:
            self.metrics.solve("unknown", "timeout", time.perf_counter() - t0)
            raise
        self.metrics.solve(sol.method, sol.status.value, time.perf_counter() - t0, reason=_reason(sol))
        return sol

    def _counted(self, fn: Callable[[], T]) -> T:
        with self._lock:
            self._running += 1
        try:
            return fn()
        finally:
            with self._lock:
                self._running -= 1


def _reason(sol: Solution) -> str | None:
    """Why a solve ended as it did (``Solution.reason`` where the engine gives one), as a label value."""
    reason = getattr(sol, "reason", None)
    if reason is None:
        return None
    return str(getattr(reason, "value", reason))[:64]
