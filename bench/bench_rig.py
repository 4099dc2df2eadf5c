"""Sparse rig frames (seed 001's point): rate against the number of stars in the whole frame.

    python -m bench.bench_rig --frames 1000 --mag-limit 5.5 --noise 0.5 [--method auto] [--db default]
    python -m bench.bench_rig --frames 1000 --mag-limit 5.5 --noise 0.5 --method multifov --db rig

``--false-stars`` adds false stars to every camera and ``--missing`` drops real ones (wrong
answers under stress); ``--random N`` also runs N random-point rig frames of 3-6 points (none
may be identified). With ``--method multifov`` the 3-star frames are also offered to multifov's
sparse proof alone (``rig_proof.prove_sparse_rig``), which the pipeline does not yet run on
frames of fewer than 4 stars (``pipeline.SPARSE_PROOF_METHODS``).

``--db rig`` builds (in a temporary directory) the rig camera's own database: seed 001's
preset at ``--mag-limit`` with multifov and triangle, ``--db seed001`` the preset as it is (6.5
Mv: deeper than frames to 5.5); ``--db default`` is the default set (which holds no
multifov); any other value is a database path.

GF-7's two cameras (8.9 x 8.9 deg, 2048 x 2048, axes 70 deg apart), stars to ``--mag-limit``,
body attitudes uniform on SO(3). Frames are tallied by the total number of real stars across
both cameras (3, 4, 5, 6+) and by how they fall across the cameras, e.g. (1, 3). Prints
markdown tables; wrong answers are counted against the simulator's truth in either camera.
"""

from __future__ import annotations

from . import common  # noqa: F401  (pins threads before numpy)

import argparse  # noqa: E402
import math  # noqa: E402
import time  # noqa: E402
from collections import defaultdict  # noqa: E402
from collections.abc import Sequence  # noqa: E402
import tempfile  # noqa: E402
from dataclasses import replace  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

from service.core.attitude import quat_to_matrix  # noqa: E402
from service.core.evaluate import score  # noqa: E402
from service.core.methods import get_matcher  # noqa: E402
from service.core.methods.rig_proof import prove_sparse_rig  # noqa: E402
from service.core.camera import Rig  # noqa: E402
from service.core.navdb import (  # noqa: E402
    NavDatabase,
    build_database,
    ensure_default_database,
    open_database,
)
from service.core.pipeline import SolveOptions, _observation, solve_rig  # noqa: E402
from service.core.presets import PRESETS  # noqa: E402
from service.core.sim import SimConfig  # noqa: E402
from service.core.sim_rig import RigFrame, gf7_rig, random_rig_points, simulate_rig_frames  # noqa: E402
from service.core.verify import Verifier  # noqa: E402

RANDOM_SPLITS = ((1, 2), (2, 1), (2, 2), (1, 3), (3, 1), (0, 4), (2, 3), (1, 4), (3, 3), (4, 2))


def proof_alone(db: NavDatabase, rf: RigFrame, rig: Rig, sigma: float) -> bool | None:
    """A frame offered to multifov's sparse proof alone (match radius and pattern tolerance as
    the pipeline sets them): None refused, else whether every star it named is right."""
    inputs = rf.inputs(rig)
    obs = _observation(inputs, [quat_to_matrix(np.asarray(q, float)) for _, _, q in inputs])
    matcher = get_matcher(db, "multifov")
    tol = (3.0 * math.sqrt(2.0) * sigma + 0.5) * obs.pixel_scale_rad
    found = prove_sparse_rig(Verifier(db, obs, match_radius_px=max(2.5, 3.0 * sigma)), matcher.lookup, tol,
                             matcher.mount_tol)
    if found is None:
        return None
    truth = [rf.frames[c].hip[i] for c, i in zip(obs.camera[found.obs], obs.index[found.obs], strict=True)]
    return bool(np.array_equal(db.stars.hip[found.cat], truth))


