"""``WS /v1/stream``: one frame per message, one reply per message, in order.

A text message is a JSON ``SolveRequest`` (centroids) or a ``{"type": "config", ...}``
message (``StreamConfig``: camera, fov_deg, method, track for the frames that follow; answered
with a ``StreamAck``). A binary message is an image, solved with the connection's camera (query
parameters or the last config). Replies: a ``SolveResult``, or a ``StreamError`` for a frame
that cannot be solved; either way the stream goes on. A frame without an id gets its message
number (0-based). With ``track=true`` each solution is the attitude hint of the next frame.
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from dataclasses import dataclass
from functools import partial
from typing import Any

from fastapi import APIRouter, WebSocket
from pydantic import ValidationError

from client.models import CameraSpec, SolveRequest, SolveResult, StreamAck, StreamConfig, StreamError

from ...core import pipeline
from ...core.centroid import decode_image
from ...core.errors import SkyfixError
from ...core.types import Solution
from .. import convert, validation
from ..deps import API_KEY_HEADER, CamerasDep, NavDbDep, SettingsDep, SolverDep, key_ok
from ..errors import ApiError, error_status
from ..pump import pump
from ..sessions import get_hub, publishing
from ..settings import Settings
from ..solver import Solver

router = APIRouter(prefix="/v1", tags=["stream"])


@dataclass(slots=True)
class StreamState:
    """A connection's settings and tracking state."""

    camera: CameraSpec | str | None
    fov_deg: float | None
    method: str
    track: bool
    hint_radius_deg: float
    last: convert.Hint | None = None
    seq: int = 0


@router.websocket("/stream")
async def stream(ws: WebSocket, db: NavDbDep, solver: SolverDep, cameras: CamerasDep, settings: SettingsDep) -> None:
    """Query parameters (``validation.StreamQuery``): track, camera, fov_deg, method,
    hint_radius_deg, session, api_key. A bad one closes the connection with code 1008 and a reason
    naming it; a wrong key is refused at the handshake (403)."""
    if not key_ok(settings, ws.headers.get(API_KEY_HEADER) or ws.query_params.get("api_key")):
        await ws.close(code=1008, reason="missing or wrong API key")
        return
    try:
        q = validation.stream_query(ws.query_params, db, cameras)
    except (ValidationError, SkyfixError) as exc:
        await ws.accept()
        await ws.close(code=validation.CLOSE_POLICY, reason=validation.close_reason(exc))
        return
    await ws.accept()
    frames = _Frames(db, solver, cameras, settings,
                     StreamState(q.camera, q.fov_deg, q.method, q.track, q.hint_radius_deg))
    handle = frames.handle if q.session is None else publishing(frames.handle, get_hub(ws), q.session)
    await pump(ws, handle, max_in_flight=settings.max_in_flight,
               lifecycle=getattr(ws.app.state, "lifecycle", None))


class _Frames:
    """Turns one message into one reply (text)."""

    def __init__(self, db: convert.NavDb, solver: Solver, cameras: Mapping[str, convert.CameraEntry],
                 settings: Settings, state: StreamState) -> None:
        self.db, self.solver, self.cameras, self.settings, self.state = db, solver, cameras, settings, state

    async def handle(self, text: str | None, data: bytes | None) -> str:
        seq = self.state.seq
        self.state.seq += 1
        frame_id: str | int = seq
        kind = "image" if data is not None else "json"
        try:
            if data is not None:
                sol = await self._image(data)
            else:
                obj = self._parse(text or "")
                if isinstance(obj, dict) and isinstance(obj.get("id"), str | int):
                    frame_id = obj["id"]
                if isinstance(obj, dict) and obj.get("type") == "config":
                    kind = "config"
                    ack = self._configure(obj)
                    self.solver.metrics.ws_frames[kind] += 1
                    return ack
                sol = await self._centroids(SolveRequest.model_validate(obj))
        except (SkyfixError, ValidationError, ApiError) as exc:
            self.solver.metrics.ws_frames[f"{kind}_error"] += 1
            code, detail, field = error_status(exc, self.settings.max_centroids)
            return StreamError(id=frame_id, code=code, detail=detail, field=field).model_dump_json()
        self.solver.metrics.ws_frames[kind] += 1
        if self.state.track:
            q = sol.quaternion
            self.state.last = (q, self.state.hint_radius_deg) if sol.solved and q is not None else None
        return SolveResult.model_validate(sol.to_dict(frame_id)).model_dump_json()

    def _parse(self, text: str) -> Any:
        if len(text) > self.settings.max_body_bytes:
            raise ApiError(413, f"message is {len(text)} bytes, the limit is {self.settings.max_body_bytes}", "body")
        try:
            return json.loads(text)
        except ValueError as exc:
            raise ApiError(400, f"message is not valid JSON: {exc}", "body") from None

    async def _centroids(self, req: SolveRequest) -> Solution:
        track = self.state.last if self.state.track else None
        call = convert.frame_call(req, self.db, self.cameras, max_centroids=self.settings.max_centroids,
                                  options=self.solver.options, track_hint=track)
        return await self.solver.solve(call)

    async def _image(self, data: bytes) -> Solution:
        st = self.state
        if len(data) > self.settings.max_image_bytes:
            raise ApiError(413, f"image is {len(data)} bytes, the limit is {self.settings.max_image_bytes}", "image")
        convert.check_method(self.db, st.method)
        pixels = await self.solver.run(partial(decode_image, data, max_pixels=self.settings.max_image_pixels))
        cam = convert.image_camera(st.camera, st.fov_deg, pixels.shape, self.cameras)
        return await self.solver.solve(partial(pipeline.solve_image, pixels, cam, self.db, method=st.method,
                                               options=self.solver.options))

    def _configure(self, obj: dict[str, Any]) -> str:
        cfg = StreamConfig.model_validate(obj)
        st = self.state
        if cfg.method is not None:
            convert.check_method(self.db, cfg.method)
            st.method = cfg.method
        if isinstance(cfg.camera, CameraSpec):
            convert.camera_entry(cfg.camera, "camera")
        elif cfg.camera is not None:
            convert.parse_camera_field(cfg.camera, "camera", self.cameras)
        validation.one_camera(cfg.camera, cfg.fov_deg)
        if cfg.camera is not None:  # the latest of camera and fov_deg is the connection's camera
            st.fov_deg = None
        if cfg.fov_deg is not None:
            st.camera = None
        for name in ("camera", "fov_deg", "track", "hint_radius_deg"):
            if getattr(cfg, name) is not None:
                setattr(st, name, getattr(cfg, name))
        if not st.track:
            st.last = None
        return StreamAck(camera=st.camera, fov_deg=st.fov_deg, method=st.method, track=st.track,
                         hint_radius_deg=st.hint_radius_deg).model_dump_json()
