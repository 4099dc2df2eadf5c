"""The default path compiles each of its large kernels once.

numba compiles a kernel again for every new combination of argument types, and an array's
type includes whether it is writable: a memory-mapped (read-only) star table and an in-memory
copy of it make two signatures. Each costs the kernel's whole compile again (and its callees'):
a fresh install's first start spent ~75 s compiling, ~20 s of it on such duplicates. A fresh
process warms up the default database and solves frames of every kind on it; each kernel below
must then hold one signature. (A kernel called only from inside another is listed only when it
was compiled in that process: loaded from numba's cache, it lives in its caller's code. So on a
warm cache those show none, and the kernels Python calls must show exactly one.)
"""

from __future__ import annotations

import json
import os
import subprocess
import sys

from ..conftest import ROOT

KERNELS = {
    "service.core.first_pass": ["first_pass_kernel", "settle_kernel", "packed_settle_kernel", "frame_first_pass_kernel"],
    "service.core.fallback_pass": ["chain_kernel", "_chain", "_maxangle_pass"],
    "service.core.frame_chain": ["frame_chain_kernel"],
    "service.core.methods.quad_kernel": ["quad_search", "_verify"],
    "service.core.check_kernel": ["verify_pairs", "recheck_pairs", "could_pair_more"],
    "service.core.match": ["_refine", "_match_rig", "_wahba_pairs"],
    "service.core.answer": ["answer_kernel"],
    "service.core.methods.maxangle": ["_triangles_extended"],
    "service.core.methods.maxangle_search": ["search_chunks"],
}

SCRIPT = f"""
import importlib, json
import numpy as np
from service.core.navdb import ensure_default_database, open_database
from service.core.pipeline import SolveOptions, solve, solve_rig
from service.core.warmup import warm_up
from service.core.presets import PRESETS
from service.core.sim import SimConfig, random_points, simulate_frames

db = open_database(ensure_default_database(build=False))
warm_up(db)
for key in ("seed000", "seed001", "seed002"):
    p = PRESETS[key]
    options = SolveOptions(centroid_sigma_px=1.0)  # one object: the camera's set-up is kept (camera_setup)
    for f in simulate_frames(p.camera, 15, SimConfig(mag_limit=p.mag_limit, centroid_noise_px=1.0, false_stars=2), rng=4):
        solve(f.centroids, p.camera, db, options=options)
        solve(f.centroids, p.camera, db, options=SolveOptions(centroid_sigma_px=1.0))  # equal: the same set-up
        solve_rig([(f.centroids, p.camera, None)], db, options=options)  # a one-camera rig: the general path
    solve(random_points(p.camera, 25, 1), p.camera, db)
    # a retry sigma: the first pass's call alone (the chain runs in the general loop)
    solve(f.centroids, p.camera, db, options=SolveOptions(centroid_sigma_px=1.0, retry_sigma_factor=2.0))
out = {{}}
for module, names in {KERNELS!r}.items():
    m = importlib.import_module(module)
    for name in names:
        out[name] = [str(s) for s in getattr(m, name).signatures]
print(json.dumps(out))
"""


def test_the_default_path_compiles_each_kernel_once(default_set_db: object) -> None:
    proc = subprocess.run([sys.executable, "-c", SCRIPT], cwd=ROOT, capture_output=True, text=True, timeout=600,
                          env=dict(os.environ))
    assert proc.returncode == 0, proc.stderr[-3000:]
    signatures = json.loads(proc.stdout.strip().splitlines()[-1])
    assert set(signatures) == {n for names in KERNELS.values() for n in names}
    for name, sigs in signatures.items():
        assert len(sigs) <= 1, (name, sigs)
    # called from Python (quad_search no longer is on these frames: since session 18 the
    # fallbacks of a frame of more than QUERY_STARS stars run compiled too, as a small frame's did)
    for name in ("first_pass_kernel", "packed_settle_kernel", "chain_kernel", "_triangles_extended", "search_chunks",
                 "frame_first_pass_kernel", "frame_chain_kernel"):
        assert len(signatures[name]) == 1, (name, signatures[name])
