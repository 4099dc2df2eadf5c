"""Request body limit per path, enforced while the body streams in.

A small ASGI middleware that picks the limit for the request's path (images may be larger
than JSON frames), answers 413 at once to a ``Content-Length`` over it (before reading a
byte), and otherwise hands the request to Starlette's ``RequestBodyLimitResponder``, which
counts the bytes of the body as they arrive and raises 413 as soon as they pass the limit
(a chunked body, or one longer than its header said). Nothing is buffered beyond the limit.
"""

from __future__ import annotations

from collections.abc import Mapping

from starlette.datastructures import Headers
from starlette.middleware.body_limit import RequestBodyLimitResponder
from starlette.responses import JSONResponse
from starlette.types import ASGIApp, Receive, Scope, Send


class PathBodyLimit:
    """``default`` bytes for every HTTP request, ``per_path[path]`` for the paths listed."""

    def __init__(self, app: ASGIApp, *, default: int, per_path: Mapping[str, int] | None = None) -> None:
        self.app = app
        self.default = default
        self.per_path = dict(per_path or {})

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        limit = self.per_path.get(scope["path"], self.default)
        declared = Headers(scope=scope).get("content-length", "")
        if declared.isdigit() and int(declared) > limit:
            response = JSONResponse({"detail": f"body is {declared} bytes, the limit is {limit}", "field": "body"},
                                    status_code=413, headers={"Connection": "close"})
            await response(scope, receive, send)
            return
        await RequestBodyLimitResponder(self.app, limit)(scope, receive, send)
