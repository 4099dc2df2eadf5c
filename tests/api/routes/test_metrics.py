"""GET /metrics: Prometheus text that counts what happened."""

from __future__ import annotations

import re

import httpx

from service.core.sim import SimFrame

from ..conftest import real_stars, rows


def sample(text: str, name: str, **labels: str) -> float:
    for line in text.splitlines():
        if (line.startswith(name + "{") or line.startswith(name + " ")) and all(f'{k}="{v}"' in line for k, v in labels.items()):
            return float(line.rsplit(" ", 1)[1])
    return 0.0


def test_metrics_count_requests_and_solves(client: httpx.Client, frames: list[SimFrame]) -> None:
    before = client.get("/metrics").text
    frame = next(f for f in frames if real_stars(f) >= 8)
    for _ in range(3):
        assert client.post("/v1/solve", json={"camera": "tetra3", "centroids": rows(frame)}).status_code == 200
    client.post("/v1/solve", json={"camera": "tetra3", "centroids": [[1, 2]], "method": "nope"})
    client.post("/v1/solve", json={"camera": "tetra3", "centroids": [[1, 2], [30, 40], [500, 600]]})
    r = client.get("/metrics")
    assert r.headers["content-type"].startswith("text/plain; version=0.0.4")
    after = r.text
    req = "skyfix_http_requests_total"
    assert sample(after, req, route="/v1/solve", status="200") - sample(before, req, route="/v1/solve",
                                                                         status="200") == 4
    assert sample(after, req, route="/v1/solve", status="422") - sample(before, req, route="/v1/solve",
                                                                         status="422") == 1
    solved = sum(sample(after, "skyfix_solves_total", method=m, outcome="solved") -
                 sample(before, "skyfix_solves_total", method=m, outcome="solved") for m in ("pyramid", "maxangle"))
    assert solved == 3
    outcomes = [ln for ln in after.splitlines() if ln.startswith("skyfix_solves_total{")]
    assert outcomes and all('reason="' in ln for ln in outcomes)  # the outcome when the engine gives none
    assert sample(after, "skyfix_solve_seconds_count") - sample(before, "skyfix_solve_seconds_count") == 4
    assert sample(after, "skyfix_solve_seconds_bucket", le="+Inf") == sample(after, "skyfix_solve_seconds_count")


def test_metrics_are_well_formed(client: httpx.Client) -> None:
    client.get("/no/such/path")
    text = client.get("/metrics").text
    assert 'route="unmatched"' in text and "/no/such/path" not in text  # bounded label values
    line = re.compile(r'^[a-z_]+(\{([a-z_]+="[^"]*",?)*\})? [0-9.e+-]+$')
    for ln in text.splitlines():
        assert ln.startswith("# ") or line.match(ln), ln
