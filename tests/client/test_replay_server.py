"""Replays against a real server: numbers checked against the truth, REST and WebSocket, the CLI
with its exit status, a server killed mid-run, and a stream resumed without duplicates."""

from __future__ import annotations

import asyncio
import json
import math
import subprocess
import sys
import threading
from pathlib import Path

import numpy as np
import pytest

from client import FrameReport, ReplayReport, Retry, read_recording
from client.recording import RecordingWriter
from client.replay import replay, replay_frames
from service.core.attitude import quat_to_matrix

from .conftest import ROOT, ServerProcess

FAST_FAIL = Retry(attempts=2, backoff_s=0.05, max_backoff_s=0.1)
PATIENT = Retry(attempts=80, backoff_s=0.05, max_backoff_s=0.25)  # ~20 s: a server restart fits


def independent_errors(q_solved: list[float], q_truth: list[float]) -> tuple[float, float]:
    """Cross-boresight and |roll| error, arcsec, with numpy matrices (not the client's code)."""
    r_err = quat_to_matrix(np.array(q_solved)) @ quat_to_matrix(np.array(q_truth)).T
    z = r_err[:, 2]
    cross = math.degrees(math.atan2(math.hypot(z[0], z[1]), z[2])) * 3600
    # remove the tilt, what is left is a rotation about z
    axis = np.cross([0.0, 0.0, 1.0], z)
    s, c = np.linalg.norm(axis), z[2]
    if s > 1e-15:
        k = axis / s
        kx = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
        swing = np.eye(3) + s * kx + (1 - c) * kx @ kx
    else:
        swing = np.eye(3)
    twist = swing.T @ r_err
    roll = math.degrees(math.atan2(twist[1, 0], twist[0, 0])) * 3600
    return cross, abs(roll)


def check_against_truth(report: ReplayReport, recording: Path) -> None:
    """Every number of the report, recomputed from the recording's truth."""
    frames = list(read_recording(recording))
    assert report.frames == len(frames) == len(report.per_frame)
    assert [f.id for f in report.per_frame] == [f.id for f in frames]
    assert report.solved + report.no_solution + report.failed == report.frames
    assert report.identification_rate == pytest.approx(report.solved / report.frames)
    crosses = []
    for rep, frame in zip(report.per_frame, frames, strict=True):
        if rep.status != "solved":
            continue
        assert frame.truth is not None and frame.truth.quaternion is not None and rep.quaternion is not None
        cross, roll = independent_errors(rep.quaternion, frame.truth.quaternion)
        assert rep.cross_boresight_arcsec == pytest.approx(cross, abs=1e-3)
        assert abs(rep.roll_arcsec or 0) == pytest.approx(roll, abs=1e-3)
        crosses.append(cross)
    assert report.cross_boresight_arcsec.n == len(crosses)
    if crosses:
        assert report.cross_boresight_arcsec.p50 == pytest.approx(float(np.percentile(crosses, 50)), abs=1e-6)
        assert report.cross_boresight_arcsec.max == pytest.approx(max(crosses), abs=1e-6)
    answered = [f.latency_ms for f in report.per_frame if f.status != "failed"]
    assert report.latency_ms.n == len(answered)
    assert report.latency_ms.p95 == pytest.approx(float(np.percentile(answered, 95)))


def test_rest_replay_of_simulated_frames(server: ServerProcess, sim_recording: Path) -> None:
    report = replay(sim_recording, url=server.url, concurrency=4)
    check_against_truth(report, sim_recording)
    assert report.transport == "rest" and report.failed == 0
    assert report.identification_rate >= 0.95
    assert report.wrong == 0 and report.hip_wrong == 0 and report.hip_checked > 10 * report.solved
    assert report.cross_boresight_arcsec.p95 is not None and report.cross_boresight_arcsec.p95 < 15
    assert report.roll_arcsec.max is not None and report.roll_arcsec.max < 300
    assert report.latency_ms.p50 is not None and report.latency_ms.p50 > 0


def test_ws_replay_at_a_fixed_rate(server: ServerProcess, sim_recording: Path) -> None:
    seen: list[FrameReport] = []
    report = replay(sim_recording, url=server.url, ws=True, rate_hz=50.0, concurrency=3,
                    on_result=seen.append)
    check_against_truth(report, sim_recording)
    assert report.transport == "ws" and report.failed == 0 and report.reconnects == 0
    assert report.identification_rate >= 0.95 and report.wrong == 0
    assert len(seen) == 40
    assert report.wall_s >= 39 / 50.0  # frame 39 was due at 0.78 s
    assert report.throughput_fps <= 52