def main(argv: Sequence[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=1000)
    ap.add_argument("--mag-limit", type=float, default=5.5)
    ap.add_argument("--noise", type=float, default=0.5)
    ap.add_argument("--method", default="auto")
    ap.add_argument("--db", default="default")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--false-stars", type=int, default=0)
    ap.add_argument("--missing", type=float, default=0.0)
    ap.add_argument("--random", type=int, default=0)
    args = ap.parse_args(argv)
    if args.db in ("rig", "seed001"):
        path = Path(tempfile.mkdtemp(prefix="bench-rig-")) / args.db
        preset = PRESETS["seed001"]
        if args.db == "rig":
            preset = replace(preset, mag_limit=args.mag_limit)
        build_database(path, preset.build_config(("multifov", "triangle")))
    else:
        path = ensure_default_database() if args.db == "default" else Path(args.db)
    db = open_database(path)
    rig = gf7_rig()
    config = SimConfig(mag_limit=args.mag_limit, centroid_noise_px=args.noise, false_stars=args.false_stars,
                       missing_prob=args.missing)
    frames = simulate_rig_frames(rig, args.frames, config, rng=args.seed)
    opts = SolveOptions(centroid_sigma_px=max(args.noise, 0.1))
    by_total: dict[str, list[int]] = defaultdict(lambda: [0, 0, 0])  # frames, solved, wrong
    by_split: dict[tuple[int, int], list[int]] = defaultdict(lambda: [0, 0, 0])
    alone = [0, 0, 0]  # 3-star frames offered to the sparse proof alone: frames, proven right, wrong
    ms: dict[str, list[float]] = defaultdict(list)
    for rf in frames:
        counts = tuple(sorted((int((f.hip >= 0).sum()) for f in rf.frames), reverse=True))
        total = sum(counts)
        t0 = time.perf_counter()
        sol = solve_rig(rf.inputs(rig), db, method=args.method, options=opts)
        ms["6+" if total >= 6 else str(total)].append(1e3 * (time.perf_counter() - t0))
        ok = sol.solved
        wrong = False
        if ok:
            wrong = not all(score(sol, f.quaternion, f.hip.tolist(), camera=c, blends=f.blends).correct
                            for c, f in enumerate(rf.frames))
        key = "6+" if total >= 6 else str(total)
        for table, k in ((by_total, key), (by_split, counts)):
            table[k][0] += 1
            table[k][1] += ok and not wrong
            table[k][2] += wrong
        if total == 3 and args.method == "multifov":
            got = proof_alone(db, rf, rig, opts.centroid_sigma_px)
            alone[0] += 1
            alone[1] += got is True
            alone[2] += got is False
    print(f"{args.frames} rig frames, stars to {args.mag_limit} Mv, {args.noise} px, {args.false_stars} "
          f"false stars a camera, {args.missing:g} missing, method {args.method}, db {args.db}\n")
    print("| stars in the frame | frames | identified | rate | wrong | median ms |")
    print("|---|---|---|---|---|---|")
    for k in ("0", "1", "2", "3", "4", "5", "6+"):
        if k in by_total:
            n, s, w = by_total[k]
            print(f"| {k} | {n} | {s} | {100 * s / n:.1f}% | {w} | {np.median(ms[k]):.1f} |")
    if alone[0]:
        print(f"\n3-star frames, multifov's sparse proof alone: {alone[1]}/{alone[0]} = "
              f"{100 * alone[1] / alone[0]:.1f}%, {alone[2]} wrong")
    four = [v for k, v in by_total.items() if k not in ("0", "1", "2", "3")]
    n4, s4 = sum(v[0] for v in four), sum(v[1] for v in four)
    print(f"\n4 or more stars: {s4}/{n4} = {100 * s4 / max(n4, 1):.1f}%\n")
    print("| stars per camera | frames | identified | rate | wrong |\n|---|---|---|---|---|")
    for k in sorted(by_split, key=lambda c: (sum(c), c)):
        if 3 <= sum(k) <= 6:
            n, s, w = by_split[k]
            print(f"| {k} | {n} | {s} | {100 * s / n:.1f}% | {w} |")
    if args.random:
        gen = np.random.default_rng(args.seed)
        hits = sum(solve_rig(random_rig_points(rig, RANDOM_SPLITS[t % len(RANDOM_SPLITS)], gen), db,
                             method=args.method, options=opts).solved for t in range(args.random))
        print(f"\nrandom-point rig frames ({len(RANDOM_SPLITS)} splits of 3-6 points): "
              f"{hits}/{args.random} identified")


if __name__ == "__main__":
    main()
