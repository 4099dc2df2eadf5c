"""skyfix reprocess on a real dask LocalCluster with worker processes."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

distributed = pytest.importorskip("distributed")

from service.cluster import plan_partitions, reprocess  # noqa: E402
from service.cluster.run import _recorded  # noqa: E402
from service.cluster.work import DatabasePlugin, solve_partition  # noqa: E402
from service.core.errors import UnknownMethodError  # noqa: E402
from service.core.sim import SimConfig, simulate_frames  # noqa: E402
from tests.conftest import SEED000_CAMERA  # noqa: E402

SKYFIX = [sys.executable, "-c", "from service.cli import main; main()"]
N = 240


@pytest.fixture(scope="module")
def recording(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("rec") / "frames.jsonl"
    frames = simulate_frames(SEED000_CAMERA, N, SimConfig(mag_limit=6.5, centroid_noise_px=0.5, false_stars=1), rng=3)
    path.write_text("".join(json.dumps(f.to_record(i, SEED000_CAMERA)) + "\n" for i, f in enumerate(frames)))
    return path


@pytest.fixture(scope="module")
def client():
    cluster = distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=":0")
    c = distributed.Client(cluster)
    yield c
    c.close()
    cluster.close()


def _outputs(out: Path) -> list[dict]:
    rows = []
    for part in sorted(out.glob("part-*.jsonl")):
        rows += [json.loads(line) for line in part.read_text().splitlines()]
    return rows


def _strip(row: dict) -> dict:
    return {k: v for k, v in row.items() if k != "timings_ms"}


def test_output_equals_skyfix_solve_frame_for_frame(tmp_path: Path, recording: Path, client, seed000_db) -> None:
    summary = reprocess([recording], tmp_path / "out", db=seed000_db.path, partition_frames=50, client=client)
    assert summary.partitions == 5 and summary.frames == N and summary.wrong == 0 and summary.errors == 0
    ours = _outputs(tmp_path / "out")
    done = subprocess.run([*SKYFIX, "solve", str(recording), "--db", str(seed000_db.path), "--workers", "1"],
                          capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    theirs = [json.loads(line) for line in done.stdout.splitlines()]
    assert [_strip(r) for r in ours] == [_strip(r) for r in theirs]
    manifest = json.loads((tmp_path / "out" / "manifest.json").read_text())
    assert [p["status"] for p in manifest["partitions"]] == ["done"] * 5
    assert sum(p["frames"] for p in manifest["partitions"]) == N
    assert [(p["first_id"], p["last_id"], p["start"]) for p in manifest["partitions"]][:2] == \
        [(0, 49, 0), (50, 99, manifest["partitions"][0]["end"])]
    assert not (tmp_path / "out" / "journal.jsonl").exists()  # folded into the manifest
    with pytest.raises(UnknownMethodError, match="dmv"):  # refused before any partition is written
        reprocess([recording], tmp_path / "dmv", db=seed000_db.path, method="dmv", client=client)
    assert not list((tmp_path / "dmv").glob("part-*"))
    with pytest.raises(ValueError, match=r"other settings \(method 'auto' there, 'maxangle' now"):
        reprocess([recording], tmp_path / "out", db=seed000_db.path, method="maxangle", partition_frames=50,
                  client=client)


def test_corrupt_frame_gets_an_error_record(tmp_path: Path, recording: Path, client, seed000_db) -> None:
    lines = recording.read_text().splitlines()[:30]
    lines[12] = '{"id": 12, "camera": {"width": 1024, "height": 1024, "fov_deg": 8}, "centroids": "garbage"}'
    lines[20] = "{not json"
    bad = tmp_path / "bad.jsonl"
    bad.write_text("\n".join(lines) + "\n")
    summary = reprocess([bad], tmp_path / "out", db=seed000_db.path, partition_frames=100, client=client)
    rows = _outputs(tmp_path / "out")
    assert len(rows) == 30 and summary.errors == 2
    assert rows[12]["status"] == "error" and rows[12]["line"] == 13 and rows[12]["field"] == "centroids"
    assert rows[20]["status"] == "error" and rows[20]["line"] == 21
    assert sum(r.get("status") == "solved" for r in rows) >= 26


def test_interrupted_run_resumes_without_redoing_verified_partitions(tmp_path: Path, recording: Path, client,
                                                                      seed000_db) -> None:
    out = tmp_path / "out"
    # the client is a separate `skyfix reprocess` on the running cluster, killed mid-run
    proc = subprocess.Popen([*SKYFIX, "reprocess", str(recording), "--out", str(out), "--cluster",
                             client.cluster.scheduler_address,
                             "--db", str(seed000_db.path), "--partition-frames", "5"],
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True)
    deadline = time.time() + 90
    done: list = []
    try:
        while time.time() < deadline:
            done = list(_recorded(out)[1].values())  # the manifest and the journal
            if len(done) >= 2 or proc.poll() is not None:
                break
            time.sleep(0.01)
    finally:
        os.killpg(proc.pid, signal.SIGKILL)  # the client; the cluster runs on
        proc.wait(timeout=30)
    assert 2 <= len(done) < 48, "the run was not interrupted mid-way"
    before = {p["output"]: (out / p["output"]).stat().st_mtime_ns for p in done}
    summary = reprocess([recording], out, db=seed000_db.path, partition_frames=5, client=client)
    assert summary.skipped >= len(done) and summary.skipped + summary.partitions == 48
    assert all((out / name).stat().st_mtime_ns == t for name, t in before.items())  # not redone
    assert sorted(r["id"] for r in _outputs(out)) == list(range(N))


def test_missing_database_on_a_worker_names_the_worker_and_path(recording: Path, tmp_path: Path, client) -> None:
    # the shared cluster's workers get a plugin for a path that does not exist (every
    # reprocess call registers its own plugin again, replacing this one)
    client.register_plugin(DatabasePlugin(str(tmp_path / "nowhere"), "0" * 64))
    part = plan_partitions([recording], 10)[0]
    with pytest.raises(RuntimeError, match=r"worker tcp://\S+: cannot use the navigation database at \S*nowhere"):
        client.submit(solve_partition, part.to_dict(), str(tmp_path), "auto", 1.0, pure=False).result(timeout=60)


# last: the cluster is left restarting the killed worker
def test_worker_killed_mid_run_leaves_every_frame_once(tmp_path: Path, recording: Path, client, seed000_db) -> None:
    out = tmp_path / "out"
    result: dict = {}
    run = threading.Thread(target=lambda: result.update(s=reprocess(
        [recording], out, db=seed000_db.path, partition_frames=10, client=client)))
    run.start()
    deadline = time.time() + 60
    while time.time() < deadline and not list(out.glob("part-*.jsonl")):
        time.sleep(0.05)
    pids = client.run(os.getpid)
    victim = sorted(pids.values())[0]
    os.kill(victim, signal.SIGKILL)  # a worker process dies with partitions in hand
    finished_at_kill = len(list(out.glob("part-*.jsonl")))
    assert run.is_alive() and finished_at_kill < N // 10, "the worker was not killed mid-run"
    run.join(timeout=120)
    assert not run.is_alive() and "s" in result
    ids = [r["id"] for r in _outputs(out)]
    assert sorted(ids) == list(range(N))  # every frame exactly once
    assert result["s"].frames == N
