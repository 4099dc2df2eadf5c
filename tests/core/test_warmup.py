"""Warming a database up (service/core/warmup.py): nothing is left for the first requests to
compile, and a database is warmed once."""

from __future__ import annotations

import numpy as np

from service.core import pipeline, warmup
from service.core.pipeline import SolveOptions, solve
from service.core.presets import PRESETS
from service.core.sim import SimConfig, random_points, simulate_frames
from service.core.types import Centroids
from service.core.warmup import own_frames, warm_up


def _compiled_signatures() -> dict[str, int]:
    import sys

    from numba.core.registry import CPUDispatcher

    return {f"{name}.{key}": len(value.overloads) for name, module in list(sys.modules.items())
            if name.startswith("service.") for key, value in list(vars(module).items())
            if isinstance(value, CPUDispatcher)}


def test_after_warm_up_auto_compiles_nothing_more(default_set_db) -> None:
    """warm_up leaves no kernel for auto's first requests to compile (each took 0.7-4 s on a
    fresh install, past the time limit): the compiled first pass, frames of 4 and 3 stars, and
    frames the first pass cannot prove. Run alone, on an empty numba cache, this is what fails
    when warm_up misses one; in a session where other tests compiled them it passes anyway."""
    warm_up(default_set_db)
    before = _compiled_signatures()
    rng = np.random.default_rng(3)
    for key in ("seed000", "seed002", "seed004"):
        p = PRESETS[key]
        frames = [f.centroids for f in simulate_frames(p.camera, 6, SimConfig(mag_limit=p.mag_limit,
                                                                              centroid_noise_px=1.0,
                                                                              false_stars=2), rng=2)]
        frames += [Centroids(f.xy[:n], f.flux[:n]) for f in frames[:1] for n in (3, 4, 6)]
        frames += [random_points(p.camera, n, rng) for n in (5, 12, 30)]
        if key == "seed002":  # a 4-star frame (bench_wrong's, 0.25 px) that pyramid proves from a
            # triangle of one candidate: the read-only view of that candidate was a second compiled
            # signature of the screen, 1-2 s inside a request on a fresh install (session 26)
            frames.append(Centroids(np.array([[2800.29, 281.83], [628.6, 3971.0], [3220.25, 1874.79], [38.34, 89.75]]),
                                    np.array([1871.0, 1308.7, 472.8, 422.6])))
        for centroids in frames:
            solve(centroids, p.camera, default_set_db, options=SolveOptions(centroid_sigma_px=1.0))
    after = _compiled_signatures()
    assert {k: v for k, v in after.items() if v != before.get(k)} == {}


def test_warm_up_is_still_importable_from_the_pipeline() -> None:
    assert pipeline.warm_up is warmup.warm_up
    from service.core.pipeline import warm_up as from_pipeline

    assert from_pipeline is warm_up


def test_own_frames_hold_the_databases_brightest_stars(default_set_db) -> None:
    member = default_set_db.members["wide"]
    camera = PRESETS["seed003"].camera
    frames = own_frames(member, camera)  # around every 12th of the 50 brightest stars
    assert len(frames) == 5 and all(3 <= len(f) <= 20 for f in frames)
    assert all(solve(f, camera, member).solved for f in frames)  # noise-free frames of its own stars
    assert len(own_frames(member, camera, n_tries=1)) == 1


def test_map_pages_maps_every_array_file_of_the_database(default_set_db, monkeypatch) -> None:
    files = sum(f.stat().st_size for f in default_set_db.path.rglob("*.npy") if f.stat().st_size > 128)
    mapped = warmup.map_pages(default_set_db)
    assert 0.95 * files <= mapped <= files  # every array's map (a few tiny arrays are read, not mapped)
    monkeypatch.setattr(warmup.sys, "platform", "darwin")  # no MADV_POPULATE_READ: one byte read a page
    assert warmup.map_pages(default_set_db) == mapped


LOADS_SCRIPT = """
import gc, json
from numba.core.registry import CPUDispatcher
from service.core.navdb import ensure_default_database, open_database
from service.core.pipeline import SolveOptions, solve
from service.core.presets import PRESETS
from service.core.sim import SimConfig, simulate_frames
from service.core.warmup import warm_up

def loaded():
    return {f"{d.py_func.__module__}.{d.py_func.__name__}": len(d.signatures)
            for d in gc.get_objects() if isinstance(d, CPUDispatcher)}

db = open_database(ensure_default_database(build=False))
warm_up(db)
before = loaded()
p = PRESETS["seed002"]
frames = simulate_frames(p.camera, 400, SimConfig(mag_limit=p.mag_limit, centroid_noise_px=1.0), rng=5)
options = SolveOptions(centroid_sigma_px=1.0)
for f in [f for f in frames if 3 <= len(f.centroids.xy) <= 4][:40]:
    solve(f.centroids, p.camera, db, options=options)
from service.core.pipeline import solve_rig
from service.core.sim_rig import gf7_rig, simulate_rig_frames
rig = gf7_rig()
rig_frames = simulate_rig_frames(rig, 300, SimConfig(mag_limit=5.5, centroid_noise_px=0.5), rng=3)
for rf in [rf for rf in rig_frames if 3 <= sum(len(f.hip) for f in rf.frames) <= 5][:12]:
    solve_rig(rf.inputs(rig), db, options=SolveOptions(centroid_sigma_px=0.5))
after = loaded()
print(json.dumps({k: v for k, v in after.items() if v > before.get(k, 0)}))
"""


def test_a_fresh_worker_loads_no_kernel_on_its_first_sparse_frames(default_set_db) -> None:
    """In a process of its own (as a server worker is), warm_up leaves no kernel for seed 002's
    3-4-star frames to load: the unique-triangle proof's pairing (``match._match_rig``) and the
    small frame's wide screen (``screen.hits_under``) are called from Python, where a compiled
    caller's cached copy does not serve them; loaded on first use they cost a worker's first
    such frames 5-9 ms each. Nor for a rig's sparse frames: the rig proof's third-star lookup
    (``_rig_third.third_star_candidates``), which the warm-up's own rig frames need not reach.
    (In the test session's own process other tests load them first, so only a fresh process
    shows it.)"""
    import json
    import os
    import subprocess
    import sys

    from ..conftest import ROOT

    proc = subprocess.run([sys.executable, "-c", LOADS_SCRIPT], cwd=ROOT, capture_output=True, text=True,
                          timeout=600, env=dict(os.environ))
    assert proc.returncode == 0, proc.stderr[-3000:]
    assert json.loads(proc.stdout.strip().splitlines()[-1]) == {}
