"""Fixtures for the client tests: a real uvicorn server on loopback, and recordings with truth.

The server runs as a subprocess (``python -m uvicorn service.api.app:create_app --factory``)
so that tests can kill it mid-run and start it again on the same port. Tests may import
``service`` (to simulate frames); the ``client`` package itself never does.
"""

from __future__ import annotations

import json
import os
import signal
import socket
import subprocess
import sys
import time
from collections.abc import Iterator
from datetime import UTC, datetime, timedelta
from pathlib import Path
from typing import Any

import httpx
import pytest

from client.recording import RecordingWriter

from ..conftest import START_TIMEOUT_S

ROOT = Path(__file__).resolve().parents[2]
REAL = Path(os.environ.get("SKYFIX_REAL_DATA", ROOT.parent / "shared" / "data" / "real"))


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


class ServerProcess:
    """A skyfix server in a subprocess: ``start``, ``kill`` (SIGKILL, no goodbye), ``restart``."""

    def __init__(self, db_path: Path, port: int | None = None, env: dict[str, str] | None = None,
                 log: Path | None = None) -> None:
        self.port = port or free_port()
        self.url = f"http://127.0.0.1:{self.port}"
        self.db_path = db_path
        self.extra_env = env or {}
        self.log = log
        self.proc: subprocess.Popen[bytes] | None = None
        self._out: Any = None

    def start(self) -> ServerProcess:
        env = {**os.environ, "SKYFIX_DB_PATH": str(self.db_path), "SKYFIX_HOST": "127.0.0.1",
               "SKYFIX_PORT": str(self.port)}
        env.pop("SKYFIX_API_KEY", None)
        env.update(self.extra_env)
        self._out = open(self.log, "ab") if self.log else None  # noqa: SIM115 - closed in kill()
        out = self._out or subprocess.DEVNULL
        self.proc = subprocess.Popen(
            [sys.executable, "-m", "uvicorn", "service.api.app:create_app", "--factory",
             "--host", "127.0.0.1", "--port", str(self.port), "--log-level", "warning"],
            cwd=ROOT, env=env, stdout=out, stderr=out,
        )
        deadline = time.monotonic() + START_TIMEOUT_S
        while time.monotonic() < deadline:
            if self.proc.poll() is not None:
                code = self.proc.returncode
                self.kill()
                tail = self.log.read_text(errors="replace")[-1500:] if self.log else ""
                raise RuntimeError(f"server exited with {code}:\n{tail}")
            try:
                if httpx.get(self.url + "/v1/health", timeout=1.0).status_code == 200:
                    return self
            except httpx.TransportError:
                pass
            time.sleep(0.05)
        self.kill()
        raise RuntimeError("server did not become healthy")

    def kill(self) -> None:
        if self.proc is not None and self.proc.poll() is None:
            self.proc.send_signal(signal.SIGKILL)
            self.proc.wait(10)
        self.proc = None
        if self._out is not None:
            self._out.close()
            self._out = None

    def restart(self) -> ServerProcess:
        self.kill()
        return self.start()


@pytest.fixture(scope="session")
def db_path() -> Path:
    from service.core.navdb import ensure_default_database

    return ensure_default_database()


@pytest.fixture(scope="session")
def server(db_path: Path, tmp_path_factory: pytest.TempPathFactory) -> Iterator[ServerProcess]:
    """One server shared by the tests that do not kill it."""
    srv = ServerProcess(db_path, log=tmp_path_factory.mktemp("server") / "server.log").start()
    yield srv
    srv.kill()


@pytest.fixture
def own_server(db_path: Path, tmp_path: Path) -> Iterator[ServerProcess]:
    """A server for one test, which may kill and restart it."""
    srv = ServerProcess(db_path, log=tmp_path / "server.log").start()
    yield srv
    srv.kill()


T0 = datetime(2026, 3, 1, 12, 0, 0, tzinfo=UTC)


@pytest.fixture(scope="session")
def sim_recording(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """40 simulated frames (12° camera, 0.2 px noise, 2 false stars each), at 10 Hz from T0."""
    from service.core.camera import Camera
    from service.core.sim import SimConfig, simulate_frames

    camera = Camera.from_fov(12.0, 1024, 768)
    frames = simulate_frames(camera, 40, SimConfig(centroid_noise_px=0.2, false_stars=2, max_stars=40),
                             rng=20260301)
    path = tmp_path_factory.mktemp("sim") / "sim.jsonl"
    with RecordingWriter(path) as rec:
        for i, frame in enumerate(frames):
            record = frame.to_record(f"sim-{i:03d}", camera)
            record["time"] = (T0 + timedelta(seconds=0.1 * i)).isoformat().replace("+00:00", "Z")
            rec.write(record)
    return path


def real_frames() -> list[dict[str, object]]:
    """One centroid frame per real image: matches.json's centroids (moved to our pixel
    convention: the centre of the top-left pixel is (0, 0)) with their HIP as truth."""
    truth = json.loads((REAL / "truth.json").read_text())["images"]
    matches = json.loads((REAL / "matches.json").read_text())["images"]
    frames = []
    for i, (name, t) in enumerate(sorted(truth.items())):
        stars = matches[name]["matches"]
        frames.append({
            "id": name,
            "time": 1_780_000_000.0 + i,
            "camera": {"width": t["width"], "height": t["height"], "fov_deg": t["fov_deg"]},
            "centroids": [[s["x"] - 0.5, s["y"] - 0.5] for s in stars],
            "truth": {"quaternion": t["quaternion_icrs_to_camera_wxyz"], "hip": [s["hip"] for s in stars]},
        })
    return frames


@pytest.fixture(scope="session")
def real_recording(tmp_path_factory: pytest.TempPathFactory) -> Path:
    if not (REAL / "truth.json").is_file():
        pytest.skip(f"real images not found in {REAL}")
    path = tmp_path_factory.mktemp("real") / "real.jsonl"
    with RecordingWriter(path) as rec:
        for frame in real_frames():
            rec.write(frame)
    return path
