"""The solve time limit: 504 past it, and the server carries on."""

from __future__ import annotations

import json

import httpx
from websockets.sync.client import connect

from service.api import Settings
from service.core.sim import SimFrame

from .conftest import real_stars, rows, start_server


def test_time_limit_gives_504_and_the_server_survives(settings: Settings, frames: list[SimFrame]) -> None:
    live = start_server(Settings(**{**settings.model_dump(), "solve_timeout_s": 1e-6}))
    try:
        frame = next(f for f in frames if real_stars(f) >= 8)
        body = {"id": 9, "camera": "tetra3", "centroids": rows(frame)}
        with httpx.Client(base_url=live.url) as c:
            r = c.post("/v1/solve", json=body)
            assert r.status_code == 504 and "limit" in r.json()["detail"]
            assert c.get("/v1/health").status_code == 200
            assert 'outcome="timeout"' in c.get("/metrics").text
        with connect(live.ws_url) as ws:
            ws.send(json.dumps(body))
            reply = json.loads(ws.recv(timeout=10))
            assert (reply["id"], reply["code"]) == (9, 504)
    finally:
        live.stop()
