"""Retries, backoff and error mapping, through httpx's own seam (MockTransport)."""

import asyncio
import json
import random

import httpx
import pytest

from client import (
    AsyncClient,
    Client,
    Retry,
    SkyfixConnectError,
    SkyfixHTTPError,
    SkyfixProtocolError,
    SkyfixTimeoutError,
)

CAM = {"width": 1024, "height": 768, "fov_deg": 11.4}
FAST = Retry(attempts=3, backoff_s=0.0, max_backoff_s=0.0)
OK = {"id": 7, "status": "no_solution", "method": "pyramid"}


def scripted(*steps: object) -> tuple[httpx.MockTransport, list[httpx.Request]]:
    """A transport answering with each step in turn: a Response, or an exception to raise."""
    seen: list[httpx.Request] = []
    todo = list(steps)

    def handler(request: httpx.Request) -> httpx.Response:
        seen.append(request)
        step = todo.pop(0)
        if isinstance(step, Exception):
            raise step
        assert isinstance(step, httpx.Response)
        return step

    return httpx.MockTransport(handler), seen


def test_backoff_grows_exponentially_and_is_capped() -> None:
    r = Retry(attempts=10, backoff_s=0.1, max_backoff_s=1.0, jitter=0.0)
    assert [r.delay_s(k) for k in (1, 2, 3, 4, 5, 6)] == pytest.approx([0.1, 0.2, 0.4, 0.8, 1.0, 1.0])
    jittered = Retry(backoff_s=1.0, jitter=0.5)
    rng = random.Random(1)
    assert all(0.5 <= jittered.delay_s(1, rng=rng) <= 1.0 for _ in range(100))
    assert Retry(backoff_s=0.1, max_backoff_s=5).delay_s(1, retry_after_s=3) == 3
    assert Retry(backoff_s=0.1, max_backoff_s=5).delay_s(1, retry_after_s=60) == 5
    with pytest.raises(ValueError):
        Retry(statuses=frozenset({429}))


@pytest.mark.parametrize("status", [502, 503, 504])
def test_transient_statuses_are_retried(status: int) -> None:
    transport, seen = scripted(httpx.Response(status), httpx.Response(200, json=OK))
    with Client("http://sky", transport=transport, retries=FAST) as c:
        assert c.solve([[1, 2]], camera=CAM, id=7).status == "no_solution"
    assert len(seen) == 2
    assert json.loads(seen[1].content)["centroids"] == [[1.0, 2.0]]


def test_connect_errors_are_retried_then_raised() -> None:
    transport, seen = scripted(*[httpx.ConnectError("refused")] * 3)
    with Client("http://sky", transport=transport, retries=FAST) as c, pytest.raises(SkyfixConnectError,
                                                                                      match="3 attempts"):
        c.health()
    assert len(seen) == 3


def test_dropped_connection_is_retried() -> None:
    transport, seen = scripted(httpx.RemoteProtocolError("server disconnected"), httpx.Response(200, json=OK))
    with Client("http://sky", transport=transport, retries=FAST) as c:
        assert c.solve([[1, 2]], camera=CAM).status == "no_solution"
    assert len(seen) == 2


def test_read_timeout_is_not_retried() -> None:
    transport, seen = scripted(httpx.ReadTimeout("slow"), httpx.Response(200, json=OK))
    with Client("http://sky", transport=transport, retries=FAST) as c, pytest.raises(SkyfixTimeoutError):
        c.solve([[1, 2]], camera=CAM)
    assert len(seen) == 1


@pytest.mark.parametrize("status", [400, 401, 404, 413, 415, 422, 429])
def test_4xx_is_never_retried_and_carries_detail_and_field(status: int) -> None:
    body = {"detail": "camera.fov_deg: Input should be less than 180", "field": "camera.fov_deg"}
    transport, seen = scripted(httpx.Response(status, json=body), httpx.Response(200, json=OK))
    with Client("http://sky", transport=transport, retries=FAST) as c, pytest.raises(SkyfixHTTPError) as info:
        c.solve([[1, 2]], camera=CAM)
    assert len(seen) == 1
    err = info.value
    assert (err.status, err.detail, err.field) == (status, body["detail"], "camera.fov_deg")


def test_retries_exhausted_returns_the_last_error() -> None:
    transport, seen = scripted(*[httpx.Response(503, json={"detail": "busy", "field": None})] * 3)
    with Client("http://sky", transport=transport, retries=FAST) as c, pytest.raises(SkyfixHTTPError) as info:
        c.info()
    assert len(seen) == 3 and info.value.status == 503 and info.value.detail == "busy"


def test_error_bodies_of_other_shapes() -> None:
    fastapi_default = {"detail": [{"loc": ["body", "centroids", 0, 1], "msg": "not a number", "type": "x"}]}
    transport, _ = scripted(httpx.Response(422, json=fastapi_default), httpx.Response(500, text="<html>oops"),
                            httpx.Response(200, text="not json"), httpx.Response(200, json={"status": "?"}))
    with Client("http://sky", transport=transport, retries=0) as c:
        with pytest.raises(SkyfixHTTPError) as info:
            c.solve([[1, 2]], camera=CAM)
        assert (info.value.detail, info.value.field) == ("not a number", "centroids.0.1")
        with pytest.raises(SkyfixHTTPError, match="oops"):
            c.solve([[1, 2]], camera=CAM)
        with pytest.raises(SkyfixProtocolError):
            c.solve([[1, 2]], camera=CAM)
        with pytest.raises(SkyfixProtocolError):
            c.solve([[1, 2]], camera=CAM)


def test_requests_carry_key_and_image_form() -> None:
    transport, seen = scripted(httpx.Response(200, json=OK), httpx.Response(200, json=OK))
    with Client("http://sky/", api_key="k3y", transport=transport) as c:
        c.solve([[1, 2, 3]], camera="navcam", method="pyramid", id="f1")
        c.solve_image(b"\x89PNG", camera=CAM, id=3, filename="x.png")
    assert seen[0].headers["X-API-Key"] == "k3y" and seen[0].url.path == "/v1/solve"
    assert json.loads(seen[0].content) == {"id": "f1", "camera": "navcam", "centroids": [[1.0, 2.0, 3.0]],
                                           "method": "pyramid"}
    form = seen[1].content
    assert seen[1].url.path == "/v1/solve/image"
    assert b'name="image"; filename="x.png"' in form and b"image/png" in form
    assert b'"fov_deg":11.4' in form and b'name="id"' in form


def test_async_client_retries_too() -> None:
    async def main() -> str:
        calls = 0

        async def handler(request: httpx.Request) -> httpx.Response:
            nonlocal calls
            calls += 1
            if calls == 1:
                raise httpx.ConnectError("refused")
            return httpx.Response(200, json=OK)

        async with AsyncClient("http://sky", transport=httpx.MockTransport(handler), retries=FAST) as c:
            return (await c.solve([[1, 2]], camera=CAM)).status

    assert asyncio.run(main()) == "no_solution"
