"""``skyfix serve`` as a subprocess: refusing unsafe starts, and two workers sharing one database."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import httpx
from websockets.sync.client import connect

from service.core.sim import SimFrame

from .conftest import ROOT, angle_deg, free_port, real_stars, rows, spawn_serve, stop_serve, wait_healthy


def run_serve(*args: str, env: dict[str, str]) -> subprocess.CompletedProcess[str]:
    clean = {k: v for k, v in os.environ.items() if not k.startswith("SKYFIX_")}
    return subprocess.run([sys.executable, "-m", "service.cli.serve", *args], cwd=ROOT, env={**clean, **env},
                          capture_output=True, text=True, timeout=60)


def test_refuses_a_public_bind_without_a_key(api_db_path: Path) -> None:
    done = run_serve("--host", "0.0.0.0", "--db", str(api_db_path), env={})
    assert done.returncode == 2 and "SKYFIX_API_KEY" in done.stderr


def test_refuses_a_missing_database(tmp_path: Path) -> None:
    done = run_serve("--db", str(tmp_path / "nothing"), env={})
    assert done.returncode == 2 and "no navigation database" in done.stderr


def mapped_files(pid: int) -> set[str]:
    return {line.split()[-1] for line in Path(f"/proc/{pid}/maps").read_text().splitlines()
            if line.split()[-1].endswith(".npy")}


def test_two_workers_share_one_memory_mapped_database(api_db_path: Path, frames: list[SimFrame]) -> None:
    port = free_port()
    url = f"http://127.0.0.1:{port}"
    proc = spawn_serve("--workers", "2", "--port", str(port), "--db", str(api_db_path),
                       env={"SKYFIX_CAMERAS": json.dumps({"tetra3": {"width": 1024, "height": 768, "fov_deg": 11.4}})})
    try:
        wait_healthy(url, proc)
        pids: set[int] = set()
        for _ in range(300):  # a fresh connection each time: the kernel spreads them over the workers
            with httpx.Client(base_url=url, limits=httpx.Limits(max_keepalive_connections=0)) as c:
                pids.add(c.get("/v1/health").json()["pid"])
            if len(pids) == 2:
                break
        assert len(pids) == 2
        if Path("/proc/self/maps").is_file():
            maps = [mapped_files(pid) for pid in pids]
            assert maps[0] and maps[0] == maps[1]  # the same .npy files, mapped (shared pages) in both
            assert all(str(api_db_path.resolve()) in f for f in maps[0])

        good = [f for f in frames if real_stars(f) >= 8][:40]

        def solve(frame: SimFrame) -> float:
            with httpx.Client(base_url=url, limits=httpx.Limits(max_keepalive_connections=0)) as c:
                r = c.post("/v1/solve", json={"camera": "tetra3", "centroids": rows(frame)})
            assert r.status_code == 200 and r.json()["status"] == "solved", r.text
            return angle_deg(r.json()["quaternion"], frame.quaternion)

        with ThreadPoolExecutor(8) as pool:
            assert max(pool.map(solve, good)) < 0.05
        ws_url = url.replace("http", "ws") + "/v1/stream"
        with connect(ws_url) as a, connect(ws_url) as b:
            for i, frame in enumerate(good[:10]):
                for ws in (a, b):
                    ws.send(json.dumps({"id": i, "camera": "tetra3", "centroids": rows(frame)}))
            for ws in (a, b):
                assert [json.loads(ws.recv(timeout=30))["id"] for _ in range(10)] == list(range(10))
    finally:
        stop_serve(proc)
    assert proc.returncode is not None


def test_the_start_up_heap_is_frozen(client: httpx.Client) -> None:
    # the server runs in this process (conftest.start_server): its lifespan froze what the
    # warm-up built, so a full collection during a request does not walk it
    import gc

    assert client.get("/v1/health").status_code == 200
    assert gc.get_freeze_count() > 1000, gc.get_freeze_count()
