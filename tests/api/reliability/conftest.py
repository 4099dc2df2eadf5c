"""A real ``skyfix serve`` (supervisor and workers) on 127.0.0.1 for the reliability tests.

``Served`` knows the supervisor's process, its workers (children running ``spawn_main``), their
resident memory, and the file the server's stderr (JSON access log lines) goes to.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

import httpx
import pytest

from ..conftest import CAMERA_SPEC, ROOT, START_TIMEOUT_S, free_port, stop_serve

CAMERAS = json.dumps({"tetra3": CAMERA_SPEC, "bench": CAMERA_SPEC})  # bench: bench_soak's frames


@dataclass
class Served:
    """A running ``skyfix serve``."""

    proc: subprocess.Popen[bytes]
    url: str
    log_path: Path

    @property
    def ws_url(self) -> str:
        return "ws" + self.url.removeprefix("http") + "/v1/stream"

    def workers(self) -> list[int]:
        """Pids of the supervisor's live worker processes."""
        return children(self.proc.pid)

    def wait_workers(self, n: int, timeout_s: float = START_TIMEOUT_S, exclude: set[int] | None = None) -> list[int]:
        """Wait until ``n`` workers (none in ``exclude``) answer ``/v1/health``; their pids."""
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            pids = [p for p in self.workers() if p not in (exclude or set())]
            if len(pids) == n and all_healthy(self.url, set(pids)):
                return pids
            time.sleep(0.2)
        raise AssertionError(f"{n} workers not serving within {timeout_s} s: {self.workers()}")

    def log_lines(self) -> list[dict]:
        out = []
        for line in self.log_path.read_text(errors="replace").splitlines():
            if line.startswith("{"):
                try:
                    out.append(json.loads(line))
                except ValueError:
                    pass
        return out


def children(pid: int) -> list[int]:
    """Worker pids: children of ``pid`` started by multiprocessing's spawn (not its resource tracker)."""
    out = []
    for d in Path("/proc").iterdir():
        if not d.name.isdigit():
            continue
        try:
            ppid = int((d / "stat").read_text().rsplit(")", 1)[1].split()[1])
            cmd = (d / "cmdline").read_bytes()
        except (OSError, IndexError, ValueError):
            continue
        if ppid == pid and b"spawn_main" in cmd:
            out.append(int(d.name))
    return sorted(out)


def rss_bytes(pid: int) -> int:
    """Resident set size of a process, bytes."""
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) * 1024
    raise RuntimeError(f"no VmRSS for {pid}")


def all_healthy(url: str, pids: set[int], tries: int = 200) -> bool:
    """True once fresh connections have reached every pid in ``pids`` with ``/v1/health`` 200."""
    seen: set[int] = set()
    for _ in range(tries):
        try:
            with httpx.Client(base_url=url, timeout=2, limits=httpx.Limits(max_keepalive_connections=0)) as c:
                r = c.get("/v1/health")
        except httpx.TransportError:
            return False
        if r.status_code != 200:
            return False
        seen.add(r.json()["pid"])
        if pids <= seen:
            return True
    return False


@contextmanager
def serve(tmp: Path, db: Path, workers: int = 1, env: dict[str, str] | None = None,
          log_level: str = "warning") -> Iterator[Served]:
    """``skyfix serve`` on a free port with ``env``; stopped (SIGTERM, then SIGKILL) on exit."""
    port = free_port()
    log_path = tmp / f"serve-{port}.log"
    clean = {k: v for k, v in os.environ.items() if not k.startswith(("SKYFIX_", "PROMETHEUS_"))}
    with open(log_path, "wb") as log:
        proc = subprocess.Popen(
            [sys.executable, "-m", "service.cli.serve", "--log-level", log_level, "--workers", str(workers),
             "--port", str(port), "--db", str(db)],
            cwd=ROOT, env={**clean, "SKYFIX_CAMERAS": CAMERAS, **(env or {})}, stdout=log, stderr=log,
            start_new_session=True)
    served = Served(proc, f"http://127.0.0.1:{port}", log_path)
    try:
        deadline = time.monotonic() + START_TIMEOUT_S
        while len(served.workers()) < workers or not all_healthy(served.url, set(served.workers())):
            if proc.poll() is not None or time.monotonic() > deadline:
                raise RuntimeError(f"skyfix serve did not start: {log_path.read_text()[-2000:]}")
            time.sleep(0.2)
        yield served
    finally:
        stop_serve(proc)


@pytest.fixture(scope="module")
def module_tmp(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return tmp_path_factory.mktemp("reliability")
