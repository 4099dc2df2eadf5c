"""``skyfix serve``: run the API under uvicorn (``--workers N`` share one memory-mapped database).

The workers run under ``service.cli.supervisor`` (for any N, 1 included): a worker that dies
is restarted, SIGTERM drains, SIGHUP restarts the workers one by one (onto a rebuilt database).

Options override the ``SKYFIX_*`` environment; the result is written back into the
environment so that every worker process (uvicorn spawns them and calls the app factory,
``service.api.app:create_app``) reads the same settings. The API key is taken from
``SKYFIX_API_KEY`` only, never from the command line (where ``ps`` would show it).
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Annotated

import typer
from pydantic import ValidationError

APP_FACTORY = "service.api.app:create_app"
HTTP_PROTOCOL = "service.api.header_timeout:HeaderTimeoutProtocol"
"""uvicorn's httptools protocol with a time limit on request headers (slowloris)."""
WS_MAX_QUEUE = 4
"""WebSocket messages uvicorn buffers per connection before it stops reading the socket (TCP
back-pressure); with images of up to max_image_bytes this bounds a connection's memory."""


def serve(
    host: Annotated[str | None, typer.Option(help="Interface to bind (env SKYFIX_HOST; default 127.0.0.1). "
                                             "Anything but loopback requires SKYFIX_API_KEY.")] = None,
    port: Annotated[int | None, typer.Option(help="TCP port (env SKYFIX_PORT; default 8000).")] = None,
    workers: Annotated[int | None, typer.Option(help="Worker processes (env SKYFIX_WORKERS; default 1).")] = None,
    db: Annotated[Path | None, typer.Option(help="Navigation database directory (env SKYFIX_DB_PATH; "
                                            "default: the default database, built on first use).")] = None,
    log_level: Annotated[str, typer.Option(help="uvicorn log level.")] = "info",
    verify: Annotated[bool, typer.Option("--verify", help="Check every array's sha256 before starting "
                                         "(seconds for the default database; always: headers, sizes, "
                                         "stars, sampled bytes).")] = False,
) -> None:
    """Serve the REST and WebSocket API."""
    import uvicorn

    from ..api.settings import Settings
    from ..core.errors import DatabaseError
    from ..core.navdb.integrity import check_at_start
    from .supervisor import Supervisor

    overrides = {k: v for k, v in {"host": host, "port": port, "workers": workers, "db_path": db}.items()
                 if v is not None}
    try:
        settings = Settings(**overrides)  # type: ignore[arg-type]
    except ValidationError as exc:
        typer.echo(f"skyfix serve: {_first_error(exc)}", err=True)
        raise typer.Exit(2) from None
    path = settings.db_path or _default_database()
    try:
        check_at_start(path, verify_hashes=verify)
    except DatabaseError as exc:
        typer.echo(f"skyfix serve: {exc}", err=True)
        raise typer.Exit(2) from None
    os.environ.update({"SKYFIX_HOST": settings.host, "SKYFIX_PORT": str(settings.port),
                       "SKYFIX_WORKERS": str(settings.workers), "SKYFIX_DB_PATH": str(path),
                       "SKYFIX_HEADER_TIMEOUT_S": repr(settings.header_timeout_s)})
    config = uvicorn.Config(APP_FACTORY, factory=True, host=settings.host, port=settings.port,
                            http=HTTP_PROTOCOL, ws_max_size=settings.ws_max_message_bytes + 1024,
                            ws_max_queue=WS_MAX_QUEUE, ws_per_message_deflate=False,
                            log_level=log_level, access_log=False, server_header=False,
                            timeout_graceful_shutdown=10)
    raise typer.Exit(Supervisor(config, settings.workers, drain_timeout_s=settings.drain_timeout_s,
                                access_log_level=log_level).run())


def _default_database() -> Path:
    """Build the default database once, here, before any worker starts (with a progress bar)."""
    from rich.progress import Progress

    from ..core.navdb import default_database_ready, ensure_default_database

    if default_database_ready():
        return ensure_default_database(build=False)
    with Progress(transient=True) as bar:
        task = bar.add_task("building the default navigation database", total=1.0)
        return ensure_default_database(progress=lambda stage, frac: bar.update(
            task, completed=frac, description=stage[:60]))


def _first_error(exc: ValidationError) -> str:
    err = exc.errors()[0]
    where = ".".join(str(p) for p in err["loc"])
    return f"{where}: {err['msg']}" if where else str(err["msg"]).removeprefix("Value error, ")


if __name__ == "__main__":
    typer.run(serve)
