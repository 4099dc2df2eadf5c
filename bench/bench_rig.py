"""Sparse rig frames (seed 001's point): rate against the number of stars in the whole frame.

    python -m bench.bench_rig --frames 1000 --mag-limit 5.5 --noise 0.5 [--method auto] [--db default]

GF-7's two cameras (8.9 x 8.9 deg, 2048 x 2048, axes 70 deg apart), stars to ``--mag-limit``,
body attitudes uniform on SO(3). Frames are tallied by the total number of real stars across
both cameras (3, 4, 5, 6+) and by how they fall across the cameras, e.g. (1, 3). Prints
markdown tables; wrong answers are counted against the simulator's truth in either camera.
"""

from __future__ import annotations

from . import common  # noqa: F401  (pins threads before numpy)

import argparse  # noqa: E402
from collections import defaultdict  # noqa: E402
from collections.abc import Sequence  # noqa: E402
from pathlib import Path  # noqa: E402

from service.core.evaluate import score  # noqa: E402
from service.core.navdb import ensure_default_database, open_database  # noqa: E402
from service.core.pipeline import SolveOptions, solve_rig  # noqa: E402
from service.core.sim import SimConfig  # noqa: E402
from service.core.sim_rig import gf7_rig, simulate_rig_frames  # noqa: E402


def main(argv: Sequence[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=1000)
    ap.add_argument("--mag-limit", type=float, default=5.5)
    ap.add_argument("--noise", type=float, default=0.5)
    ap.add_argument("--method", default="auto")
    ap.add_argument("--db", default="default")
    ap.add_argument("--seed", type=int, default=1)
    args = ap.parse_args(argv)
    db = open_database(ensure_default_database() if args.db == "default" else Path(args.db))
    rig = gf7_rig()
    frames = simulate_rig_frames(rig, args.frames, SimConfig(mag_limit=args.mag_limit, centroid_noise_px=args.noise),
                                 rng=args.seed)
    opts = SolveOptions(centroid_sigma_px=max(args.noise, 0.1))
    by_total: dict[str, list[int]] = defaultdict(lambda: [0, 0, 0])  # frames, solved, wrong
    by_split: dict[tuple[int, int], list[int]] = defaultdict(lambda: [0, 0, 0])
    for rf in frames:
        counts = tuple(sorted((int((f.hip >= 0).sum()) for f in rf.frames), reverse=True))
        total = sum(counts)
        sol = solve_rig(rf.inputs(rig), db, method=args.method, options=opts)
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
    print(f"{args.frames} rig frames, stars to {args.mag_limit} Mv, {args.noise} px, method {args.method}, db {args.db}\n")
    print("| stars in the frame | frames | identified | rate | wrong |\n|---|---|---|---|---|")
    for k in ("0", "1", "2", "3", "4", "5", "6+"):
        if k in by_total:
            n, s, w = by_total[k]
            print(f"| {k} | {n} | {s} | {100 * s / n:.1f}% | {w} |")
    four = [v for k, v in by_total.items() if k not in ("0", "1", "2", "3")]
    n4, s4 = sum(v[0] for v in four), sum(v[1] for v in four)
    print(f"\n4 or more stars: {s4}/{n4} = {100 * s4 / max(n4, 1):.1f}%\n")
    print("| stars per camera | frames | identified | rate | wrong |\n|---|---|---|---|---|")
    for k in sorted(by_split, key=lambda c: (sum(c), c)):
        if 3 <= sum(k) <= 6:
            n, s, w = by_split[k]
            print(f"| {k} | {n} | {s} | {100 * s / n:.1f}% | {w} |")


if __name__ == "__main__":
    main()
