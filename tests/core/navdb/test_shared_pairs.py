"""The star-pair table shared by pyramid, triangle and multifov: built once over the union of
their limits, stored once (``pairs/``), each method reading its own rows; old-schema databases
refused, and the default one rebuilt."""

from __future__ import annotations

import dataclasses
import json
import math
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from service.core.errors import DatabaseCorruptError, DatabaseMissingError
from service.core.methods._pairs import build_pair_table
from service.core.navdb import (
    BuildConfig,
    NavDatabase,
    build_database,
    default_database_ready,
    ensure_default_database,
    open_database,
)
from service.core.navdb.default import DEFAULT_REVISION
from service.core.navdb.format import SCHEMA_VERSION
from service.core.pipeline import SolveOptions
from service.core.sim import SimConfig, simulate_frames
from tests.conftest import SEED000_CAMERA, seed000_config
from tests.core.acceptance import tally

PAIR_METHODS = ("pyramid", "triangle", "multifov")
PYRAMID_MAX_DEG = 7.0
"""pyramid's own, smaller pair limit in the test database: its rows are a prefix of the table."""
SKYFIX = [sys.executable, "-c", "from service.cli import main; main()"]


@pytest.fixture(scope="module")
def shared_db(tmp_path_factory: pytest.TempPathFactory) -> NavDatabase:
    cfg = dataclasses.replace(seed000_config(PAIR_METHODS),
                              method_params={"pyramid": {"max_angle_deg": PYRAMID_MAX_DEG}})
    return open_database(build_database(tmp_path_factory.mktemp("shared") / "seed000", cfg))


def test_one_pair_table_is_stored_for_three_methods(shared_db: NavDatabase) -> None:
    db = shared_db
    pair_files = sorted(f.name for f in db.path.iterdir() if f.name.endswith(("__pairs.npy", "__angles.npy")))
    assert pair_files == ["pairs__angles.npy", "pairs__pairs.npy"]
    pair_arrays = [n for n in db.manifest["arrays"] if n.endswith(("/pairs", "/angles"))]
    assert pair_arrays == ["pairs/pairs", "pairs/angles"]
    spec = db.manifest["shared"]["pairs"]
    n = len(db.shared["pairs"]["angles"])
    assert spec["n_pairs"] == n > 100_000 and spec["max_angle_deg"] == db.manifest["fov_max_deg"]
    vec = np.asarray(db.stars.vec)
    # the table is what build_pair_table gives for the union of the limits ...
    whole = build_pair_table(vec, math.radians(spec["max_angle_deg"]))
    assert np.array_equal(whole[0], db.shared["pairs"]["pairs"])
    assert np.array_equal(whole[1], db.shared["pairs"]["angles"])
    # ... and each method reads a view of its rows: pyramid a prefix equal to its own table
    own = build_pair_table(vec, math.radians(PYRAMID_MAX_DEG))
    assert np.array_equal(own[0], db.tables["pyramid"]["pairs"])
    assert np.array_equal(own[1], db.tables["pyramid"]["angles"])
    assert spec["rows"] == {"pyramid": [0, len(own[1])], "triangle": [0, n], "multifov": [0, n]}
    assert db.method_params("pyramid") == {"max_angle_deg": PYRAMID_MAX_DEG, "n_pairs": len(own[1])}
    for m in PAIR_METHODS:
        t = db.tables[m]
        assert np.shares_memory(t["pairs"], db.shared["pairs"]["pairs"]) and not t["angles"].flags.writeable
    assert set(db.tables["multifov"]) == {"pairs", "angles", "seg_start", "seg_coef", "seg_err"}
    assert db.tables["multifov"]["seg_start"][-1] == n  # its segment index is over its rows


def test_each_method_still_solves_on_the_shared_table(shared_db: NavDatabase) -> None:
    frames = simulate_frames(SEED000_CAMERA, 30, SimConfig(mag_limit=6.5, centroid_noise_px=0.5), rng=2000)
    for m in PAIR_METHODS:
        solved, wrong = tally(frames, SEED000_CAMERA, shared_db, m, SolveOptions(centroid_sigma_px=0.5))
        assert wrong == 0 and solved >= 29, (m, solved, wrong)