def test_rest_replay_of_real_images(server: ServerProcess, real_recording: Path) -> None:
    """The 38 real images as centroid lists (matches.json), against the reference attitudes."""
    report = replay(real_recording, url=server.url, concurrency=2)
    check_against_truth(report, real_recording)
    assert report.failed == 0
    assert report.solved >= 30
    assert report.wrong == 0 and report.hip_wrong == 0
    assert report.cross_boresight_arcsec.p90 is not None and report.cross_boresight_arcsec.p90 < 60


def write_mixed_recording(src: Path, dest: Path) -> None:
    """20 good frames, 3 of pure noise (no solution expected) and 2 whose truth was tampered with
    (the server's answer will be right, so the replay must call it wrong)."""
    frames = list(read_recording(src))[:25]
    rng = np.random.default_rng(7)
    with RecordingWriter(dest) as rec:
        for i, frame in enumerate(frames):
            d = frame.model_dump(exclude_none=True)
            if i in (20, 21, 22):
                d["centroids"] = rng.uniform(0, 700, (12, 2)).round(2).tolist()
                d["truth"] = {"quaternion": d["truth"]["quaternion"], "hip": [None] * 12}
            if i in (23, 24):
                w, x, y, z = d["truth"]["quaternion"]
                d["truth"] = {"quaternion": [x, -w, z, -y]}  # a 180° turn about camera x
            rec.write(d)


def run_cli(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "client.cli", *args, "--quiet"], cwd=ROOT,
                          capture_output=True, text=True, timeout=120)


def test_cli_report_aem_and_exit_status(server: ServerProcess, sim_recording: Path, tmp_path: Path) -> None:
    rec = tmp_path / "mixed.jsonl"
    write_mixed_recording(sim_recording, rec)
    out = run_cli(str(rec), "--url", server.url, "--concurrency", "4", "--report", str(tmp_path / "r.json"),
                  "--aem", str(tmp_path / "a.aem"), "--min-rate", "0.7", "--max-wrong", "2")
    assert out.returncode == 0, out.stderr
    assert "identification rate" in out.stdout
    report = ReplayReport.model_validate_json((tmp_path / "r.json").read_text())
    assert report.frames == 25 and report.failed == 0
    assert set(report.wrong_ids) == {"sim-023", "sim-024"}
    assert report.bars == {"min_rate": 0.7, "max_wrong": 2, "passed": True, "missed": []}
    assert sum(f.status == "no_solution" for f in report.per_frame[20:23]) == 3
    aem = (tmp_path / "a.aem").read_text()
    data = aem[aem.index("DATA_START"):aem.index("DATA_STOP")].splitlines()[1:]
    assert len(data) == report.solved
    assert data[0].startswith("2026-03-01T12:00:00.000000")  # the recording's own frame times

    out = run_cli(str(rec), "--url", server.url, "--max-wrong", "0", "--report", str(tmp_path / "r2.json"))
    assert out.returncode == 1 and "2 wrong answers > --max-wrong 0" in out.stderr
    assert json.loads((tmp_path / "r2.json").read_text())["bars"]["passed"] is False
    out = run_cli(str(rec), "--url", server.url, "--ws", "--min-rate", "0.9")
    assert out.returncode == 1 and "identification rate" in out.stderr
    out = run_cli(str(tmp_path / "missing.jsonl"), "--url", server.url)
    assert out.returncode == 2


def test_cli_nothing_answered(tmp_path: Path, sim_recording: Path) -> None:
    from .conftest import free_port

    out = run_cli(str(sim_recording), "--url", f"http://127.0.0.1:{free_port()}", "--retries", "0")
    assert out.returncode == 3
    assert "failed 40" in out.stdout.replace("\n", " ") or "failed 40" in out.stdout


@pytest.mark.parametrize("ws", [False, True], ids=["rest", "ws"])
def test_server_killed_mid_run_fails_the_rest(own_server: ServerProcess, sim_recording: Path,
                                              ws: bool) -> None:
    frames = list(read_recording(sim_recording))

    def on_result(rep: FrameReport) -> None:
        if rep.index == 9:
            own_server.kill()

    report = asyncio.run(replay_frames(frames, url=own_server.url, ws=ws, rate_hz=100.0, retries=FAST_FAIL,
                                       timeout=5.0, on_result=on_result))
    assert report.frames == 40 and len(report.per_frame) == 40
    assert report.solved >= 9 and report.failed >= 20
    assert report.solved + report.no_solution + report.failed == 40
    assert all(f.error for f in report.per_frame if f.status == "failed")
    assert {f["id"] for f in report.failures} == {f.id for f in report.per_frame if f.status == "failed"}
    assert report.identification_rate < 0.75


