"""Checks of what a client sends outside a request body: the WebSocket's query parameters and
the image endpoint's camera fields. Each raises an error naming the parameter."""

from __future__ import annotations

from collections.abc import Mapping

from pydantic import BaseModel, ConfigDict, Field, ValidationError

from ..core.errors import InvalidInputError, SkyfixError
from . import convert
from .errors import error_status
from .sessions import SESSION_NAME

CLOSE_POLICY = 1008
"""WebSocket close code for a connection refused over its query parameters (RFC 6455 'policy
violation'); a wrong API key is refused earlier, at the handshake (HTTP 403)."""
MAX_REASON_BYTES = 123
"""A close frame's reason is at most 123 bytes of UTF-8."""


class StreamQuery(BaseModel):
    """``WS /v1/stream`` query parameters (all optional)."""

    model_config = ConfigDict(extra="ignore", allow_inf_nan=False)

    track: bool = Field(False, description="Use each solution as the next frame's attitude hint.")
    camera: str | None = Field(None, max_length=4096, description="Image frames: camera JSON or name.")
    fov_deg: float | None = Field(None, gt=0, lt=170, description="Image frames: horizontal FOV, deg.")
    method: str = Field("auto", max_length=32, description="Identification method, or 'auto'.")
    hint_radius_deg: float = Field(5.0, gt=0, le=180, description="Tracking hint radius, deg.")
    session: str | None = Field(None, pattern=SESSION_NAME.pattern, description=(
        "Publish every reply to the viewers of this session (WS /v1/sessions/{session}/watch)."))


def one_camera(camera: object | None, fov_deg: float | None) -> None:
    """Refuse ``camera`` and ``fov_deg`` given together (the JSON endpoint refuses it too)."""
    if camera is not None and fov_deg is not None:
        raise InvalidInputError("fov_deg", "give camera or fov_deg, not both")


def stream_query(params: Mapping[str, str], db: convert.NavDb,
                 cameras: Mapping[str, convert.CameraEntry]) -> StreamQuery:
    """The connection's parameters, checked before the first frame: types and ranges, the
    method against the database, the camera against the configured names or as JSON."""
    q = StreamQuery.model_validate({k: v for k, v in params.items() if k in StreamQuery.model_fields})
    convert.check_method(db, q.method)
    one_camera(q.camera, q.fov_deg)
    if q.camera is not None:
        convert.parse_camera_field(q.camera, "camera", cameras)
    return q


def close_reason(exc: ValidationError | SkyfixError) -> str:
    """The close frame's reason: the error, naming the parameter, cut to 123 bytes."""
    _, detail, field = error_status(exc)
    text = detail if field is None or detail.startswith(f"{field}:") else f"{field}: {detail}"
    data = text.encode()
    return text if len(data) <= MAX_REASON_BYTES else data[:MAX_REASON_BYTES - 3].decode(errors="ignore") + "..."


__all__ = ["CLOSE_POLICY", "StreamQuery", "close_reason", "one_camera", "stream_query"]