def test_cli_info_shows_and_verify_hashes_the_shared_group(shared_db: NavDatabase, tmp_path: Path) -> None:
    out = subprocess.run([*SKYFIX, "db", "info", str(shared_db.path)], capture_output=True, text=True)
    assert out.returncode == 0, out.stderr
    info = json.loads(out.stdout)
    assert info["schema_version"] == SCHEMA_VERSION
    assert set(info["shared"]["pairs"]["rows"]) == set(PAIR_METHODS) == set(info["methods"])
    # a copy with one flipped byte in the shared angles: verify names the shared file
    copy = tmp_path / "copy"
    copy.mkdir()
    for f in shared_db.path.iterdir():
        (copy / f.name).write_bytes(f.read_bytes())
    data = bytearray((copy / "pairs__angles.npy").read_bytes())
    data[-1] ^= 1
    (copy / "pairs__angles.npy").write_bytes(bytes(data))
    bad = subprocess.run([*SKYFIX, "db", "verify", str(copy)], capture_output=True, text=True)
    assert bad.returncode == 1 and "pairs__angles.npy" in bad.stderr


def test_a_database_without_pair_methods_has_no_shared_group(tmp_path: Path) -> None:
    cfg = BuildConfig(fov_max_deg=10.0, fov_min_deg=8.0, mag_limit=5.0, epoch=2026.0, methods=("dmv",))
    db = open_database(build_database(tmp_path / "dmv", cfg))
    assert db.shared == {} and db.manifest["shared"] == {} and list(db.tables) == ["dmv"]


def _set_schema(path: Path, version: int) -> None:
    """Rewrite the schema version of the database (set) at ``path`` and of its members."""
    for mpath in path.resolve().glob("**/manifest.json"):
        manifest = json.loads(mpath.read_text())
        manifest["schema_version"] = version
        mpath.write_text(json.dumps(manifest))


def test_old_schema_is_refused_naming_the_rebuild(tmp_path: Path) -> None:
    cfg = BuildConfig(fov_max_deg=10.0, fov_min_deg=8.0, mag_limit=5.0, epoch=2026.0, methods=("pyramid",))
    path = build_database(tmp_path / "old", cfg)
    _set_schema(path, 1)
    with pytest.raises(DatabaseCorruptError, match=rf"schema version 1, this skyfix reads {SCHEMA_VERSION}; rebuild"):
        open_database(path)


def test_default_database_of_an_older_schema_is_rebuilt(tmp_path: Path,
                                                       monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("SKYFIX_DB_DIR", str(tmp_path))
    small = {"only": BuildConfig(fov_max_deg=10.0, fov_min_deg=8.0, mag_limit=4.5, epoch=2026.0,
                                 methods=("pyramid",))}
    path = ensure_default_database(members=small)
    assert default_database_ready()
    first = os.readlink(path)
    _set_schema(path, SCHEMA_VERSION - 1)  # as a skyfix of the previous schema left it
    assert not default_database_ready()
    with pytest.raises(DatabaseMissingError, match="outdated"):
        ensure_default_database(build=False, members=small)
    assert ensure_default_database(members=small) == path
    assert os.readlink(path) != first and default_database_ready()
    db = open_database(path, verify_hashes=True)
    assert db.manifest["schema_version"] == SCHEMA_VERSION and "pairs" in db.members["only"].shared
    # a newer schema (a later skyfix) is not downgraded: left in place, and opening refuses it
    _set_schema(path, SCHEMA_VERSION + 1)
    second = os.readlink(path)
    assert ensure_default_database(members=small) == path and os.readlink(path) == second
    with pytest.raises(DatabaseCorruptError, match="schema version"):
        open_database(path)


def test_default_database_of_an_older_revision_is_rebuilt(tmp_path: Path,
                                                         monkeypatch: pytest.MonkeyPatch) -> None:
    """A default set built before ``DEFAULT_REVISION`` (no ``default_revision``: revision 1) is
    rebuilt on first use; a database a user built at the same schema is not touched."""
    monkeypatch.setenv("SKYFIX_DB_DIR", str(tmp_path))
    small = {"only": BuildConfig(fov_max_deg=10.0, fov_min_deg=8.0, mag_limit=4.5, epoch=2026.0,
                                 methods=("maxangle",))}
    path = ensure_default_database(members=small)
    first = os.readlink(path)
    mpath = path.resolve() / "manifest.json"
    manifest = json.loads(mpath.read_text())
    assert manifest["default_revision"] == DEFAULT_REVISION
    del manifest["default_revision"]  # as the previous skyfix wrote it
    mpath.write_text(json.dumps(manifest))
    assert not default_database_ready()
    with pytest.raises(DatabaseMissingError, match="revision 1"):
        ensure_default_database(build=False, members=small)
    assert ensure_default_database(members=small) == path and os.readlink(path) != first
    db = open_database(path, verify_hashes=True)
    assert db.manifest["default_revision"] == DEFAULT_REVISION
    assert db.members["only"].method_params("maxangle")["layout"] == "cells"
