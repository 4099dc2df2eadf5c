"""A real uvicorn server on loopback over a small navigation database, and simulated frames.

``live_server`` runs ``uvicorn.Server`` in a thread on a socket bound to 127.0.0.1:0 (no port
race); ``spawn_serve`` runs ``skyfix serve`` as a subprocess (for ``--workers``).
"""

from __future__ import annotations

import os
import signal
import socket
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import httpx
import numpy as np
import pytest
import uvicorn

from service.api import Settings, create_app
from service.core.camera import Camera
from service.core.navdb import BuildConfig, build_database
from service.core.sim import SimConfig, SimFrame, simulate_frames

from ..conftest import START_TIMEOUT_S

ROOT = Path(__file__).resolve().parents[2]
REAL = ROOT.parent / "shared" / "data" / "real"

CAMERA_SPEC: dict[str, Any] = {"width": 1024, "height": 768, "fov_deg": 11.4}
"""The tetra3 test camera (1024x768, 11.4 deg): simulated frames and the real TIFFs."""

API_DB_CONFIG = BuildConfig(fov_max_deg=15.0, fov_min_deg=7.0, mag_limit=6.0, methods=("pyramid", "maxangle"))


@dataclass
class LiveServer:
    """A running server: its base URL and the settings it was made with."""

    url: str
    settings: Settings
    server: uvicorn.Server
    thread: threading.Thread
    sock: socket.socket

    @property
    def ws_url(self) -> str:
        return "ws" + self.url.removeprefix("http") + "/v1/stream"

    def stop(self) -> None:
        self.server.should_exit = True
        self.thread.join(timeout=15)
        self.sock.close()


def start_server(settings: Settings) -> LiveServer:
    """``create_app(settings)`` under uvicorn in a thread, on a free loopback port."""
    sock = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    sock.bind(("127.0.0.1", 0))
    port = sock.getsockname()[1]
    config = uvicorn.Config(create_app(settings), log_level="warning", lifespan="on",
                            ws_max_size=settings.ws_max_message_bytes + 1024, ws_per_message_deflate=False,
                            ws_max_queue=4)
    server = uvicorn.Server(config)

    def run() -> None:
        try:
            server.run(sockets=[sock])
        except SystemExit:  # uvicorn exits when the lifespan startup fails
            pass

    thread = threading.Thread(target=run, daemon=True)
    thread.start()
    deadline = time.monotonic() + START_TIMEOUT_S
    while not server.started:
        if not thread.is_alive() or time.monotonic() > deadline:
            server.should_exit = True
            thread.join(timeout=15)
            sock.close()
            raise RuntimeError("uvicorn did not start")
        time.sleep(0.01)
    return LiveServer(f"http://127.0.0.1:{port}", settings, server, thread, sock)


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def spawn_serve(*args: str, env: dict[str, str] | None = None) -> subprocess.Popen[bytes]:
    """``skyfix serve ARGS`` as a subprocess (via ``python -m service.cli.serve``)."""
    return subprocess.Popen(
        [sys.executable, "-m", "service.cli.serve", "--log-level", "warning", *args],
        cwd=ROOT, env={**os.environ, **(env or {})}, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
        start_new_session=True,
    )


def stop_serve(proc: subprocess.Popen[bytes]) -> None:
    if proc.poll() is None:
        os.killpg(proc.pid, signal.SIGTERM)
    try:
        proc.communicate(timeout=15)
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGKILL)
        proc.communicate()


def wait_healthy(url: str, proc: subprocess.Popen[bytes], timeout_s: float = START_TIMEOUT_S) -> None:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if proc.poll() is not None:
            raise RuntimeError(f"skyfix serve exited {proc.returncode}: {proc.stderr.read().decode()[-2000:]}"
                               if proc.stderr else "skyfix serve exited")
        try:
            if httpx.get(url + "/v1/health", timeout=1).status_code == 200:
                return
        except httpx.TransportError:
            pass
        time.sleep(0.1)
    raise RuntimeError("skyfix serve did not become healthy")


# ---- fixtures ---------------------------------------------------------------------------------


@pytest.fixture(scope="session")
def api_db_path(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A small database (fields 7-15 deg, V <= 6.0, pyramid + maxangle), built in about a second."""
    return build_database(tmp_path_factory.mktemp("navdb") / "api", API_DB_CONFIG)


@pytest.fixture(scope="session")
def settings(api_db_path: Path) -> Settings:
    return Settings(db_path=api_db_path, cameras={"tetra3": CAMERA_SPEC, "side": {
        **CAMERA_SPEC, "mounting_quaternion": [0.7071067811865476, 0.7071067811865476, 0.0, 0.0]}},
        max_centroids=500, max_image_bytes=4 * 1024 * 1024, max_body_bytes=256 * 1024)


@pytest.fixture(scope="session")
def server(settings: Settings) -> Iterator[LiveServer]:
    live = start_server(settings)
    yield live
    live.stop()


@pytest.fixture
def client(server: LiveServer) -> Iterator[httpx.Client]:
    with httpx.Client(base_url=server.url, timeout=30) as c:
        yield c


@pytest.fixture(scope="session")
def camera() -> Camera:
    return Camera.from_spec(CAMERA_SPEC)


@pytest.fixture(scope="session")
def frames(camera: Camera, api_db_path: Path) -> list[SimFrame]:
    """150 seeded frames: 20 brightest stars, 0.2 px noise, one false star; most have >= 6 stars."""
    config = SimConfig(mag_limit=6.0, centroid_noise_px=0.2, false_stars=1, max_stars=20, epoch=2026.0)
    return simulate_frames(camera, 150, config, rng=20261122)


def rows(frame: SimFrame) -> list[list[float]]:
    """Centroid rows ``[x, y, flux]`` of a simulated frame."""
    return np.column_stack([frame.centroids.xy, frame.centroids.flux]).round(4).tolist()


def real_stars(frame: SimFrame) -> int:
    return int((frame.hip >= 0).sum())


def angle_deg(q1: list[float] | np.ndarray, q2: list[float] | np.ndarray) -> float:
    """Rotation angle between two unit quaternions, degrees (sign-agnostic)."""
    d = abs(float(np.dot(np.asarray(q1, float), np.asarray(q2, float))))
    return float(np.degrees(2 * np.arccos(min(1.0, d))))


def check_hips(result: dict[str, Any], frame: SimFrame) -> None:
    """Every identified star is the one the simulator put at that centroid."""
    assert result["stars"], "no stars identified"
    for star in result["stars"]:
        assert star["hip"] == int(frame.hip[star["centroid"]]), star


CENTROIDS_OK: dict[str, Any] = {"camera": "tetra3", "centroids": [[100.0, 200.0], [300.0, 400.0], [700.0, 100.0]]}
"""A well-formed request (no solution: three arbitrary points)."""
