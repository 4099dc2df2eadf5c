"""One worker with small limits: connection limit, slow and hostile clients, graceful shutdown.

The server (``skyfix serve``, one worker) is shared by the tests of this module, in order; the
last one shuts it down with SIGTERM.
"""

from __future__ import annotations

import json
import os
import select
import signal
import socket
import threading
import time
from collections.abc import Iterator
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import httpx
import numpy as np
import pytest
from websockets.exceptions import ConnectionClosed
from websockets.sync.client import connect

from service.core.sim import SimFrame

from ..conftest import real_stars, rows
from .conftest import Served, rss_bytes, serve

LIMIT = 3
IN_FLIGHT = 4


@pytest.fixture(scope="module")
def small(module_tmp: Path, api_db_path: Path) -> Iterator[Served]:
    with serve(module_tmp, api_db_path, workers=1, env={
            "SKYFIX_MAX_CONNECTIONS": str(LIMIT), "SKYFIX_HEADER_TIMEOUT_S": "1",
            "SKYFIX_MAX_IN_FLIGHT": str(IN_FLIGHT)}) as s:
        yield s


@pytest.fixture(scope="module")
def good(frames: list[SimFrame]) -> list[str]:
    """Centroid frames that solve, as stream messages."""
    return [json.dumps({"id": i, "camera": "tetra3", "centroids": rows(f)})
            for i, f in enumerate(f for f in frames if real_stars(f) >= 8)]


def test_past_the_connection_limit_new_work_is_refused_and_streams_go_on(small: Served, good: list[str]) -> None:
    with connect(small.ws_url) as a, connect(small.ws_url) as b, connect(small.ws_url) as c:
        for ws in (a, b, c):
            ws.send(good[0])
            assert json.loads(ws.recv(timeout=30))["status"] == "solved"
        with connect(small.ws_url) as d:  # the fourth: accepted, then closed with 1013 and why
            with pytest.raises(ConnectionClosed) as closed:
                d.recv(timeout=10)
        assert closed.value.rcvd is not None and closed.value.rcvd.code == 1013
        assert "full" in closed.value.rcvd.reason and str(LIMIT) in closed.value.rcvd.reason
        r = httpx.post(small.url + "/v1/solve", content=good[1], headers={"content-type": "application/json"})
        assert r.status_code == 503 and r.headers["retry-after"] == "1" and "full" in r.json()["detail"]
        assert httpx.get(small.url + "/v1/health").status_code == 200  # never refused
        for i, ws in enumerate((a, b, c)):  # the open streams are not disturbed
            ws.send(good[2 + i])
            assert json.loads(ws.recv(timeout=30))["id"] == 2 + i
    deadline = time.monotonic() + 10  # the slots free up as the streams close
    while (r := httpx.post(small.url + "/v1/solve", content=good[1],
                           headers={"content-type": "application/json"})).status_code == 503:
        assert time.monotonic() < deadline
        time.sleep(0.05)
    assert r.status_code == 200
    metrics = httpx.get(small.url + "/metrics").text
    assert 'skyfix_rejected_total{kind="websocket",reason="limit"} 1.0' in metrics
    assert 'skyfix_rejected_total{kind="http",reason="limit"}' in metrics


def dribble(url: str, data: bytes, interval_s: float, limit_s: float,
            first: bytes = b"") -> tuple[bytes, int, float]:
    """Send ``data`` one byte per ``interval_s`` (after a whole request ``first`` and its answer,
    on the same keep-alive connection); (what the server answered, bytes sent, seconds)."""
    host, port = url.removeprefix("http://").split(":")
    with socket.create_connection((host, int(port))) as s:
        if first:
            s.sendall(first)
            head = b""  # the whole first answer: head and body may come in separate segments
            while b"\r\n\r\n" not in head:
                head += s.recv(4096)
            assert head.startswith(b"HTTP/1.1 200 "), head
            head, body = head.split(b"\r\n\r\n", 1)
            length = int(next(line.split(b":", 1)[1] for line in head.split(b"\r\n")
                              if line.lower().startswith(b"content-length:")))
            while len(body) < length:
                body += s.recv(4096)
        t0 = time.monotonic()
        sent = 0
        while time.monotonic() - t0 < limit_s:
            if sent < len(data):
                try:
                    s.send(data[sent:sent + 1])
                except OSError:
                    break
                sent += 1
            if select.select([s], [], [], interval_s)[0]:
                answer = b""
                while chunk := s.recv(4096):
                    answer += chunk
                return answer, sent, time.monotonic() - t0
    return b"", sent, time.monotonic() - t0


