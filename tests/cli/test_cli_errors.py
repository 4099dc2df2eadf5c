"""The CLI battery: every everyday mistake gets one line on stderr and a non-zero exit, never
a traceback (issue 12). Most cases run ``service.cli.errors.run`` in-process (what ``main``
runs); two run the console entry point as a subprocess for its exit status."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from service.cli import app
from service.cli.errors import run
from service.core.navdb import BuildConfig, build_database

SKYFIX = [sys.executable, "-c", "from service.cli import main; main()"]
CAM = {"width": 1024, "height": 768, "fov_deg": 11.4}


@pytest.fixture(scope="module")
def files(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    d = tmp_path_factory.mktemp("cli-errors")
    db = build_database(d / "db", BuildConfig(fov_max_deg=15.0, fov_min_deg=7.0, mag_limit=5.5,
                                              methods=("pyramid",)))
    frames = d / "frames.jsonl"
    frames.write_text(json.dumps({"id": 1, "camera": CAM, "centroids": [[1, 2], [30, 40], [500, 600]]}) + "\n")
    bad_dist = d / "dist.jsonl"
    bad_dist.write_text(json.dumps({"id": 1, "camera": {**CAM, "distortion": [0.1, 0.2, 0.0]},
                                    "centroids": [[1, 2], [30, 40], [500, 600]]}) + "\n")
    junk = d / "junk.png"
    junk.write_bytes(b"not an image at all")
    return {"db": db, "frames": frames, "dist": bad_dist, "junk": junk, "dir": d}


def cases(f: dict[str, Path]) -> dict[str, list[str]]:
    db, fr, missing = str(f["db"]), str(f["frames"]), str(f["dir"] / "missing")
    return {
        "unknown command": ["nope"],
        "solve: no argument": ["solve"],
        "solve: missing file": ["solve", missing + ".jsonl", "--db", db],
        "solve: a directory": ["solve", str(f["dir"]), "--db", db],
        "solve: missing --db": ["solve", fr, "--db", missing],
        "solve: --db not a database": ["solve", fr, "--db", str(f["dir"])],
        "solve: unknown method": ["solve", fr, "--db", db, "--method", "nope"],
        "solve: bad --sigma": ["solve", fr, "--db", db, "--sigma", "abc"],
        "solve: --workers 0": ["solve", fr, "--db", db, "--workers", "0"],
        "solve: unknown option": ["solve", fr, "--frobnicate"],
        "solve: bad distortion": ["solve", str(f["dist"]), "--db", db],
        "db info: missing": ["db", "info", missing],
        "db info: a file": ["db", "info", fr],
        "db verify: missing": ["db", "verify", missing],
        "db build: no --out": ["db", "build"],
        "db build: bad fov": ["db", "build", "--out", missing, "--fov-min", "0"],
        "db build: bad methods": ["db", "build", "--out", missing, "--methods", "nope"],
        "db build: bad mag": ["db", "build", "--out", missing, "--mag-limit", "bright"],
        "solve-image: missing file": ["solve-image", missing + ".png", "--fov", "10", "--db", db],
        "solve-image: not an image": ["solve-image", str(f["junk"]), "--fov", "10", "--db", db],
        "sim: bad --n": ["sim", "--out", missing, "--n", "0"],
        "calibrate: missing file": ["calibrate", missing + ".jsonl", "--out", missing + ".json", "--db", db],
        "serve: bad port": ["serve", "--port", "abc"],
        "serve: missing db": ["serve", "--db", missing],
        "replay: missing file": ["replay", missing + ".jsonl"],
    }


NAMES = list(cases({k: Path("x") for k in ("db", "frames", "dist", "junk", "dir")}))


@pytest.mark.parametrize("name", NAMES)
def test_every_mistake_is_one_line_and_a_non_zero_exit(
        name: str, files: dict[str, Path], capfd: pytest.CaptureFixture[str]) -> None:
    status = run(app, cases(files)[name])
    out, err = capfd.readouterr()
    lines = [line for line in err.splitlines() if line.strip()]
    assert status != 0, (out, err)
    assert "Traceback" not in err and lines, err
    # one message: rich wraps it at the console's width (80 columns under capture), nothing more
    assert len(lines) == 1 or all(len(line) >= 60 for line in lines[:-1]), err
    assert not lines[0].startswith("skyfix: ") or "Error:" not in lines[0].split(" ")[1], err  # no bare type name


def test_the_entry_point_exits_non_zero_with_one_line(files: dict[str, Path]) -> None:
    for args in (["solve", str(files["dir"] / "missing.jsonl"), "--db", str(files["dir"] / "nodb")],):
        proc = subprocess.run([*SKYFIX, *args], capture_output=True, text=True, timeout=120)
        assert proc.returncode == 2 and "Traceback" not in proc.stderr, proc.stderr
        assert len(proc.stderr.strip().splitlines()) == 1 and "nodb" in proc.stderr, proc.stderr


def test_db_info_and_verify_on_the_default_set(files: dict[str, Path], capfd: pytest.CaptureFixture[str]) -> None:
    from service.core.navdb.default import ensure_default_database

    path = ensure_default_database()
    assert run(app, ["db", "info", str(path)]) == 0
    info = json.loads(capfd.readouterr().out)
    assert info["format"] == "set" and info["members"] and all(m["n_stars"] > 0 for m in info["members"].values())
    assert run(app, ["db", "verify", str(path)]) == 0
    assert capfd.readouterr().err.startswith("OK")


def test_version(capfd: pytest.CaptureFixture[str]) -> None:
    from service import __version__

    assert run(app, ["--version"]) == 0
    assert capfd.readouterr().out.strip() == f"skyfix {__version__}"
