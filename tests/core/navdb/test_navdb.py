import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from service.core.errors import DatabaseCorruptError, DatabaseMissingError, InvalidInputError
from service.core.navdb import BuildConfig, build_database, open_database

SMALL = BuildConfig(fov_max_deg=10.0, fov_min_deg=8.0, mag_limit=5.0, epoch=2026.0, methods=("pyramid",))


@pytest.fixture
def small_db(tmp_path: Path) -> Path:
    return build_database(tmp_path / "small", SMALL)


def test_build_open_memory_mapped(small_db: Path) -> None:
    db = open_database(small_db)
    import mmap

    base = db.stars.vec
    while isinstance(base, np.ndarray) and base.base is not None:
        base = base.base
    assert isinstance(base, mmap.mmap) and not db.stars.vec.flags.writeable  # mapped, not copied
    assert db.manifest["n_stars"] == len(db.stars) > 1000
    assert db.methods == ["pyramid"]
    np.testing.assert_allclose(np.linalg.norm(db.stars.vec, axis=1), 1.0)
    open_database(small_db, verify_hashes=True)


def test_rebuild_replaces_atomically(small_db: Path) -> None:
    first = os.readlink(small_db)
    build_database(small_db, SMALL)
    assert os.readlink(small_db) != first
    assert not (small_db.parent / first).exists()  # the old version is cleaned up
    open_database(small_db, verify_hashes=True)


def test_missing(tmp_path: Path) -> None:
    with pytest.raises(DatabaseMissingError):
        open_database(tmp_path / "nope")


def test_truncated_file_is_refused_naming_it(small_db: Path) -> None:
    f = small_db / "stars__vec.npy"
    data = f.read_bytes()
    target = small_db.resolve() / "stars__vec.npy"
    target.write_bytes(data[: len(data) // 2])
    with pytest.raises(DatabaseCorruptError, match="stars__vec.npy"):
        open_database(small_db)


def test_corrupted_bytes_caught_by_hash(small_db: Path) -> None:
    target = small_db.resolve() / "pairs__angles.npy"
    data = bytearray(target.read_bytes())
    data[-8:] = b"\x00" * 8
    target.write_bytes(bytes(data))
    open_database(small_db)  # sizes and shapes still fine
    with pytest.raises(DatabaseCorruptError, match="pairs__angles.npy"):
        open_database(small_db, verify_hashes=True)


def test_wrong_schema_and_shape_are_refused(small_db: Path) -> None:
    mpath = small_db.resolve() / "manifest.json"
    manifest = json.loads(mpath.read_text())
    manifest["arrays"]["stars/mag"]["shape"] = [3]
    mpath.write_text(json.dumps(manifest))
    with pytest.raises(DatabaseCorruptError, match="stars__mag.npy"):
        open_database(small_db)
    manifest["schema_version"] = 999
    mpath.write_text(json.dumps(manifest))
    with pytest.raises(DatabaseCorruptError, match="schema version"):
        open_database(small_db)


def test_pickled_object_array_is_refused(small_db: Path) -> None:
    target = small_db.resolve() / "stars__hip.npy"
    np.save(target, np.array([object()] * 3), allow_pickle=True)
    with pytest.raises(DatabaseCorruptError, match="stars__hip.npy"):
        open_database(small_db)


def test_killed_build_leaves_old_database_intact(small_db: Path) -> None:
    before = os.readlink(small_db)
    code = (
        "from service.core.navdb import BuildConfig, build_database\n"
        f"build_database({str(small_db)!r}, BuildConfig(fov_max_deg=14, fov_min_deg=10, mag_limit=6.5,"
        " methods=('pyramid', 'maxangle')))\n"
    )
    proc = subprocess.Popen([sys.executable, "-c", code])
    deadline = time.time() + 60
    while time.time() < deadline and not list(small_db.parent.glob(".small.tmp-*/*maxangle*")) \
            and not list(small_db.parent.glob(".small.tmp-*/stars__vec.npy")):
        time.sleep(0.01)
    assert proc.poll() is None, "the build finished before it could be killed"
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    assert os.readlink(small_db) == before
    db = open_database(small_db, verify_hashes=True)
    assert db.methods == ["pyramid"]
    # the next build clears the debris
    build_database(small_db, SMALL)
    assert not list(small_db.parent.glob(".small.tmp-*"))


def test_database_set_picks_a_member_per_camera(tmp_path: Path) -> None:
    from service.core.navdb import NavDatabaseSet, build_database_set

    narrow = BuildConfig(fov_max_deg=6.0, fov_min_deg=3.0, mag_limit=5.5, epoch=2026.0, methods=("pyramid",))
    wide = BuildConfig(fov_max_deg=30.0, fov_min_deg=6.0, mag_limit=4.5, epoch=2026.0, methods=("pyramid",))
    path = build_database_set(tmp_path / "set", {"narrow": narrow, "wide": wide})
    db = open_database(path, verify_hashes=True)
    assert isinstance(db, NavDatabaseSet)
    assert [m.path.name for m in db.for_camera(4.0, 5.0)] == ["narrow"]
    assert [m.path.name for m in db.for_camera(6.0, 6.0)] == ["narrow", "wide"]  # deepest first
    assert [m.path.name for m in db.for_camera(10.0, 14.0)] == ["wide"]
    assert [m.path.name for m in db.for_camera(40.0, 50.0)] == ["wide"]  # nearest range
    assert [m.path.name for m in db.for_camera(1.0, 1.4)] == ["narrow"]
    assert db.methods == ["pyramid"]
    # a corrupt member is refused naming its file
    (path.resolve() / "wide" / "stars__mag.npy").write_bytes(b"\x93NUMPY")
    with pytest.raises(DatabaseCorruptError, match="stars__mag.npy"):
        open_database(path)


def test_a_set_built_on_threads_equals_its_members_built_one_by_one(tmp_path: Path, monkeypatch) -> None:
    """build_database_set builds its members on a thread each (at most a core each): the same
    arrays as ``build_database`` of each member alone, a progress that only rises, and a member
    that fails fails the set with nothing published."""
    from service.core.navdb import build_database_set, builder

    members = {"narrow": BuildConfig(fov_max_deg=6.0, fov_min_deg=3.0, mag_limit=5.5, epoch=2026.0,
                                     methods=("quad", "maxangle")),
               "wide": BuildConfig(fov_max_deg=30.0, fov_min_deg=6.0, mag_limit=4.5, epoch=2026.0,
                                   methods=("quad", "pyramid"))}
    monkeypatch.setattr(builder, "usable_cores", lambda: 2)  # threads even on a 1-core runner
    seen: list[float] = []
    path = build_database_set(tmp_path / "set", members, progress=lambda stage, frac: seen.append(frac))
    assert seen == sorted(seen) and seen[-1] == 1.0 and len(seen) > 4
    for name, config in members.items():
        alone = build_database(tmp_path / name, config)
        a = json.loads((path / name / "manifest.json").read_text())["arrays"]
        b = json.loads((alone / "manifest.json").read_text())["arrays"]
        assert {k: v["sha256"] for k, v in a.items()} == {k: v["sha256"] for k, v in b.items()}
    broken = BuildConfig(fov_max_deg=30.0, fov_min_deg=6.0, mag_limit=-3.0, methods=("quad",))  # no stars
    bad = {**members, "broken": broken}
    with pytest.raises(InvalidInputError, match="mag_limit"):
        build_database_set(tmp_path / "bad", bad)
    assert not (tmp_path / "bad").exists() and not list(tmp_path.glob(".bad.*"))