def test_slowloris_headers_are_cut_off(small: Served) -> None:
    request = b"GET /v1/health HTTP/1.1\r\nHost: 127.0.0.1\r\nUser-Agent: slow\r\n\r\n"
    with ThreadPoolExecutor(3) as pool:
        slow = pool.submit(dribble, small.url, request, 1.0, 10)  # one byte a second
        silent = pool.submit(dribble, small.url, b"", 0.2, 10)  # connects, sends nothing
        second = pool.submit(dribble, small.url, request, 1.0, 10, request)  # keep-alive, then slow
        for _ in range(5):  # others are served meanwhile
            assert httpx.get(small.url + "/v1/health").status_code == 200
        for answer, sent, seconds in (slow.result(), silent.result(), second.result()):
            assert answer.startswith(b"HTTP/1.1 408 "), answer
            assert json.loads(answer.split(b"\r\n\r\n", 1)[1])["field"] == "headers"
            assert sent < len(request) and seconds < 8  # 1 s, with room for a busy machine


def test_a_client_still_sending_when_the_limit_fires_reads_its_408(small: Served) -> None:
    # headers that never end, a byte every 20 ms: bytes are still arriving when the server gives
    # up; a plain close would answer them with a reset that can destroy the 408 (seen in CI)
    host, port = small.url.removeprefix("http://").split(":")
    for _ in range(3):
        with socket.create_connection((host, int(port))) as s:
            s.sendall(b"GET /v1/health HTTP/1.1\r\nHost: 127.0.0.1\r\nX-Pad: ")
            t0, answer = time.monotonic(), b""
            while time.monotonic() - t0 < 6:
                try:
                    s.send(b"a")
                except OSError:
                    pass  # our side was shut: the answer is what matters
                if select.select([s], [], [], 0.02)[0]:
                    while chunk := s.recv(4096):
                        answer += chunk
                    break
            assert answer.startswith(b"HTTP/1.1 408 "), answer
            assert json.loads(answer.split(b"\r\n\r\n", 1)[1])["field"] == "headers"


def wait_idle(served: Served, timeout_s: float = 15) -> None:
    """Until the server has no request or stream in progress (those of earlier tests end)."""
    deadline = time.monotonic() + timeout_s
    while "skyfix_open_connections 0.0" not in httpx.get(served.url + "/metrics").text:
        assert time.monotonic() < deadline, "connections of earlier tests still open"
        time.sleep(0.05)


def test_a_client_that_never_reads_cannot_grow_server_memory(small: Served) -> None:
    """10,000 frames of 32 kB (312 MiB) into a stream whose answers are never read."""
    junk = bytes(np.random.default_rng(5).integers(0, 256, 32 * 1024, dtype=np.uint8))  # not an image: 422
    worker = small.workers()[0]
    before = peak = rss_bytes(worker)
    pushed = 0
    with connect(small.ws_url, max_queue=1) as ws:

        def push() -> None:
            nonlocal pushed
            try:
                for _ in range(10_000):
                    ws.send(junk)
                    pushed += 1
            except ConnectionClosed:
                pass

        sender = threading.Thread(target=push, daemon=True)
        sender.start()
        t0 = time.monotonic()
        while sender.is_alive() and time.monotonic() - t0 < 20:
            peak = max(peak, rss_bytes(worker))
            time.sleep(0.05)
        seconds = time.monotonic() - t0
        ws.close_socket()
        sender.join(timeout=10)
    growth = (peak - before) / 2**20
    print(f"\nnever-reading client: {pushed} frames of 32 kB ({pushed / 32:.0f} MiB) pushed in {seconds:.1f} s; "
          f"worker RSS {before / 2**20:.1f} -> peak {peak / 2**20:.1f} MiB (+{growth:.1f})")
    assert pushed == 10_000 and growth < 24  # the server held a few frames at a time, not the 312 MiB
    wait_idle(small)
    with connect(small.ws_url) as other:  # the worker still answers others
        other.send(json.dumps({"camera": "tetra3", "centroids": [[1, 2], [30, 40], [500, 600]]}))
        assert json.loads(other.recv(timeout=10))["status"] == "no_solution"


