"""Typed dependencies: what a handler needs, read from ``app.state`` (set in the lifespan).

They are ``async def`` on purpose: FastAPI runs a plain ``def`` dependency in the thread pool,
a thread hop (~0.1 ms) per dependency per request.
"""

from __future__ import annotations

import hmac
from collections.abc import Awaitable, Callable, Mapping
from typing import Annotated

from fastapi import Depends, Request
from fastapi.security import APIKeyHeader
from starlette.requests import HTTPConnection

from .convert import CameraEntry, NavDb
from .errors import ApiError
from .metrics import Metrics
from .settings import Settings
from .solver import Solver

API_KEY_HEADER = "X-API-Key"
_api_key_scheme = APIKeyHeader(name=API_KEY_HEADER, auto_error=False,
                               description="Required when the server has SKYFIX_API_KEY set.")


async def get_db(conn: HTTPConnection) -> NavDb:
    db: NavDb = conn.app.state.db
    return db


async def get_settings(conn: HTTPConnection) -> Settings:
    settings: Settings = conn.app.state.settings
    return settings


async def get_solver(conn: HTTPConnection) -> Solver:
    solver: Solver = conn.app.state.solver
    return solver


async def get_cameras(conn: HTTPConnection) -> Mapping[str, CameraEntry]:
    cameras: Mapping[str, CameraEntry] = conn.app.state.cameras
    return cameras


async def get_metrics(conn: HTTPConnection) -> Metrics:
    metrics: Metrics = conn.app.state.metrics
    return metrics


NavDbDep = Annotated[NavDb, Depends(get_db)]
SettingsDep = Annotated[Settings, Depends(get_settings)]
SolverDep = Annotated[Solver, Depends(get_solver)]
CamerasDep = Annotated[Mapping[str, CameraEntry], Depends(get_cameras)]
MetricsDep = Annotated[Metrics, Depends(get_metrics)]


def key_ok(settings: Settings, given: str | None) -> bool:
    """True if the server has no key, or ``given`` is it (constant-time comparison)."""
    if settings.api_key is None:
        return True
    return given is not None and hmac.compare_digest(given.encode(), settings.api_key.get_secret_value().encode())


async def require_api_key(settings: SettingsDep, key: Annotated[str | None, Depends(_api_key_scheme)]) -> None:
    """401 unless the request carries the configured ``X-API-Key``."""
    if not key_ok(settings, key):
        raise ApiError(401, "missing or wrong API key", API_KEY_HEADER, headers={"WWW-Authenticate": "APIKey"})


def require_media_type(*allowed: str) -> Callable[[Request], Awaitable[None]]:
    """A dependency answering 415 unless the Content-Type is one of ``allowed``."""

    async def check(request: Request) -> None:
        media = request.headers.get("content-type", "").split(";", 1)[0].strip().lower()
        ok = media in allowed or ("application/json" in allowed and media.endswith("+json")
                                  and media.startswith("application/"))
        if not ok:
            raise ApiError(415, f"Content-Type must be {' or '.join(allowed)}, not {media or 'missing'}",
                           "content-type")

    return check
