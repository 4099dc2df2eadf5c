"""Service latency and throughput on loopback: REST and WebSocket, 1..N workers, C clients.

    python -m bench.bench_service                       # workers 1 2, clients 1 4, 2000 frames
    python -m bench.bench_service --workers 2 --clients 8 --frames 5000 --window 16

Starts a real ``skyfix serve --workers W`` per worker count, sends simulated 20-centroid
frames (1024x768 px, 11.4 deg, the tetra3 camera; 0.2 px noise, one false star) and reports
frames/s and latency percentiles as a markdown table (stdout and ``--out``), plus JSON.

- REST: each client is one keep-alive HTTP/1.1 connection sending ``POST /v1/solve`` one
  after another; latency = request written -> response read. The client is a lean asyncio
  socket loop, so the numbers are the server's, not an HTTP library's.
- WebSocket: each client is one ``/v1/stream`` connection keeping ``--window`` frames in
  flight (a rig pipelining frames); latency = frame sent -> its result received, queueing in
  the window included.

The client runs on the same machine, so it competes with the server for the CPU; "server CPU
ms/frame" (user + system time of the server's processes over the run, per frame) does not
depend on that competition: cores / it is the throughput ceiling.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import os
import platform
import signal
import socket
import subprocess
import sys
import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import asdict, dataclass
from pathlib import Path

import httpx
import numpy as np
from websockets.asyncio.client import connect

ROOT = Path(__file__).resolve().parents[1]
CAMERA = {"width": 1024, "height": 768, "fov_deg": 11.4}


@dataclass
class Row:
    """One measured configuration."""

    mode: str
    workers: int
    clients: int
    window: int
    frames: int
    seconds: float
    fps: float
    p50_ms: float
    p95_ms: float
    p99_ms: float
    server_cpu_ms: float
    solved: float


def make_payloads(n: int, seed: int, method: str) -> list[bytes]:
    """``n`` simulated frames as ``SolveRequest`` JSON bytes (named camera ``bench``)."""
    from service.core.camera import Camera
    from service.core.sim import SimConfig, simulate_frames

    cam = Camera.from_spec(CAMERA)
    config = SimConfig(mag_limit=6.5, centroid_noise_px=0.2, false_stars=1, max_stars=20)
    frames = simulate_frames(cam, n, config, rng=seed)
    out = []
    for i, f in enumerate(frames):
        rows = np.column_stack([f.centroids.xy, f.centroids.flux]).round(3).tolist()
        out.append(json.dumps({"id": i, "camera": "bench", "centroids": rows, "method": method}).encode())
    return out


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def group_cpu_s(pgid: int) -> float:
    """CPU seconds (user + system) used so far by every process of a process group (Linux)."""
    total = 0
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue
        if int(fields[2]) == pgid:  # fields after "(comm)": state, ppid, pgrp, ..., utime, stime
            total += int(fields[11]) + int(fields[12])
    return total / os.sysconf("SC_CLK_TCK")


@dataclass
class Server:
    url: str
    pgid: int


@contextmanager
def served(workers: int, db: Path | None) -> Iterator[Server]:
    """``skyfix serve --workers N`` on a free loopback port, until the block ends."""
    port = free_port()
    args = [sys.executable, "-m", "service.cli.serve", "--workers", str(workers), "--port", str(port),
            "--log-level", "warning"] + (["--db", str(db)] if db else [])
    env = {**os.environ, "SKYFIX_CAMERAS": json.dumps({"bench": CAMERA}), "SKYFIX_HOST": "127.0.0.1"}
    env.pop("SKYFIX_API_KEY", None)
    proc = subprocess.Popen(args, cwd=ROOT, env=env, start_new_session=True)
    url = f"http://127.0.0.1:{port}"
    try:
        deadline = time.monotonic() + 120
        while True:
            if proc.poll() is not None:
                raise SystemExit(f"skyfix serve exited with {proc.returncode}")
            try:
                if httpx.get(url + "/v1/health", timeout=1).status_code == 200:
                    break
            except httpx.TransportError:
                pass
            if time.monotonic() > deadline:
                raise SystemExit("skyfix serve did not come up")
            time.sleep(0.1)
        time.sleep(0.5 * workers)  # let every worker finish its lifespan
        yield Server(url, proc.pid)
    finally:
        os.killpg(proc.pid, signal.SIGTERM)
        proc.wait(timeout=30)


async def _rest_client(host: str, port: int, payloads: list[bytes], lat: list[float]) -> int:
    reader, writer = await asyncio.open_connection(host, port)
    solved = 0
    try:
        for body in payloads:
            head = (f"POST /v1/solve HTTP/1.1\r\nHost: {host}\r\nContent-Type: application/json\r\n"
                    f"Content-Length: {len(body)}\r\n\r\n").encode()
            t0 = time.perf_counter()
            writer.write(head + body)
            headers = await reader.readuntil(b"\r\n\r\n")
            status = int(headers.split(b" ", 2)[1])
            length = next(int(h.split(b":", 1)[1]) for h in headers.split(b"\r\n")
                          if h.lower().startswith(b"content-length:"))
            reply = await reader.readexactly(length)
            lat.append(time.perf_counter() - t0)
            if status != 200:
                raise SystemExit(f"REST {status}: {reply[:300]!r}")
            solved += b'"status":"solved"' in reply
    finally:
        writer.close()
    return solved


async def _ws_client(url: str, payloads: list[bytes], window: int, lat: list[float]) -> int:
    sent: list[float] = []
    solved = 0
    async with connect(url, max_size=None, compression=None) as ws:
        slots = asyncio.Semaphore(window)

        async def sender() -> None:
            for body in payloads:
                await slots.acquire()
                sent.append(time.perf_counter())
                await ws.send(body.decode())

        task = asyncio.create_task(sender())
        for i in range(len(payloads)):
            reply = await ws.recv()
            lat.append(time.perf_counter() - sent[i])
            slots.release()
            text = reply if isinstance(reply, str) else reply.decode()
            if '"status"' not in text:
                raise SystemExit(f"WS error: {text[:300]}")
            solved += '"status":"solved"' in text
        await task
    return solved


async def run_mode(mode: str, url: str, payloads: list[bytes], clients: int, window: int,
                   session: str | None = None) -> tuple[float, list[float], int]:
    """Split ``payloads`` over ``clients`` connections; (seconds, latencies, solved)."""
    shares = [payloads[i::clients] for i in range(clients)]
    lat: list[float] = []
    host, port = url.removeprefix("http://").split(":")
    t0 = time.perf_counter()
    if mode == "rest":
        counts = await asyncio.gather(*(_rest_client(host, int(port), s, lat) for s in shares))
    else:
        ws_url = "ws://" + url.removeprefix("http://") + "/v1/stream" + (f"?session={session}" if session else "")
        counts = await asyncio.gather(*(_ws_client(ws_url, s, window, lat) for s in shares))
    return time.perf_counter() - t0, lat, sum(counts)


def measure(mode: str, server: Server, payloads: list[bytes], workers: int, clients: int, window: int,
            session: str | None = None) -> Row:
    url = server.url
    asyncio.run(run_mode(mode, url, payloads[: max(50, clients * 10)], clients, window, session))  # warm up
    cpu0 = group_cpu_s(server.pgid)
    seconds, lat, solved = asyncio.run(run_mode(mode, url, payloads, clients, window, session))
    cpu_ms = (group_cpu_s(server.pgid) - cpu0) * 1e3 / len(payloads)
    ms = np.asarray(lat) * 1e3
    p50, p95, p99 = (float(np.percentile(ms, q)) for q in (50, 95, 99))
    return Row(mode, workers, clients, window if mode == "ws" else 1, len(payloads), round(seconds, 3),
               round(len(payloads) / seconds, 1), round(p50, 2), round(p95, 2), round(p99, 2),
               round(cpu_ms, 3), round(solved / len(payloads), 4))


def table(rows: list[Row]) -> str:
    head = ("| mode | workers | clients | in flight / client | frames | frames/s | p50 ms | p95 ms | p99 ms "
            "| server CPU ms/frame | solved |\n|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|\n")
    return head + "".join(
        f"| {r.mode} | {r.workers} | {r.clients} | {r.window} | {r.frames} | {r.fps:.0f} | {r.p50_ms:.2f} "
        f"| {r.p95_ms:.2f} | {r.p99_ms:.2f} | {r.server_cpu_ms:.2f} | {100 * r.solved:.1f}% |\n" for r in rows)


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(prog="python -m bench.bench_service", description=__doc__.split("\n\n")[0])
    ap.add_argument("--workers", type=int, nargs="+", default=[1, 2])
    ap.add_argument("--clients", type=int, nargs="+", default=[1, 4])
    ap.add_argument("--frames", type=int, default=2000, help="frames per measurement")
    ap.add_argument("--window", type=int, default=8, help="WebSocket frames in flight per client")
    ap.add_argument("--modes", nargs="+", choices=["rest", "ws"], default=["rest", "ws"])
    ap.add_argument("--method", default="auto")
    ap.add_argument("--session", default=None, help="WebSocket: publish to this stream session (no viewer: the "
                                                    "console's cost on the stream path)")
    ap.add_argument("--db", type=Path, default=None, help="navigation database (default: the default one)")
    ap.add_argument("--seed", type=int, default=2026)
    ap.add_argument("--out", type=Path, default=ROOT / "bench" / "out" / "service.md")
    args = ap.parse_args(argv)

    payloads = make_payloads(args.frames, args.seed, args.method)
    load0 = os.getloadavg()[0]
    rows: list[Row] = []
    for workers in args.workers:
        with served(workers, args.db) as server:
            for clients in args.clients:
                for mode in args.modes:
                    rows.append(measure(mode, server, payloads, workers, clients, args.window, args.session))
                    print(table(rows[-1:]).splitlines()[-1], flush=True)
    machine = f"{platform.machine()}, {os.cpu_count()} CPUs, Python {platform.python_version()}"
    command = "python -m bench.bench_service " + " ".join(argv if argv is not None else sys.argv[1:])
    load = os.getloadavg()[0]
    report = f"`{command.strip()}` on {machine} (load average before: {load0:.2f}, after: {load:.2f})\n\n{table(rows)}"
    print("\n" + report)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(report)
    args.out.with_suffix(".json").write_text(json.dumps([asdict(r) for r in rows], indent=1))


if __name__ == "__main__":
    main()
