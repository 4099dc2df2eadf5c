"""Soak: a WebSocket stream at a fixed frame rate plus REST traffic, for minutes, against 2 workers.

    python -m bench.bench_soak --minutes 10                 # 300 frames/s on 2 streams, 20 REST/s
    python -m bench.bench_soak --minutes 1 --rate 100 --window-s 20 --out soak.json

Starts a real ``skyfix serve --workers W`` (default 2) over a small database (fields 7-15 deg,
V <= 6.5; built once in a temporary directory), then for the whole run:

- ``--streams`` WebSocket connections each send simulated 20-centroid frames (the tetra3
  camera, 0.2 px noise, one false star) on a fixed schedule, ``--rate`` frames/s in all; the
  answers are read as they come. Latency = frame sent -> its answer read.
- one REST client sends ``POST /v1/solve`` at ``--rest-rate`` requests/s, each on a new
  connection (so both workers get some).
- every second, the resident memory (RSS) of the server's whole process group (supervisor and
  workers) is sampled.

Reported per window (``--window-s``, default 60 s): frames answered, frames/s, stream p50/p99,
REST p50/p99, RSS; and over the run: frames sent / answered / lost, errors (a refused frame, a
REST status other than 200, a dropped connection), RSS growth after the first window, and the
ratio of the largest to the smallest window p99. Goal: no error, 0 lost, RSS growth < 5 %,
p99 flat within 2x.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import os
import tempfile
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path

import httpx
import numpy as np
from websockets.asyncio.client import connect

from bench.bench_service import make_payloads, served


@dataclass
class Window:
    """One window of the run."""

    t_end_s: float
    frames: int
    fps: float
    ws_p50_ms: float
    ws_p99_ms: float
    rest: int
    rest_p50_ms: float
    rest_p99_ms: float
    rss_mib: float


@dataclass
class Soak:
    """A whole run."""

    seconds: float
    rate: float
    streams: int
    rest_rate: float
    sent: int = 0
    answered: int = 0
    errors: int = 0
    rest_sent: int = 0
    rest_ok: int = 0
    windows: list[Window] = field(default_factory=list)
    rss_mib: list[tuple[float, float]] = field(default_factory=list)

    @property
    def lost(self) -> int:
        return self.sent - self.answered

    @property
    def rss_growth(self) -> float:
        """RSS at the end over RSS at the end of the first window, minus 1."""
        if not self.windows:
            return 0.0
        return self.windows[-1].rss_mib / self.windows[0].rss_mib - 1

    @property
    def p99_ratio(self) -> float:
        p99 = [w.ws_p99_ms for w in self.windows if w.frames]
        return max(p99) / min(p99) if p99 else 0.0

    def summary(self) -> dict[str, float]:
        return {"sent": self.sent, "answered": self.answered, "lost": self.lost, "errors": self.errors,
                "rest_sent": self.rest_sent, "rest_ok": self.rest_ok,
                "rss_growth_pct": round(100 * self.rss_growth, 2), "p99_ratio": round(self.p99_ratio, 2)}


def group_rss_bytes(pgid: int) -> int:
    """Resident memory of every process of a process group, bytes (Linux)."""
    total = 0
    for d in Path("/proc").glob("[0-9]*"):
        try:
            if int((d / "stat").read_text().rsplit(")", 1)[1].split()[2]) != pgid:
                continue
            status = (d / "status").read_text()
        except (OSError, IndexError, ValueError):
            continue
        for line in status.splitlines():
            if line.startswith("VmRSS:"):
                total += int(line.split()[1]) * 1024
    return total


async def _stream(url: str, payloads: list[bytes], rate: float, t_end: float, soak: Soak,
                  lat: list[tuple[float, float]], offset_s: float = 0.0) -> None:
    sent_at: dict[int, float] = {}
    async with connect(url, max_size=2**24) as ws:
        async def send() -> None:
            t0 = time.monotonic() + offset_s
            k = 0
            while (due := t0 + k / rate) < t_end:
                await asyncio.sleep(max(0.0, due - time.monotonic()))
                body = json.loads(payloads[k % len(payloads)])
                body["id"] = k
                sent_at[k] = time.monotonic()
                await ws.send(json.dumps(body))
                soak.sent += 1
                k += 1

        sender = asyncio.create_task(send())
        while not sender.done() or len(sent_at):
            try:
                msg = json.loads(await asyncio.wait_for(ws.recv(), timeout=60))
            except TimeoutError:
                if sender.done():
                    break
                continue
            t = sent_at.pop(msg.get("id"), None)
            if t is None or msg.get("status") not in ("solved", "no_solution"):
                soak.errors += 1
                continue
            now = time.monotonic()
            soak.answered += 1
            lat.append((now, now - t))
        await sender


async def _rest(url: str, payloads: list[bytes], rate: float, t_end: float, soak: Soak,
                lat: list[tuple[float, float]]) -> None:
    limits = httpx.Limits(max_keepalive_connections=0)
    async with httpx.AsyncClient(base_url=url, timeout=30, limits=limits) as client:
        t0 = time.monotonic()
        k = 0
        while (due := t0 + k / rate) < t_end:
            await asyncio.sleep(max(0.0, due - time.monotonic()))
            t = time.monotonic()
            soak.rest_sent += 1
            try:
                r = await client.post("/v1/solve", content=payloads[k % len(payloads)],
                                      headers={"content-type": "application/json"})
                ok = r.status_code == 200
            except httpx.HTTPError:
                ok = False
            soak.rest_ok += ok
            soak.errors += not ok
            lat.append((time.monotonic(), time.monotonic() - t))
            k += 1


async def _sample(pgid: int, t_start: float, t_end: float, soak: Soak) -> None:
    while time.monotonic() < t_end:
        soak.rss_mib.append((time.monotonic() - t_start, group_rss_bytes(pgid) / 2**20))
        await asyncio.sleep(1.0)


def _windows(soak: Soak, t_start: float, window_s: float, ws_lat: list[tuple[float, float]],
             rest_lat: list[tuple[float, float]]) -> list[Window]:
    out = []
    n = max(1, round(soak.seconds / window_s))
    for i in range(n):
        lo, hi = t_start + i * window_s, t_start + (i + 1) * window_s
        ws = np.array([d for t, d in ws_lat if lo <= t < hi or (i == n - 1 and t >= hi)]) * 1e3
        rs = np.array([d for t, d in rest_lat if lo <= t < hi or (i == n - 1 and t >= hi)]) * 1e3
        rss = [m for t, m in soak.rss_mib if t <= hi - t_start] or [0.0]
        out.append(Window(round(hi - t_start, 1), len(ws), round(len(ws) / window_s, 1), _pct(ws, 50),
                          _pct(ws, 99), len(rs), _pct(rs, 50), _pct(rs, 99), round(rss[-1], 1)))
    return out


def _pct(a: np.ndarray, q: float) -> float:
    return round(float(np.percentile(a, q)), 2) if len(a) else 0.0


async def soak_run(url: str, pgid: int, *, seconds: float, rate: float = 300.0, streams: int = 2,
                   rest_rate: float = 20.0, window_s: float = 60.0, payloads: list[bytes] | None = None) -> Soak:
    """Drive the server at ``url`` (process group ``pgid``) for ``seconds``; the measurements."""
    payloads = payloads or make_payloads(300, 2026, "auto")
    soak = Soak(seconds, rate, streams, rest_rate)
    ws_url = "ws" + url.removeprefix("http") + "/v1/stream"
    ws_lat: list[tuple[float, float]] = []
    rest_lat: list[tuple[float, float]] = []
    t_start = time.monotonic()
    t_end = t_start + seconds
    tasks = [_stream(ws_url, payloads, rate / streams, t_end, soak, ws_lat, offset_s=j / rate)
             for j in range(streams)]  # staggered: the streams' frames together are evenly spaced
    results = await asyncio.gather(*tasks, _rest(url, payloads, rest_rate, t_end, soak, rest_lat),
                                   _sample(pgid, t_start, t_end, soak), return_exceptions=True)
    soak.errors += sum(isinstance(r, BaseException) for r in results)
    soak.windows = _windows(soak, t_start, window_s, ws_lat, rest_lat)
    return soak


def markdown(soak: Soak) -> str:
    rows = ["| until s | frames | frames/s | stream p50 ms | stream p99 ms | REST | REST p50 ms | REST p99 ms | RSS MiB |",
            "|---:|---:|---:|---:|---:|---:|---:|---:|---:|"]
    for w in soak.windows:
        rows.append(f"| {w.t_end_s:g} | {w.frames} | {w.fps} | {w.ws_p50_ms} | {w.ws_p99_ms} | {w.rest} | "
                    f"{w.rest_p50_ms} | {w.rest_p99_ms} | {w.rss_mib} |")
    return "\n".join(rows) + "\n\n" + json.dumps(soak.summary())


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--minutes", type=float, default=10.0)
    ap.add_argument("--rate", type=float, default=300.0, help="stream frames/s, all streams together")
    ap.add_argument("--streams", type=int, default=2)
    ap.add_argument("--rest-rate", type=float, default=20.0, help="REST requests/s")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--window-s", type=float, default=60.0)
    ap.add_argument("--out", type=Path, help="write the measurements as JSON here")
    args = ap.parse_args()

    from service.core.navdb import BuildConfig, build_database

    with tempfile.TemporaryDirectory(prefix="skyfix-soak-") as tmp:
        db = build_database(Path(tmp) / "db", BuildConfig(fov_max_deg=15.0, fov_min_deg=7.0, mag_limit=6.5,
                                                          methods=("pyramid", "maxangle")))
        with served(args.workers, db) as server:
            soak = asyncio.run(soak_run(server.url, server.pgid, seconds=args.minutes * 60, rate=args.rate,
                                        streams=args.streams, rest_rate=args.rest_rate, window_s=args.window_s))
    print(f"soak: {args.minutes:g} min, {args.rate:g} frames/s on {args.streams} streams + {args.rest_rate:g} "
          f"REST/s, {args.workers} workers, load average {os.getloadavg()[0]:.1f}")
    print(markdown(soak))
    if args.out:
        args.out.write_text(json.dumps({**asdict(soak), "summary": soak.summary()}, indent=1))


if __name__ == "__main__":
    main()
