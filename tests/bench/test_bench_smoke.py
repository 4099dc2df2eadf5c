"""Smoke tests: each benchmark runs end to end on a handful of frames, so the scripts can't rot.

The peers are optional (``pip install -e '.[bench]'`` for tetra3rs; ``python -m
bench.peers.cedar setup`` for cedar-solve's own venv): their tests skip when a peer is absent.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from bench import bench_methods, bench_peers, common
from service.core.navdb import build_database
from service.core.presets import PRESETS


@pytest.fixture(scope="module")
def maxangle_db(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("benchdb") / "seed000"
    build_database(path, PRESETS["seed000"].build_config(("maxangle",)))
    return path


def test_scenarios_cover_the_sweeps() -> None:
    noise = common.scenarios("seed000", "noise")
    assert [s.value for s in noise] == [0.25 * i for i in range(9)]
    assert all(s.false_stars == 2 and s.mag_noise == 0 for s in noise)
    false = common.scenarios("seed003", "false")
    assert [s.false_stars for s in false] == [0, 1, 2, 3, 4, 5]
    mag = common.scenarios("seed004", "magnoise")
    assert mag[-1].mag_noise == 1.0 and mag[-1].false_stars == 2
    a, b = (s.frames(2, 7) for s in (noise[4], noise[4]))
    assert np.array_equal(a[0].centroids.xy, b[0].centroids.xy)  # same frames for every solver


def test_judge_counts_wrong_answers() -> None:
    f = common.scenarios("seed000", "noise", [0.0])[0].frames(1, 3)[0]
    hip = f.hip.tolist()
    right = common.Answer(True, 1.0, f.quaternion.tolist(), [(i, h) for i, h in enumerate(hip) if h >= 0])
    assert not common.judge(right, f.quaternion, hip).wrong
    false_idx = hip.index(-1)
    paired = common.Answer(True, 1.0, f.quaternion.tolist(), [(false_idx, 1)])
    assert common.judge(paired, f.quaternion, hip).wrong_star
    w, x, y, z = f.quaternion
    turned = common.Answer(True, 1.0, [x, -w, z, -y], None)  # 180 deg about camera x
    assert common.judge(turned, f.quaternion, hip).wrong_attitude
    s = common.summarize([common.judge(right, f.quaternion, hip), common.judge(turned, f.quaternion, hip),
                          common.judge(common.Answer(False, 2.0), f.quaternion, hip)])
    assert s["frames"] == 3 and s["right"] == 1 and s["wrong"] == 1 and math.isclose(s["ms_median"], 1.0)


def test_bench_methods_smoke(tmp_path: Path, maxangle_db: Path) -> None:
    rc = bench_methods.main(["--camera", "seed000", "--sweep", "noise", "--values", "0.5,2", "--frames", "4",
                             "--no-solution", "2", "--methods", "maxangle,nosuchmethod", "--db", str(maxangle_db),
                             "--no-plot", "--out", str(tmp_path)])
    assert rc == 0
    data = json.loads((tmp_path / "methods-seed000-noise.json").read_text())
    methods = {r["method"] for r in data["rows"]}
    assert methods == {"maxangle"}
    assert "nosuchmethod" in data["skipped"]
    assert all(r["wrong"] == 0 for r in data["rows"])
    assert data["no_solution"]["maxangle"]["solved"] == 0
    md = (tmp_path / "methods-seed000-noise.md").read_text()
    assert "| maxangle |" in md and "98.08%" in md


def test_bench_peers_smoke(tmp_path: Path) -> None:
    pytest.importorskip("tetra3rs")
    rc = bench_peers.main(["--camera", "seed000", "--sweep", "false", "--values", "1", "--frames", "3",
                           "--skyfix", "maxangle", "--skyfix-db", "camera", "--peers", "tetra3rs,tetra3rs-0.002",
                           "--no-real", "--no-plot", "--out", str(tmp_path), "--db-dir", str(tmp_path / "db")])
    assert rc == 0
    data = json.loads((tmp_path / "peers.json").read_text())
    (row,) = data["sweeps"]
    assert set(row["solvers"]) == {"skyfix maxangle", "tetra3rs", "tetra3rs tol 0.002"}
    assert row["solvers"]["skyfix maxangle"]["wrong"] == 0
    assert "skyfix maxangle" in row["ratio"]
    assert "tetra3rs" in (tmp_path / "peers.md").read_text()


def test_cedar_worker_smoke(tmp_path: Path) -> None:
    from bench.peers import StarRows, cedar

    ok, why = cedar.available()
    if not ok:
        pytest.skip(why)
    from service.core.catalog import load_hipparcos, select_stars

    cam = PRESETS["seed004"].camera  # 20 deg: the smallest cedar database, a few seconds
    rows = StarRows.from_table(select_stars(load_hipparcos(), epoch=2026.0, mag_limit=5.0))
    worker = cedar.CedarWorker()
    try:
        rep = worker.prepare("smoke", rows, cam.fov_deg, None, 5.0, tmp_path, reuse=False)
        assert rep.build_s and rep.open_ms
        solver = cedar.CedarSolver(worker)
        frames = common.simulate_frames(cam, 3, common.SimConfig(mag_limit=5.0), rng=1)
        for fr in frames:
            a = solver.solve(fr.centroids, cam, 0.0)
            j = common.judge(a, fr.quaternion, fr.hip.tolist(), fr.blends)
            assert not j.wrong
    finally:
        worker.close()


@pytest.mark.skipif(not (common.REAL_DIR / "truth.json").is_file(), reason="real images not present")
def test_real_frames_load() -> None:
    frames = common.real_frames()
    assert len(frames) == 38
    f = frames[0]
    assert len(f.hip) == len(f.centroids) and len(f.quaternion) == 4


def test_bench_batch_smoke(tmp_path: Path, maxangle_db: Path, capsys: pytest.CaptureFixture[str]) -> None:
    from bench import bench_batch

    bench_batch.main(["--frames", "12", "--workers", "2", "--fov", "8.58", "--mag-limit", "6.5", "--noise", "0.5",
                      "--db", str(maxangle_db), "--out", str(tmp_path), "--repeat", "1"])
    out = capsys.readouterr().out
    assert "| 2 |" in out and "identified" in out and "0 wrong" in out
    saved = json.loads((tmp_path / "bench_batch.json").read_text())
    (run,) = saved["results"]
    assert saved["runs"]["2"] == [run]
    assert run["workers"] == 2 and run["frames"] == 12 and run["fps_solving"] > 0


def test_profile_stages_smoke(default_set_db, capsys: pytest.CaptureFixture[str]) -> None:
    from bench import profile_stages

    profile_stages.main(["--camera", "seed003", "--repeat", "20"])
    out = capsys.readouterr().out
    assert "| compiled first pass |" in out and "| whole solve |" in out


def test_bench_maxangle_layout_smoke(maxangle_db: Path, capsys: pytest.CaptureFixture[str]) -> None:
    from bench import bench_maxangle_layout

    bench_maxangle_layout.main(["--db", str(maxangle_db), "--frames", "3", "--passes", "1"])
    rows = [line for line in capsys.readouterr().out.splitlines() if line.startswith("| random") or
            line.startswith("| simulated")]
    assert len(rows) == 2
    for row in rows:  # both layouts return the records (a tolerance's edge aside)
        both, one_only = (int(x) for x in row.rstrip(" |").split("|")[-1].split("/"))
        assert both > 0 and one_only <= both // 1000


def test_profile_default_by_stars_smoke(default_set_db, capsys: pytest.CaptureFixture[str]) -> None:
    from bench import profile_default

    profile_default.main(["--camera", "seed002", "--frames", "30", "--random", "2", "--by-stars"])
    out = capsys.readouterr().out
    assert "seed002 random points" in out and "by centroids in the frame" in out
    shares = [float(line.split("|")[2].strip().rstrip("%")) for line in out.splitlines()
              if line.startswith("| ") and line.split("|")[1].strip().isdigit()]
    assert abs(sum(shares) - 100.0) < 1.0  # every frame counted once


def test_profile_cold_smoke(default_set_db, capsys: pytest.CaptureFixture[str]) -> None:
    from bench import profile_cold

    profile_cold.main(["--camera", "seed003", "--frames", "12", "--evict-mb", "4"])
    out = capsys.readouterr().out
    rows = {line.split("|")[1].strip(): line for line in out.splitlines() if line.startswith("| ")}
    assert {"warm", "in turn", "evicted"} <= set(rows)
    for label in ("warm", "in turn", "evicted"):  # the first pass's call is part of the solve
        solve_us, kernel_us = (float(rows[label].split("|")[k].split("/")[0]) for k in (2, 3))
        assert 0 < kernel_us < solve_us


def test_profile_kernels_names_the_kernels_that_ran(default_set_db, tmp_path: Path) -> None:
    """The perf map that bench.profile_kernels writes names the first pass's kernels where they
    lie in memory (a fresh process: the object code is kept only for kernels loaded after
    ``install``); perf itself is not needed for this."""
    import subprocess
    import sys

    from bench.profile_kernels import short_name

    assert short_name("_ZN7service4core10first_pass17first_pass_kernelB4v1") == "first_pass.first_pass_kernel"
    assert short_name("NRT_decref") == "NRT_decref"
    path = tmp_path / "kernels.map"
    code = ("from bench import profile_kernels as p; p.install()\n"
            "from service.core.navdb import ensure_default_database, open_database\n"
            "from service.core.pipeline import solve\n"
            "frames, cam, opts = p._frames('seed003', 0.5, 0, 0, 1)\n"
            "db = open_database(ensure_default_database())\n"
            "print(sum(solve(c, cam, db, options=opts).solved for c in frames[:5]))\n"
            f"print(p.write_perf_map({str(path)!r}))\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True,
                         cwd=Path(__file__).resolve().parents[2]).stdout.split()
    assert int(out[0]) >= 4 and int(out[1]) > 20
    rows = [line.split(maxsplit=2) for line in path.read_text().splitlines()]
    names = {short_name(n) for _, _, n in rows}
    assert {"first_pass.first_pass_kernel", "quad_kernel.quad_search", "NRT_decref"} <= names
    spans = sorted((int(a, 16), int(s, 16)) for a, s, _ in rows)
    assert all(s > 0 for _, s in spans)


def test_profile_kernels_refused_keeps_the_frames_that_end_unsolved(default_set_db) -> None:
    """``--refused``: of seed 002's frames with 2 false stars (about 40% refused), exactly those
    whose solve ends with no solution, in order; none at all is an error."""
    from bench.profile_kernels import _frames, refused_only
    from service.core.pipeline import solve

    frames, cam, opts = _frames("seed002", 0.5, 2, 0, 3)
    frames = frames[:40]
    solved = [solve(c, cam, default_set_db, options=opts).solved for c in frames]
    kept = refused_only(frames, solved)
    assert 0 < len(kept) == solved.count(False) < len(frames)
    assert all(not solve(c, cam, default_set_db, options=opts).solved for c in kept)
    assert [id(c) for c in kept] == [id(c) for c, ok in zip(frames, solved) if not ok]
    with pytest.raises(SystemExit):
        refused_only(frames[:1], [True])


def test_profile_kernels_stars_keeps_the_frames_of_that_many_centroids() -> None:
    """``--stars N``: exactly the frames of ``N`` centroids, in order; none at all is an error."""
    from bench.profile_kernels import of_stars

    frames = [np.zeros((n, 3)) for n in (5, 6, 7, 6, 3)]
    kept = of_stars(frames, 6)
    assert [id(c) for c in kept] == [id(frames[1]), id(frames[3])]
    with pytest.raises(SystemExit):
        of_stars(frames, 4)
