"""The solve time limit: 504 past it, and the server carries on."""

from __future__ import annotations

import json

import httpx
import numpy as np
from websockets.sync.client import connect

from service.api import Settings

from .conftest import start_server


def test_time_limit_gives_504_and_the_server_survives(settings: Settings) -> None:
    live = start_server(Settings(**{**settings.model_dump(), "solve_timeout_s": 1e-6}))
    try:
        # 40 random points: no method can prove them, so each searches for milliseconds, far past
        # the limit (a real frame now solves in ~0.2 ms and could finish before the limit fires)
        rng = np.random.default_rng(0)
        points = np.column_stack([rng.uniform(0, 1024, 40), rng.uniform(0, 768, 40), rng.uniform(1e2, 1e4, 40)])
        body = {"id": 9, "camera": "tetra3", "centroids": points.tolist()}
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