def test_a_flood_of_frames_without_solution_does_not_starve_another_client(small: Served,
                                                                          good: list[str]) -> None:
    rng = np.random.default_rng(7)
    junk = [json.dumps({"id": i, "camera": "tetra3", "centroids": (rng.random((12, 2)) * [1024, 768]).round(2)
                        .tolist()}) for i in range(64)]
    stop = threading.Event()
    flooded = [0]

    def flood() -> None:
        with connect(small.ws_url) as ws:
            for i in range(10**6):
                if stop.is_set():
                    break
                ws.send(junk[i % len(junk)])  # at full speed: back-pressure is the only brake
                if i >= IN_FLIGHT:
                    assert json.loads(ws.recv(timeout=30))["status"] == "no_solution"
                    flooded[0] += 1

    flooder = threading.Thread(target=flood, daemon=True)
    latencies = []
    with connect(small.ws_url) as ws:
        for msg in good[:20]:  # baseline
            ws.send(msg)
            ws.recv(timeout=30)
        flooder.start()
        time.sleep(0.5)
        for msg in good[:60]:
            t0 = time.perf_counter()
            ws.send(msg)
            assert json.loads(ws.recv(timeout=30))["status"] == "solved"
            latencies.append(time.perf_counter() - t0)
    stop.set()
    flooder.join(timeout=30)
    p50, p99 = np.percentile(latencies, [50, 99]) * 1e3
    print(f"\nwell-behaved client beside a no-solution flood ({flooded[0]} junk frames answered): "
          f"p50 {p50:.1f} ms, p99 {p99:.1f} ms")
    assert flooded[0] > 0 and p99 < 2000


def test_sigterm_answers_what_was_read_closes_1001_and_finishes_rest(small: Served, good: list[str]) -> None:
    """Last test of the module: the server goes away."""
    wait_idle(small)
    body = good[1].encode()

    def slowly() -> Iterator[bytes]:  # a request body arriving over a second: in flight at SIGTERM
        step = len(body) // 10 + 1
        for i in range(0, len(body), step):
            yield body[i:i + step]
            time.sleep(0.1)

    with connect(small.ws_url) as ws, ThreadPoolExecutor(2) as pool:
        for msg in good[:IN_FLIGHT + 4]:
            ws.send(msg)
        rest = [pool.submit(httpx.post, small.url + "/v1/solve", content=slowly(), timeout=30,
                            headers={"content-type": "application/json"}) for _ in range(2)]
        deadline = time.monotonic() + 10
        while "skyfix_open_connections 3.0" not in httpx.get(small.url + "/metrics").text:  # all in flight
            assert time.monotonic() < deadline
            time.sleep(0.01)
        os.kill(small.proc.pid, signal.SIGTERM)
        answered = []
        with pytest.raises(ConnectionClosed) as closed:
            while True:
                answered.append(json.loads(ws.recv(timeout=30))["id"])
        assert [r.result().json()["status"] for r in rest] == ["solved", "solved"]  # REST in flight completes
    assert closed.value.rcvd is not None and closed.value.rcvd.code == 1001, closed.value
    assert answered == list(range(len(answered))) and len(answered) >= 1  # read frames answered, in order
    print(f"\nSIGTERM: {len(answered)} of {IN_FLIGHT + 4} frames answered before 1001")
    assert small.proc.wait(timeout=30) == 0
