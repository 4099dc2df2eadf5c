"""The bad-input battery: every bad request gets a 4xx naming the field; the server carries on."""

from __future__ import annotations

import json
from collections.abc import Iterator
from typing import Any

import cv2
import httpx
import numpy as np
import pytest

from client.models import ErrorResponse
from service.api.errors import dotted
from service.core.sim import SimFrame

from .conftest import CAMERA_SPEC, LiveServer, angle_deg, real_stars, rows

CENTROIDS = [[100.0, 200.0, 5.0], [300.5, 400.25, 4.0], [700.0, 100.0, 3.0]]
OK = {"camera": "tetra3", "centroids": CENTROIDS}


def post_json(body: Any) -> dict[str, Any]:
    return {"content": body if isinstance(body, bytes | str) else json.dumps(body),
            "headers": {"content-type": "application/json"}}


def png(width: int, height: int) -> bytes:
    return cv2.imencode(".png", np.zeros((height, width), np.uint8))[1].tobytes()


def chunks(n: int, size: int = 64 * 1024) -> Iterator[bytes]:
    for _ in range(n):
        yield b" " * size


JSON_CASES: list[tuple[str, Any, int, str]] = [
    ("malformed JSON", b'{"camera": "tetra3", "centroids": [[1, 2]', 400, "body"),
    ("not an object", [1, 2, 3], 422, "body"),
    ("NaN", b'{"camera": "tetra3", "centroids": [[1, NaN]]}', 422, "centroids.0.1"),
    ("Infinity", b'{"camera": "tetra3", "centroids": [[Infinity, 1]]}', 422, "centroids.0.0"),
    ("huge float", b'{"camera": "tetra3", "centroids": [[1e999, 1]]}', 422, "centroids.0.0"),
    ("string coordinate", {**OK, "centroids": [["a", 1]]}, 422, "centroids.0.0"),
    ("short row", {**OK, "centroids": [[1]]}, 422, "centroids.0"),
    ("long row", {**OK, "centroids": [[1, 2, 3, 4]]}, 422, "centroids.0"),
    ("too many centroids", {**OK, "centroids": [[1, 2]] * 501}, 422, "centroids"),
    ("over the hard cap", {**OK, "centroids": [[1, 2]] * 10_001}, 422, "centroids"),
    ("negative width", {**OK, "camera": {**CAMERA_SPEC, "width": -5}}, 422, "camera.width"),
    ("absurd width", {**OK, "camera": {**CAMERA_SPEC, "width": 10**12}}, 422, "camera.width"),
    ("zero fov", {**OK, "camera": {**CAMERA_SPEC, "fov_deg": 0}}, 422, "camera.fov_deg"),
    ("two focal lengths", {**OK, "camera": {**CAMERA_SPEC, "f_px": 1000}}, 422, "camera"),
    ("fov above what the engine takes", {**OK, "camera": {**CAMERA_SPEC, "fov_deg": 175}}, 422, "camera.fov_deg"),
    ("unknown camera name", {**OK, "camera": "../../etc/passwd"}, 422, "camera"),
    ("unknown method", {**OK, "method": "astrometry"}, 422, "method"),
    ("method too long", {**OK, "method": "x" * 100}, 422, "method"),
    ("unknown field", {**OK, "file": "/etc/passwd"}, 422, "file"),
    ("no camera", {"centroids": CENTROIDS}, 422, "body"),
    ("camera and cameras", {**OK, "cameras": [OK]}, 422, "body"),
    ("zero quaternion hint", {**OK, "attitude_hint": {"quaternion": [0, 0, 0, 0]}}, 422, "attitude_hint.quaternion"),
    ("3-element hint", {**OK, "attitude_hint": {"quaternion": [1, 0, 0]}}, 422, "attitude_hint.quaternion"),
    ("negative hint radius", {**OK, "attitude_hint": {"quaternion": [1, 0, 0, 0], "radius_deg": -1}}, 422,
     "attitude_hint.radius_deg"),
    ("epoch out of range", {**OK, "epoch": 3000}, 422, "epoch"),
    ("rig camera unknown", {"cameras": [{"camera": "tetra3", "centroids": CENTROIDS},
                                        {"camera": "nope", "centroids": CENTROIDS}]}, 422, "cameras.1.camera"),
    ("rig bad mounting", {"cameras": [{"camera": {**CAMERA_SPEC, "mounting_quaternion": [2, 0, 0, 0]},
                                       "centroids": CENTROIDS}]}, 422, "cameras.0.camera.mounting_quaternion"),
    ("rig NaN", {"cameras": [{"camera": "tetra3", "centroids": [[1, 2], [3, float("inf")]]}]}, 422,
     "cameras.0.centroids.1.1"),
    ("empty rig", {"cameras": []}, 422, "cameras"),
]


@pytest.mark.parametrize(("case", "body", "status", "field"), JSON_CASES, ids=[c[0] for c in JSON_CASES])
def test_bad_json_request(client: httpx.Client, case: str, body: Any, status: int, field: str) -> None:
    if isinstance(body, dict):
        body = json.dumps(body, allow_nan=True)
    r = client.post("/v1/solve", **post_json(body))
    assert r.status_code == status, r.text
    err = ErrorResponse.model_validate(r.json())
    assert err.field == field, r.text
    assert err.detail


@pytest.mark.parametrize(("content_type", "status"), [
    ("text/plain", 415), (None, 415), ("multipart/form-data; boundary=x", 415), ("application/json", 200),
    ("application/vnd.skyfix+json", 200), ("application/json; charset=utf-8", 200)])
