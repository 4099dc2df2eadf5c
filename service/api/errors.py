"""Every error becomes ``{"detail": ..., "field": ...}`` (``client.models.ErrorResponse``).

``field`` is the dotted path of the offending input (``centroids.3.1``, ``camera.fov_deg``,
``method``, ``image``), or ``body`` / ``content-type`` / ``X-API-Key`` for the request as a whole.

    InvalidInputError, ImageDecodeError    422  (the engine names the field)
    UnknownMethodError                     422  field "method"
    RequestValidationError                 422  (400 for JSON that does not parse)
    ApiError                               its status (401, 413, 415, 422, 503, 504)
    HTTPException                          its status (404, 405, 413 from the body limit)
    DatabaseError                          503
"""

from __future__ import annotations

import logging
import re
from collections.abc import Sequence
from typing import Any

from fastapi import FastAPI, Request
from fastapi.exceptions import RequestValidationError
from fastapi.responses import JSONResponse
from pydantic import ValidationError
from starlette.exceptions import HTTPException as StarletteHTTPException

from client.models import ErrorResponse

from ..core.errors import DatabaseError, InvalidInputError, UnknownMethodError

log = logging.getLogger("skyfix.api")

_SOURCES = {"body", "query", "path", "header", "cookie"}
_UNION_TAG = re.compile(r"^(str|int|float|bool|none|list\[.*|dict\[.*|[A-Z]\w*)$|[\[\(]")


class ApiError(Exception):
    """An error with its HTTP status and the field it concerns."""

    def __init__(self, status_code: int, detail: str, field: str | None = None,
                 headers: dict[str, str] | None = None) -> None:
        super().__init__(detail)
        self.status_code = status_code
        self.detail = detail
        self.field = field
        self.headers = headers


class SolveTimeoutError(ApiError):
    """A solve ran past the time limit."""

    def __init__(self, timeout_s: float) -> None:
        super().__init__(504, f"the solve took longer than the {timeout_s:g} s limit")


def dotted(loc: Sequence[int | str]) -> str | None:
    """``("body", "camera", "function-after[...]", "fov_deg")`` -> ``"camera.fov_deg"``."""
    parts = [str(p) for i, p in enumerate(loc)
             if not (i == 0 and p in _SOURCES) and not (isinstance(p, str) and _UNION_TAG.search(p))]
    return ".".join(parts) or None


def describe(errors: Sequence[Any], max_centroids: int | None = None) -> tuple[str, str | None]:
    """Message and field of the first pydantic error (the one a person fixes first);
    ``max_centroids``, the server's own limit, replaces the schema's hard cap in the message."""
    if not errors:
        return "invalid input", None
    err = errors[0]
    field = dotted(err.get("loc", ()))
    msg = str(err.get("msg", "invalid input"))
    actual = (err.get("ctx") or {}).get("actual_length")
    if max_centroids and err.get("type") == "too_long" and (field or "").endswith("centroids") and actual:
        msg = f"{actual} centroids, this server takes at most {max_centroids}"
    return (f"{field}: {msg}" if field else msg), field or "body"


def error_status(exc: Exception, max_centroids: int | None = None) -> tuple[int, str, str | None]:
    """``(status, detail, field)`` of an input error, for REST and the WebSocket alike
    (``max_centroids``: the server's limit, named in the message for too many centroids)."""
    if isinstance(exc, ApiError):
        return exc.status_code, exc.detail, exc.field
    if isinstance(exc, InvalidInputError):
        return 422, str(exc), exc.field
    if isinstance(exc, UnknownMethodError):
        return 422, f"method: {exc}", "method"
    if isinstance(exc, ValidationError | RequestValidationError):
        errors = exc.errors()
        if errors and errors[0].get("type") == "json_invalid":
            ctx = errors[0].get("ctx") or {}
            return 400, f"body is not valid JSON: {ctx.get('error', 'decode error')}", "body"
        detail, field = describe(errors, max_centroids)
        return 422, detail, field
    if isinstance(exc, DatabaseError):
        log.error("navigation database unusable: %s", exc)
        return 503, "the navigation database is unavailable", None
    raise TypeError(f"not an input error: {exc!r}")


def _response(status: int, detail: str, field: str | None,
              headers: dict[str, str] | None = None) -> JSONResponse:
    body = ErrorResponse(detail=detail, field=field).model_dump()
    return JSONResponse(body, status_code=status, headers=headers)


async def _handle(request: Request, exc: Exception) -> JSONResponse:
    settings = getattr(request.app.state, "settings", None)
    status, detail, field = error_status(exc, getattr(settings, "max_centroids", None))
    return _response(status, detail, field, getattr(exc, "headers", None))


async def _handle_http(request: Request, exc: Exception) -> JSONResponse:
    assert isinstance(exc, StarletteHTTPException)
    field = "body" if exc.status_code in (400, 413) else None  # 400: multipart parse errors
    return _response(exc.status_code, str(exc.detail), field, exc.headers)


def install(app: FastAPI) -> None:
    """Register the handlers on ``app``."""
    for cls in (ApiError, InvalidInputError, UnknownMethodError, RequestValidationError,
                ValidationError, DatabaseError):
        app.add_exception_handler(cls, _handle)
    app.add_exception_handler(StarletteHTTPException, _handle_http)
