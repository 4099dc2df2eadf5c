"""The web console at ``/ui``: ``/ui/live`` (watch a stream session) and ``/ui/solve`` (solve one image).

Static pages only: they call the public API (``/v1/...``) from the browser with the API key the
user types in (kept in page memory, never in the page). Every response under ``/ui`` carries a
strict Content-Security-Policy (scripts, styles, data from this origin only; no inline code). The
front-end libraries are vendored built files (``static/vendor/``, refreshed by
``scripts/vendor_ui.sh``); nothing is loaded from another host.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from fastapi import APIRouter, FastAPI
from fastapi.responses import FileResponse, RedirectResponse
from starlette.staticfiles import StaticFiles
from starlette.types import Scope

STATIC = Path(__file__).resolve().parent / "static"

CSP = ("default-src 'none'; script-src 'self'; style-src 'self'; img-src 'self' blob: data:; "
       "connect-src 'self'; font-src 'self'; base-uri 'none'; form-action 'none'; frame-ancestors 'none'")
"""Content-Security-Policy of every /ui response (``connect-src 'self'`` covers ws:// to this host)."""

HEADERS = {"Content-Security-Policy": CSP, "X-Content-Type-Options": "nosniff",
           "Referrer-Policy": "no-referrer", "X-Frame-Options": "DENY"}
"""Security headers of every /ui response."""

PAGES = {"live": "live.html", "solve": "solve.html"}


class _Static(StaticFiles):
    """StaticFiles with the console's security headers."""

    def file_response(self, *args: Any, **kwargs: Any) -> Any:
        resp = super().file_response(*args, **kwargs)
        resp.headers.update(HEADERS)
        return resp

    async def get_response(self, path: str, scope: Scope) -> Any:
        resp = await super().get_response(path, scope)
        resp.headers.update(HEADERS)
        return resp


router = APIRouter(prefix="/ui", include_in_schema=False)


@router.get("")
@router.get("/")
async def index() -> RedirectResponse:
    return RedirectResponse("/ui/live", headers=HEADERS)


def _page(name: str) -> Any:
    async def page() -> FileResponse:
        return FileResponse(STATIC / PAGES[name], media_type="text/html; charset=utf-8",
                            headers={**HEADERS, "Cache-Control": "no-cache"})

    return page


for _name in PAGES:
    router.add_api_route(f"/{_name}", _page(_name), methods=["GET"])


def install(app: FastAPI) -> None:
    """Serve the console's pages and static files under ``/ui``."""
    app.include_router(router)
    app.mount("/ui/static", _Static(directory=STATIC), name="ui-static")
