"""GET /v1/health and /v1/info, over one database and over a database set."""

from __future__ import annotations

import os
from collections.abc import Iterator

import httpx
import pytest

from client.models import HealthResponse, InfoResponse
from service.api import Settings
from service.core.navdb import BuildConfig, build_database_set
from service.core.sim import SimFrame

from ..conftest import API_DB_CONFIG, LiveServer, angle_deg, real_stars, rows, start_server


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


@pytest.fixture(scope="module")
def set_server(tmp_path_factory: pytest.TempPathFactory, settings: Settings) -> Iterator[LiveServer]:
    """A server over a database *set* (the default database's shape): two small members."""
    path = build_database_set(tmp_path_factory.mktemp("navset") / "set", {
        "narrow": BuildConfig(fov_min_deg=4.0, fov_max_deg=9.0, mag_limit=5.5, methods=("pyramid", "maxangle")),
        "wide": API_DB_CONFIG})
    live = start_server(Settings(**{**settings.model_dump(), "db_path": path}))
    yield live
    live.stop()


def test_a_database_set(set_server: LiveServer, frames: list[SimFrame]) -> None:
    with httpx.Client(base_url=set_server.url) as c:
        info = InfoResponse.model_validate(c.get("/v1/info").json())
        members = info.database["members"]
        assert isinstance(members, dict) and set(members) == {"narrow", "wide"}
        assert all("arrays" not in m for m in members.values())
        assert set(info.database_methods) == {"pyramid", "maxangle"}
        assert c.get("/v1/health").json()["n_stars"] > 1000
        frame = next(f for f in frames if real_stars(f) >= 8)
        r = c.post("/v1/solve", json={"camera": "tetra3", "centroids": rows(frame), "method": "pyramid"})
        assert r.json()["status"] == "solved", r.text
        assert angle_deg(r.json()["quaternion"], frame.quaternion) < 0.05
        bad = c.post("/v1/solve", json={"camera": "tetra3", "centroids": rows(frame), "method": "nope"})
        assert (bad.status_code, bad.json()["field"]) == (422, "method")
