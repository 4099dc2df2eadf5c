"""Database integrity at start (issue 12): corrupt bytes, NaN star vectors and a database with
no stars are refused naming the file, by the reader, ``check_at_start`` and ``skyfix serve``."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from service.core.errors import DatabaseCorruptError, InvalidInputError
from service.core.navdb import BuildConfig, build_database, open_database
from service.core.navdb.integrity import EDGE_BYTES, check_at_start, sample_digest

CONFIG = BuildConfig(fov_max_deg=15.0, fov_min_deg=7.0, mag_limit=5.5, methods=("pyramid",), epoch=2026.0)


@pytest.fixture(scope="module")
def built(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return build_database(tmp_path_factory.mktemp("integrity") / "db", CONFIG).resolve()


@pytest.fixture
def copy(built: Path, tmp_path: Path) -> Path:
    return Path(shutil.copytree(built, tmp_path / "db"))


def flip(path: Path, offset: int) -> None:
    data = bytearray(path.read_bytes())
    data[offset] ^= 0xFF
    path.write_bytes(bytes(data))


def biggest(db: Path) -> Path:
    return max(db.glob("*.npy"), key=lambda p: p.stat().st_size)


def test_every_array_has_a_sampled_digest_that_matches(built: Path) -> None:
    manifest = json.loads((built / "manifest.json").read_text())
    assert all(spec["sample_sha256"] == sample_digest(built / spec["file"]) for spec in manifest["arrays"].values())
    check_at_start(built)


@pytest.mark.parametrize("where", ["last", "early", "first-block"])
def test_same_size_corruption_at_the_ends_is_refused_at_start(copy: Path, where: str) -> None:
    target = biggest(copy)
    assert target.stat().st_size > 4 * EDGE_BYTES
    offset = {"last": -1, "early": 1000, "first-block": EDGE_BYTES}[where]
    flip(target, offset)
    open_database(copy)  # sizes and shapes still agree: the reader alone cannot tell
    with pytest.raises(DatabaseCorruptError, match=target.name):
        check_at_start(copy)


def test_corruption_between_samples_needs_verify(copy: Path) -> None:
    target = biggest(copy)
    flip(target, EDGE_BYTES + 4096 + 100)  # between sampled blocks 0 and 1 (they are ~8 KiB apart here)
    check_at_start(copy)
    with pytest.raises(DatabaseCorruptError, match="sha256"):
        check_at_start(copy, verify_hashes=True)


def test_nan_star_vectors_are_refused_naming_the_database(copy: Path) -> None:
    vec_file = copy / "stars__vec.npy"
    vec = np.load(vec_file)
    vec[5] = np.nan
    with open(vec_file, "r+b") as fh:  # same header, same size
        np.lib.format.write_array(fh, vec, allow_pickle=False)
    with pytest.raises(DatabaseCorruptError, match=r"stars__vec\.npy: 1 of \d+ star vectors"):
        open_database(copy)


def test_a_database_without_stars_is_refused_at_build(tmp_path: Path) -> None:
    with pytest.raises(InvalidInputError, match="mag_limit"):
        build_database(tmp_path / "none", BuildConfig(fov_max_deg=15.0, fov_min_deg=7.0, mag_limit=-5.0,
                                                      methods=("pyramid",)))
    assert not (tmp_path / "none").exists()


@pytest.mark.timeout(120)  # a serve that does not refuse would run until stopped
def test_serve_refuses_a_corrupt_database_and_verify_sees_every_byte(
        copy: Path, capfd: pytest.CaptureFixture[str]) -> None:
    from service.cli import app
    from service.cli.errors import run

    target = biggest(copy)
    flip(target, EDGE_BYTES + 4096 + 100)
    assert run(app, ["serve", "--port", "0", "--db", str(copy), "--verify"]) == 2
    err = capfd.readouterr().err
    assert target.name in err and "sha256" in err and "Traceback" not in err, err
    flip(target, -1)
    assert run(app, ["serve", "--port", "0", "--db", str(copy)]) == 2
    err = capfd.readouterr().err
    assert target.name in err and "Traceback" not in err, err
    assert run(app, ["db", "build", "--out", str(copy.parent / "zero"), "--mag-limit", "-5"]) == 2
    err = capfd.readouterr().err
    assert err.strip().splitlines()[-1].startswith("skyfix: mag_limit: 0 stars") and "Traceback" not in err, err
