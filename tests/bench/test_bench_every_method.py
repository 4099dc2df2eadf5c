"""bench_every_method on a couple of frames of seed 000's camera: a table row per method, pso's
cell a refusal with its reason (issue 16)."""

from __future__ import annotations

import json
from pathlib import Path

from bench import bench_every_method


def test_bench_every_method_smoke(tmp_path: Path) -> None:
    rc = bench_every_method.main(["--camera", "seed000", "--frames", "2", "--out", str(tmp_path),
                                  "--db-dir", str(tmp_path / "db")])
    assert rc == 0
    rows = {r["method"]: r for r in json.loads((tmp_path / "every-method.json").read_text())["rows"]}
    assert set(rows) == {*bench_every_method.PUBLISHED, "auto"}
    assert rows["pso"]["refused"] == 2 and "4-deg pattern circle" in rows["pso"]["refused_why"]
    assert rows["auto"]["right"] == 2 and rows["auto"]["refused"] == 0
    md = (tmp_path / "every-method.md").read_text()
    assert "| pso | refused (its 4-deg pattern circle" in md and "| auto | 100.0% (0 wrong" in md


def test_bench_every_method_on_a_given_database(tmp_path: Path) -> None:
    from service.core.navdb import BuildConfig, build_database

    db = build_database(tmp_path / "db", BuildConfig(fov_min_deg=8.0, fov_max_deg=12.0, mag_limit=6.0,
                                                     epoch=2026.0, methods=("pso", "pyramid")))
    rc = bench_every_method.main(["--db", str(db), "--fov", "8", "--px", "512", "--mag", "6.0,5.5", "--frames", "2",
                                  "--out", str(tmp_path / "out")])
    assert rc == 0
    rows = json.loads((tmp_path / "out" / "every-method.json").read_text())["rows"]
    assert {r["camera"] for r in rows} == {"8 deg, 512 px (frames to 6 Mv", "8 deg, 512 px (frames to 5.5 Mv"}
    pso = [r for r in rows if r["method"] == "pso"]
    assert all(r["refused"] == 2 for r in pso)