def test_stream_resumes_after_a_restart_without_duplicates(own_server: ServerProcess,
                                                           sim_recording: Path) -> None:
    from client import Client, SolveRequest

    frames = list(read_recording(sim_recording))[:20]
    with Client(own_server.url, retries=PATIENT).stream() as stream:
        for f in frames:
            stream.send(SolveRequest(id=f.id, camera=f.camera, centroids=f.centroids))
        got = [stream.recv().id for _ in range(5)]
        own_server.kill()  # 15 frames sent, not answered (or answered but not read: lost)
        restart = threading.Timer(0.3, own_server.start)
        restart.start()
        got += [r.id for r in stream.results()]
        restart.join()
        assert stream.reconnects >= 1
        # only the unacknowledged ones: all 15 unless an answer reached the client before the
        # kill (how many do depends on how fast the server solves; the stream reads them)
        assert 1 <= stream.frames_resent <= 15
    assert got == [f.id for f in frames]  # each once, in order


def test_ws_replay_resumes_after_a_restart(own_server: ServerProcess, sim_recording: Path) -> None:
    frames = list(read_recording(sim_recording))
    timers: list[threading.Timer] = []

    def on_result(rep: FrameReport) -> None:
        if rep.index == 9:
            own_server.kill()
            timers.append(threading.Timer(0.2, own_server.start))
            timers[0].start()

    report = asyncio.run(replay_frames(frames, url=own_server.url, ws=True, rate_hz=100.0, concurrency=4,
                                       retries=PATIENT, on_result=on_result))
    for t in timers:
        t.join()
    assert report.reconnects >= 1
    assert report.failed == 0 and report.frames == 40
    assert sorted(f.id for f in report.per_frame) == sorted(f.id for f in frames)
    assert report.identification_rate >= 0.95


def test_rig_replay_scores_the_body_attitude(server: ServerProcess, tmp_path: Path) -> None:
    """Two cameras on one body, 90° apart: truth is the body attitude and the HIPs of both
    cameras' centroids, one camera after the other."""
    from client._attitude import quat_mul
    from service.core.attitude import random_rotations
    from service.core.camera import Camera
    from service.core.sim import SimConfig, simulate_frame

    camera = Camera.from_fov(12.0, 1024, 768)
    mounts = [(1.0, 0.0, 0.0, 0.0), (math.sqrt(0.5), math.sqrt(0.5), 0.0, 0.0)]  # body -> camera
    config = SimConfig(centroid_noise_px=0.1, max_stars=15)
    rng = np.random.default_rng(5)
    path = tmp_path / "rig.jsonl"
    with RecordingWriter(path) as rec:
        for i, q_body in enumerate(random_rotations(8, rng)):
            cams, hips = [], []
            for mount in mounts:
                sim = simulate_frame(camera, np.array(quat_mul(mount, q_body)), config, rng)
                cams.append({"camera": {**camera.to_spec(), "mounting_quaternion": list(mount)},
                             "centroids": np.column_stack([sim.centroids.xy, sim.centroids.flux]).tolist()})
                hips += [None if h < 0 else int(h) for h in sim.hip]
            truth = {"quaternion": [float(c) for c in q_body], "hip": hips}
            rec.write({"id": i, "cameras": cams, "truth": truth})
    report = replay(path, url=server.url, concurrency=2)
    check_against_truth(report, path)
    assert report.solved >= 7 and report.wrong == 0 and report.hip_wrong == 0
    assert report.cross_boresight_arcsec.max is not None and report.cross_boresight_arcsec.max < 30
    assert report.hip_checked > 15 * report.solved  # stars of both cameras were checked


@pytest.fixture(scope="module")
def image_recording(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Four real 16-bit TIFFs (tetra3), copied in beside the recording, with reference attitudes."""
    from .conftest import REAL

    if not (REAL / "truth.json").is_file():
        pytest.skip(f"real images not found in {REAL}")
    truth = json.loads((REAL / "truth.json").read_text())["images"]
    names = sorted(n for n in truth if n.startswith("tetra3/"))[:4]
    path = tmp_path_factory.mktemp("images") / "images.jsonl"
    with RecordingWriter(path) as rec:
        for i, name in enumerate(names):
            rel = rec.add_image(REAL / name)
            rec.write({"id": Path(name).stem, "time": f"2019-07-29T20:47:{26 + i:02d}Z", "image": rel,
                       "camera": {"width": 1024, "height": 768, "fov_deg": 11.425},
                       "truth": {"quaternion": truth[name]["quaternion_icrs_to_camera_wxyz"]}})
    return path


@pytest.mark.parametrize("ws", [False, True], ids=["rest", "ws"])
def test_replay_of_real_images(server: ServerProcess, image_recording: Path, ws: bool) -> None:
    import service.core.pipeline as pipeline

    if not hasattr(pipeline, "solve_image"):
        pytest.skip("the engine has no image pipeline yet")
    report = replay(image_recording, url=server.url, ws=ws, concurrency=2)
    check_against_truth(report, image_recording)
    assert report.failed == 0, report.failures
    assert report.solved >= 3 and report.wrong == 0
    assert report.cross_boresight_arcsec.max is not None and report.cross_boresight_arcsec.max < 60
