"""GET /v1/health and /v1/info."""

from __future__ import annotations

import os

import httpx

from client.models import HealthResponse, InfoResponse
from service.api import Settings


def test_health(client: httpx.Client) -> None:
    h = HealthResponse.model_validate(client.get("/v1/health").json())
    assert h.status == "ok" and h.n_stars > 1000
    assert set(h.methods) == {"pyramid", "maxangle"}
    assert h.pid == os.getpid()  # the threaded test server


def test_info(client: httpx.Client, settings: Settings) -> None:
    info = InfoResponse.model_validate(client.get("/v1/info").json())
    assert info.methods[0] == "auto" and {"pyramid", "maxangle"} <= set(info.methods)
    assert set(info.database_methods) == {"pyramid", "maxangle"}
    assert info.database["mag_limit"] == 6.0 and "arrays" not in info.database
    assert str(settings.db_path) not in client.get("/v1/info").text  # no server paths
    assert set(info.cameras) == {"tetra3", "side"}
    assert info.cameras["side"].mounting_quaternion is not None
    assert info.limits.max_centroids == settings.max_centroids
