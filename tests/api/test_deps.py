"""The API key: required on every route but /v1/health when the server has one."""

from __future__ import annotations

from collections.abc import Iterator

import httpx
import pytest
from websockets.exceptions import InvalidStatus
from websockets.sync.client import connect

from service.api import Settings

from .conftest import CENTROIDS_OK, LiveServer, start_server

KEY = "correct horse battery staple"


@pytest.fixture(scope="module")
def keyed(settings: Settings) -> Iterator[LiveServer]:
    live = start_server(Settings(**{**settings.model_dump(), "api_key": KEY}))
    yield live
    live.stop()


@pytest.mark.parametrize("key", [None, "", "wrong", KEY + "x", KEY[:-1]])
def test_wrong_or_missing_key_is_401(keyed: LiveServer, key: str | None) -> None:
    headers = {} if key is None else {"X-API-Key": key}
    with httpx.Client(base_url=keyed.url, headers=headers) as c:
        for r in (c.post("/v1/solve", json=CENTROIDS_OK), c.get("/v1/info"), c.get("/metrics"),
                  c.post("/v1/solve/image", files={"image": ("x", b"x")}, data={"fov_deg": "10"})):
            assert (r.status_code, r.json()["field"]) == (401, "X-API-Key"), r.text
        assert c.get("/v1/health").status_code == 200


def test_right_key_passes(keyed: LiveServer) -> None:
    with httpx.Client(base_url=keyed.url, headers={"X-API-Key": KEY}) as c:
        assert c.post("/v1/solve", json=CENTROIDS_OK).status_code == 200
        assert c.get("/v1/info").status_code == 200


def test_websocket_key_by_header_or_query(keyed: LiveServer) -> None:
    with pytest.raises(InvalidStatus) as refused, connect(keyed.ws_url):
        pass
    assert refused.value.response.status_code == 403
    with connect(keyed.ws_url, additional_headers={"X-API-Key": KEY}) as ws:
        ws.send('{"type": "config", "method": "pyramid"}')
        assert '"config"' in ws.recv(timeout=10)
    with connect(keyed.ws_url + "?api_key=" + KEY.replace(" ", "%20")) as ws:
        ws.send('{"type": "config"}')
        assert '"config"' in ws.recv(timeout=10)


def test_openapi_and_docs_are_open_as_documented(keyed: LiveServer) -> None:
    from pathlib import Path

    with httpx.Client(base_url=keyed.url) as c:
        assert c.get("/openapi.json").status_code == 200 and c.get("/docs").status_code == 200
        assert c.get("/v1/info").status_code == 401
    text = (Path(__file__).resolve().parents[2] / "docs" / "api.md").read_text()
    assert "`/docs` and `/openapi.json` needs `X-API-Key`" in text.replace("`/v1/health`, ", "")
