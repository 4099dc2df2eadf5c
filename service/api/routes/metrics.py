"""``GET /metrics``: Prometheus text exposition of this worker."""

from __future__ import annotations

from fastapi import APIRouter
from fastapi.responses import PlainTextResponse

from ..deps import MetricsDep

router = APIRouter(tags=["service"])


@router.get("/metrics", response_class=PlainTextResponse)
async def metrics(m: MetricsDep) -> PlainTextResponse:
    """Requests by route and status, solve outcomes, solve latency histogram."""
    return PlainTextResponse(m.render(), media_type="text/plain; version=0.0.4; charset=utf-8")