def test_content_type(client: httpx.Client, content_type: str | None, status: int) -> None:
    headers = {} if content_type is None else {"content-type": content_type}
    r = client.post("/v1/solve", content=json.dumps(OK), headers=headers)
    assert r.status_code == status, r.text
    if status == 415:
        assert r.json()["field"] == "content-type"


def test_body_limit_on_content_length(client: httpx.Client, settings: Any) -> None:
    r = client.post("/v1/solve", **post_json(b" " * (settings.max_body_bytes + 1)))
    assert (r.status_code, r.json()["field"]) == (413, "body")


def test_body_limit_while_streaming_a_chunked_body(client: httpx.Client, settings: Any) -> None:
    # no Content-Length: the limit is enforced as the chunks arrive, not after reading them all
    r = client.post("/v1/solve", content=chunks(settings.max_body_bytes // (64 * 1024) + 2),
                    headers={"content-type": "application/json"})
    assert r.request.headers.get("transfer-encoding") == "chunked"
    assert (r.status_code, r.json()["field"]) == (413, "body")


IMAGE_CASES: list[tuple[str, dict[str, Any], dict[str, Any], int, str]] = [
    ("corrupt image", {"image": ("x.png", b"\x89PNG\r\n\x1a\n" + b"\x00" * 50, "image/png")}, {"fov_deg": "10"},
     422, "image"),
    ("unsupported format", {"image": ("x.gif", b"GIF89a" + b"\x00" * 50, "image/gif")}, {"fov_deg": "10"},
     422, "image"),
    ("empty image", {"image": ("x.png", b"", "image/png")}, {"fov_deg": "10"}, 422, "image"),
    ("no image", {"other": ("x", b"1", "text/plain")}, {"fov_deg": "10"}, 422, "image"),
    ("no camera", {"image": ("x.png", png(64, 48), "image/png")}, {}, 422, "camera"),
    ("camera size differs", {"image": ("x.png", png(64, 48), "image/png")}, {"camera": "tetra3"}, 422,
     "camera.width"),
    ("camera bad JSON", {"image": ("x.png", png(64, 48), "image/png")}, {"camera": "{nope"}, 422, "camera"),
    ("camera JSON invalid", {"image": ("x.png", png(64, 48), "image/png")},
     {"camera": json.dumps({"width": 64, "height": 48})}, 422, "camera"),
    ("unknown camera", {"image": ("x.png", png(64, 48), "image/png")}, {"camera": "/etc/passwd"}, 422, "camera"),
    ("negative fov", {"image": ("x.png", png(64, 48), "image/png")}, {"fov_deg": "-4"}, 422, "fov_deg"),
    ("NaN fov", {"image": ("x.png", png(64, 48), "image/png")}, {"fov_deg": "nan"}, 422, "fov_deg"),
    ("unknown method", {"image": ("x.png", png(64, 48), "image/png")}, {"fov_deg": "10", "method": "x"}, 422,
     "method"),
    ("too many pixels", {"image": ("x.png", png(20_000, 20_000), "image/png")}, {"fov_deg": "10"}, 422, "image"),
    ("too many bytes", {"image": ("x.bin", b"\x00" * (4 * 1024 * 1024 + 1), "image/png")}, {"fov_deg": "10"},
     413, "image"),
    ("two images", {"image": ("x.png", png(64, 48), "image/png"), "image2": ("y.png", png(64, 48), "image/png")},
     {"fov_deg": "10"}, 400, "body"),
]


@pytest.mark.parametrize(("case", "files", "data", "status", "field"), IMAGE_CASES, ids=[c[0] for c in IMAGE_CASES])
def test_bad_image_request(client: httpx.Client, case: str, files: dict[str, Any], data: dict[str, Any],
                           status: int, field: str) -> None:
    r = client.post("/v1/solve/image", files=files, data=data)
    assert r.status_code == status, r.text
    assert r.json()["field"] == field, r.text


def test_image_route_wants_multipart(client: httpx.Client) -> None:
    r = client.post("/v1/solve/image", content=png(64, 48), headers={"content-type": "image/png"})
    assert (r.status_code, r.json()["field"]) == (415, "content-type")


def test_unknown_route_and_method(client: httpx.Client) -> None:
    assert client.get("/v1/nope").status_code == 404
    r = client.get("/v1/solve")
    assert r.status_code == 405 and set(r.json()) == {"detail", "field"}


def test_server_still_answers_after_the_battery(server: LiveServer, frames: list[SimFrame]) -> None:
    frame = next(f for f in frames if real_stars(f) >= 8)
    with httpx.Client(base_url=server.url) as c:
        for case in JSON_CASES:
            body = case[1] if isinstance(case[1], bytes) else json.dumps(case[1], allow_nan=True)
            assert 400 <= c.post("/v1/solve", **post_json(body)).status_code < 500
        r = c.post("/v1/solve", json={"camera": "tetra3", "centroids": rows(frame)})
    assert r.status_code == 200 and r.json()["status"] == "solved"
    assert angle_deg(r.json()["quaternion"], frame.quaternion) < 0.02


@pytest.mark.parametrize(("loc", "field"), [
    (("body", "camera", "function-after[_one_focal(), CameraSpec]", "fov_deg"), "camera.fov_deg"),
    (("body", "centroids", 3, 1), "centroids.3.1"),
    (("body", "camera", "str"), "camera"),
    (("query", "fov_deg"), "fov_deg"),
    (("body",), None),
])
def test_dotted_field_paths(loc: tuple[Any, ...], field: str | None) -> None:
    assert dotted(loc) == field
