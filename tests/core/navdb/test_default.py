"""The default database set serves seed 000's camera with a maxangle table that sees its whole field."""

from __future__ import annotations

from service.core.evaluate import score
from service.core.navdb import NavDatabaseSet
from service.core.pipeline import solve
from service.core.sim import SimConfig, simulate_frames
from tests.conftest import SEED000_CAMERA


def test_a_member_holds_maxangle_triangles_across_seed000s_field(default_set_db: NavDatabaseSet) -> None:
    cam = SEED000_CAMERA
    fitting = default_set_db.for_camera(cam.fov_deg, cam.diagonal_fov_deg)
    whole = [m for m in fitting
             if "maxangle" in m.tables and m.method_params("maxangle")["d_max_deg"] >= cam.diagonal_fov_deg]
    assert whole, [m.method_params("maxangle") for m in fitting]


def test_maxangle_on_the_default_database_identifies_seed000s_frames(default_set_db: NavDatabaseSet) -> None:
    """Issue 11: 1 px noise, 2 false stars, ``--method maxangle`` on the default database (was
    66% identified: the narrow member's triangles reached 3.5 deg of an 8.6-deg field). 1,000
    frames give 99.3% (docs/benchmarks.md); 150 here must give >= 97%, none wrong."""
    config = SimConfig(mag_limit=6.5, centroid_noise_px=1.0, false_stars=2)
    frames = simulate_frames(SEED000_CAMERA, 150, config, rng=21)
    solved = wrong = 0
    for f in frames:
        s = score(solve(f.centroids, SEED000_CAMERA, default_set_db, method="maxangle"), f.quaternion,
                  f.hip.tolist(), blends=f.blends)
        solved += s.solved
        wrong += s.solved and not s.correct
    assert wrong == 0 and solved >= 0.97 * len(frames)


def test_two_processes_building_the_default_database_at_once_both_get_it(tmp_path) -> None:
    """Server workers or test workers starting together on a fresh machine: one builds, the
    other waits for it (a second builder would delete the first one's staging directory)."""
    import os
    import subprocess
    import sys

    code = ("from service.core.navdb import BuildConfig, ensure_default_database, open_database; "
            "m = {'tiny': BuildConfig(fov_min_deg=10, fov_max_deg=15, mag_limit=4.0, methods=('pyramid',))}; "
            "print(sorted(open_database(ensure_default_database(members=m)).members))")
    env = {**os.environ, "SKYFIX_DB_DIR": str(tmp_path)}
    procs = [subprocess.Popen([sys.executable, "-c", code], env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                              text=True) for _ in range(2)]
    outs = [p.communicate(timeout=300) for p in procs]
    assert [p.returncode for p in procs] == [0, 0], [err[-2000:] for _, err in outs]
    assert [out.strip() for out, _ in outs] == ["['tiny']", "['tiny']"]
    published = [p for p in tmp_path.iterdir() if p.name.startswith(".default.") and p.is_dir()]
    assert len(published) == 1 and not list(tmp_path.glob(".default.tmp-*"))  # built once, nothing left half-done
