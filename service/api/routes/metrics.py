"""``GET /metrics``: Prometheus text exposition, totals over all workers (see ``service.api.metrics``)."""

from __future__ import annotations

from fastapi import APIRouter
from fastapi.responses import PlainTextResponse

from ..deps import MetricsDep
from ..metrics import CONTENT_TYPE

router = APIRouter(tags=["service"])


@router.get("/metrics", response_class=PlainTextResponse)
async def metrics(m: MetricsDep) -> PlainTextResponse:
    """Requests by route and status, solve outcomes, solve latency histogram."""
    return PlainTextResponse(m.render(), media_type=CONTENT_TYPE)
