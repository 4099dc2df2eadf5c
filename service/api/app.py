"""The app factory: ``create_app(settings)``; ``skyfix serve`` runs it under uvicorn."""

from __future__ import annotations

import gc
import time
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager
from pathlib import Path

from anyio import to_thread
from fastapi import Depends, FastAPI

from .. import __version__
from ..core.navdb import ensure_default_database, open_database
from ..core.pipeline import SolveOptions
from ..core.warmup import warm_up
from . import errors, sessions, ui
from .convert import camera_entry
from .deps import require_api_key
from .lifecycle import ConnectionLimit, Lifecycle
from .limits import PathBodyLimit
from .logs import RequestLog
from .metrics import Metrics, MetricsMiddleware
from .routes import health, metrics, solve, stream
from .settings import Settings, get_settings
from .solver import Solver


@asynccontextmanager
async def lifespan(app: FastAPI) -> AsyncIterator[None]:
    """Open the database memory-mapped (once per worker) and resolve the named cameras."""
    s: Settings = app.state.settings
    path = s.db_path or await to_thread.run_sync(ensure_default_database)
    app.state.db = open_database(Path(path).resolve())  # one version, even if the symlink is swapped now
    await to_thread.run_sync(warm_up, app.state.db)  # matchers and k-d trees before the first request
    # what the start-up built stays for the worker's life: frozen, a full collection no longer
    # walks it (~35 ms with the default database loaded, inside whichever request it fell on)
    gc.collect()
    gc.freeze()
    app.state.cameras = {name: camera_entry(spec, f"cameras.{name}") for name, spec in s.cameras.items()}
    app.state.solver = Solver(threads=s.solve_threads, timeout_s=s.solve_timeout_s, metrics=app.state.metrics,
                              options=SolveOptions(timeout_ms=s.search_timeout_ms))
    app.state.started = time.monotonic()
    yield


def create_app(settings: Settings | None = None) -> FastAPI:
    """A skyfix server over ``settings`` (default: the ``SKYFIX_*`` environment)."""
    settings = settings or get_settings()
    app = FastAPI(
        title="skyfix", version=__version__, lifespan=lifespan,
        summary="Lost-in-space star identification: centroids or an image in; star identities and attitude out.",
        form_limits={"max_fields": 8, "max_files": 1, "max_part_size": 64 * 1024},
    )
    app.state.settings = settings
    app.state.metrics = Metrics()
    errors.install(app)
    app.add_middleware(PathBodyLimit, default=settings.max_body_bytes,
                       per_path={"/v1/solve/image": settings.max_upload_bytes})
    app.add_middleware(MetricsMiddleware, metrics=app.state.metrics)
    app.state.lifecycle = Lifecycle(settings.max_connections)
    app.add_middleware(ConnectionLimit, lifecycle=app.state.lifecycle, metrics=app.state.metrics)
    app.add_middleware(RequestLog)  # outermost: every request and refusal gets an id and a log line
    keyed = [Depends(require_api_key)] if settings.api_key else []  # the OpenAPI says what is in force
    app.include_router(health.health_router)
    app.include_router(health.info_router, dependencies=keyed)
    app.include_router(solve.router, dependencies=keyed)
    app.include_router(stream.router)  # checks the key itself (header or ?api_key=)
    app.include_router(metrics.router, dependencies=keyed)
    app.include_router(sessions.router)  # viewers of named stream sessions; checks the key itself
    ui.install(app)  # the web console at /ui (static pages; the key is typed in the page)
    return app
