"""``auto`` on a rig over the default database: the rig method after the first pass, never on
one camera (service.core.plan.RIG_METHOD, the default set's ``rig`` member)."""

from __future__ import annotations

import pytest

from service.core.evaluate import score
from service.core.navdb import NavDatabaseSet
from service.core.pipeline import SolveOptions, solve, solve_rig
from service.core.plan import RIG_METHOD, rig_methods, search_plan
from service.core.presets import PRESETS
from service.core.sim import SimConfig, simulate_frames
from service.core.sim_rig import gf7_rig, simulate_rig_frames


def test_the_rig_method_follows_the_first_pass_on_a_rig() -> None:
    assert rig_methods(["quad", "maxangle", "multifov", "pyramid"]) == ["quad", "multifov", "maxangle", "pyramid"]
    assert rig_methods(["multifov"]) == ["multifov"]
    assert rig_methods(["quad", "pyramid"]) == ["quad", "pyramid"]


def test_one_camera_keeps_the_rig_method_where_nothing_else_serves(tmp_path) -> None:
    """A database of the rig method alone still answers one camera with it (``auto``); one
    that holds others keeps it last, as before."""
    from service.core.navdb import build_database, open_database
    from service.core.navdb.builder import BuildConfig

    cam = PRESETS["seed001"].camera
    only = open_database(build_database(tmp_path / "only", BuildConfig(
        fov_min_deg=8.0, fov_max_deg=13.0, mag_limit=5.0, methods=("multifov",))))
    plan, _ = search_plan(only, [cam], "auto", 0.5)
    assert [methods for _, methods in plan] == [["multifov"]]
    both = open_database(build_database(tmp_path / "both", BuildConfig(
        fov_min_deg=8.0, fov_max_deg=13.0, mag_limit=5.0, methods=("quad", "multifov"))))
    plan, _ = search_plan(both, [cam], "auto", 0.5)
    assert [m for _, methods in plan for m in methods] == ["quad", "multifov"]


def test_the_default_set_searches_its_rig_member_for_rigs_only(default_set_db: NavDatabaseSet) -> None:
    rig = gf7_rig()
    cameras = list(rig.cameras)
    plan, _ = search_plan(default_set_db, cameras, "auto", 0.5)
    assert any(RIG_METHOD in methods for _, methods in plan)
    one, _ = search_plan(default_set_db, cameras[:1], "auto", 0.5)
    assert all(RIG_METHOD not in methods and methods for _, methods in one)
    assert default_set_db.members["rig"] not in [m for m, _ in one]
    # one camera: the same answer as the set without its rig member would give
    p = PRESETS["seed001"]
    frame = simulate_frames(p.camera, 1, SimConfig(mag_limit=6.5, centroid_noise_px=0.5), rng=3)[0]
    sol = solve(frame.centroids, p.camera, default_set_db, options=SolveOptions(centroid_sigma_px=0.5))
    assert sol.solved and RIG_METHOD not in sol.methods_tried


@pytest.mark.slow
def test_sparse_rig_frames_are_identified_on_the_default_set(default_set_db: NavDatabaseSet) -> None:
    """GF-7's rig with stars to 5.5 Mv at 0.5 px: the frames of 4-5 stars in all, which no
    camera holds enough of alone ((2, 2), (3, 1), (3, 2), (4, 1) per camera), are identified,
    none wrong (on the set without the rig member: 13 of 52 in ``bench.bench_rig``'s 1,000)."""
    rig = gf7_rig()
    frames = simulate_rig_frames(rig, 600, SimConfig(mag_limit=5.5, centroid_noise_px=0.5), rng=11)
    opts = SolveOptions(centroid_sigma_px=0.5)
    sparse = [rf for rf in frames if sum(int((f.hip >= 0).sum()) for f in rf.frames) in (4, 5)]
    assert len(sparse) >= 15
    solved = wrong = 0
    for rf in sparse:
        sol = solve_rig(rf.inputs(rig), default_set_db, options=opts)
        if sol.solved:
            solved += 1
            wrong += not all(score(sol, f.quaternion, f.hip.tolist(), camera=c, blends=f.blends).correct
                             for c, f in enumerate(rf.frames))
    assert wrong == 0
    assert solved >= 0.95 * len(sparse), (solved, len(sparse))
