"""``GET /v1/health`` (open, for load balancers and HEALTHCHECK) and ``GET /v1/info``."""

from __future__ import annotations

import os
import time
from typing import Any

from fastapi import APIRouter, Request

from client.models import CameraSpec, HealthResponse, InfoResponse, Limits

from ... import __version__
from ...core.methods import method_names
from ...core.navdb import NavDatabaseSet
from ..deps import NavDbDep, SettingsDep

health_router = APIRouter(prefix="/v1", tags=["service"])
info_router = APIRouter(prefix="/v1", tags=["service"])


@health_router.get("/health", response_model=HealthResponse)
async def health(request: Request, db: NavDbDep) -> HealthResponse:
    """The worker is up and its navigation database is open."""
    return HealthResponse(version=__version__, n_stars=len(db.stars.hip), methods=db.methods,
                          pid=os.getpid(), uptime_s=round(time.monotonic() - request.app.state.started, 3))


@info_router.get("/info", response_model=InfoResponse)
async def info(db: NavDbDep, settings: SettingsDep) -> InfoResponse:
    """The database manifest (build parameters, no server paths), methods, cameras and limits."""
    manifest = _public(db.manifest)
    if isinstance(db, NavDatabaseSet):
        manifest["members"] = {name: _public(m.manifest) for name, m in db.members.items()}
    limits = Limits(max_body_bytes=settings.max_body_bytes, max_image_bytes=settings.max_image_bytes,
                    max_image_pixels=settings.max_image_pixels, max_centroids=settings.max_centroids,
                    solve_timeout_s=settings.solve_timeout_s)
    cameras: dict[str, CameraSpec] = dict(settings.cameras)
    return InfoResponse(version=__version__, database=manifest, methods=["auto", *method_names()],
                        database_methods=db.methods, cameras=cameras, limits=limits)


def _public(manifest: dict[str, Any]) -> dict[str, Any]:
    """A manifest without its per-array file table (names, hashes: nothing a client needs)."""
    return {k: v for k, v in manifest.items() if k != "arrays"}
