"""Retry policy and defaults shared by the HTTP clients and the stream."""

from __future__ import annotations

import random
from dataclasses import dataclass, field

__all__ = ["DEFAULT_TIMEOUT_S", "DEFAULT_URL", "RETRY_STATUSES", "Retry"]

DEFAULT_URL = "http://127.0.0.1:8000"
DEFAULT_TIMEOUT_S = 30.0
RETRY_STATUSES = frozenset({502, 503, 504})


@dataclass(frozen=True, slots=True)
class Retry:
    """When and how long to wait before trying again.

    A request is retried only on transient failures: it could not connect, the connection
    dropped before an answer, or the server (or a proxy in front of it) answered 502, 503 or
    504. A 4xx is never retried: it is the request that is wrong. A read timeout is not
    retried either: the server is still working on the request, and sending it again would
    only add load. The wait after the ``k``-th failed attempt is
    ``min(max_backoff_s, backoff_s * 2 ** (k - 1))``, shortened by up to ``jitter`` of itself
    at random (so that many clients do not retry in step), and never shorter than a
    ``Retry-After`` the server sent (capped at ``max_backoff_s``).

    **Parameters:**

    * **attempts** - total tries, the first included; ``1`` disables retrying.
    * **backoff_s** - wait after the first failure, seconds.
    * **max_backoff_s** - cap on any one wait, seconds.
    * **jitter** - fraction in [0, 1] by which a wait may be shortened at random.
    * **statuses** - HTTP statuses treated as transient.
    """

    attempts: int = 3
    backoff_s: float = 0.25
    max_backoff_s: float = 5.0
    jitter: float = 0.5
    statuses: frozenset[int] = field(default=RETRY_STATUSES)

    def __post_init__(self) -> None:
        if self.attempts < 1:
            raise ValueError("Retry.attempts must be at least 1")
        if self.backoff_s < 0 or self.max_backoff_s < 0:
            raise ValueError("Retry backoff must not be negative")
        if not 0.0 <= self.jitter <= 1.0:
            raise ValueError("Retry.jitter must be in [0, 1]")
        if any(400 <= s < 500 for s in self.statuses):
            raise ValueError("4xx statuses are never retried")

    @classmethod
    def none(cls) -> Retry:
        """A policy that never retries."""
        return cls(attempts=1)

    def delay_s(self, failed_attempts: int, *, retry_after_s: float | None = None,
                rng: random.Random | None = None) -> float:
        """Seconds to wait after ``failed_attempts`` consecutive failures (1 = the first)."""
        base = min(self.max_backoff_s, self.backoff_s * 2.0 ** max(0, failed_attempts - 1))
        r = (rng or random).random()
        wait = base * (1.0 - self.jitter * r)
        if retry_after_s is not None and retry_after_s > 0:
            wait = max(wait, min(retry_after_s, self.max_backoff_s))
        return wait


def as_retry(retries: Retry | int | None) -> Retry:
    """``Retry`` from a policy, a number of *retries* (``0`` = try once), or ``None`` (default)."""
    if retries is None:
        return Retry()
    if isinstance(retries, Retry):
        return retries
    if isinstance(retries, bool) or not isinstance(retries, int) or retries < 0:
        raise ValueError("retries must be a Retry or a non-negative int")
    return Retry(attempts=retries + 1)


def parse_retry_after(value: str | None) -> float | None:
    """Seconds from a ``Retry-After`` header given as a number (HTTP dates are ignored)."""
    if not value:
        return None
    try:
        seconds = float(value.strip())
    except ValueError:
        return None
    return seconds if seconds >= 0 else None
