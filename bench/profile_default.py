"""Where a frame's time goes on the default database, per stage, per camera.

    python -m bench.profile_default --frames 300 [--camera seed000,...] [--noise 1 --false 2] [--profile]
        [--by-stars]

Solves simulated frames of each paper camera with ``auto`` on the default database set (the
README's path) and reports per stage (``Solution.timings_ms``: vectors, identify, attitude)
the median and mean ms per frame, the total's median / mean / p99, which method answered,
and the share of frames that ran a fallback method or reached the time limit. ``--profile``
adds pyinstrument's top functions over the same frames (the Python-level calls around the
compiled kernels show up there); ``--by-stars`` splits each camera's simulated frames by their
number of centroids: share of frames, share of the time, mean ms, share answered.
"""

from __future__ import annotations

from . import common  # noqa: F401  (pins threads before numpy)

import argparse  # noqa: E402
import time  # noqa: E402
from collections import Counter  # noqa: E402
from collections.abc import Sequence  # noqa: E402

import numpy as np  # noqa: E402

from service.core.navdb import ensure_default_database, open_database  # noqa: E402
from service.core.pipeline import SolveOptions, solve  # noqa: E402
from service.core.presets import PRESETS  # noqa: E402
from service.core.sim import SimConfig, random_points, simulate_frames  # noqa: E402

STAGES = ("vectors", "identify", "attitude")


def _row(label: str, timings: list[dict[str, float]], wall: np.ndarray, methods: Counter, fallbacks: int) -> str:
    cells = []
    for st in STAGES:
        v = np.array([t.get(st, 0.0) for t in timings])
        cells.append(f"{np.median(v):.3f} / {v.mean():.3f}")
    used = ", ".join(f"{m} {n}" for m, n in methods.most_common())
    return (f"| {label} | " + " | ".join(cells) + f" | {np.median(wall):.3f} / {wall.mean():.3f} / "
            f"{np.percentile(wall, 99):.2f} | {used} | {fallbacks} |")


def _by_stars(key: str, stars: np.ndarray, wall: np.ndarray, solved: np.ndarray) -> str:
    """A camera's frames by centroid count: frames, time, mean ms, answered (a markdown table)."""
    lines = [f"\n{key}, by centroids in the frame\n", "| centroids | frames | time | mean ms | answered |",
             "|---|---|---|---|---|"]
    for n in np.unique(stars):
        m = stars == n
        lines.append(f"| {n} | {m.mean() * 100:.1f}% | {wall[m].sum() / wall.sum() * 100:.1f}% | "
                     f"{wall[m].mean():.3f} | {solved[m].mean() * 100:.0f}% |")
    return "\n".join(lines)


def main(argv: Sequence[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=300)
    ap.add_argument("--camera", default="seed000,seed001,seed002,seed003,seed004")
    ap.add_argument("--noise", type=float, default=1.0)
    ap.add_argument("--false", type=int, default=2)
    ap.add_argument("--random", type=int, default=50, help="random-point frames per camera (0: none)")
    ap.add_argument("--seed", type=int, default=5)
    ap.add_argument("--profile", action="store_true")
    ap.add_argument("--by-stars", action="store_true", help="split each camera's frames by centroid count")
    args = ap.parse_args(argv)
    db = open_database(ensure_default_database())
    opts = SolveOptions(centroid_sigma_px=max(args.noise, 0.1))
    print(f"auto on the default database; {args.frames} frames a camera at {args.noise} px, {args.false} false "
          f"stars; ms per frame, median / mean\n")
    print("| camera | vectors | identify | attitude | wall: median / mean / p99 | answered by | fallbacks or limit |")
    print("|---|---|---|---|---|---|---|")
    profiler = None
    if args.profile:
        from pyinstrument import Profiler

        profiler = Profiler(interval=0.0002)
    split: list[tuple[str, list[int], list[float], list[bool]]] = []
    for key in args.camera.split(","):
        p = PRESETS[key]
        config = SimConfig(mag_limit=p.mag_limit, centroid_noise_px=args.noise, false_stars=args.false)
        frames = [f.centroids for f in simulate_frames(p.camera, args.frames, config, rng=args.seed)]
        rng = np.random.default_rng(args.seed)
        randoms = [random_points(p.camera, int(n), rng) for n in rng.integers(5, 40, args.random)]
        solve(frames[0], p.camera, db, options=opts)  # kernels and caches warm
        for label, batch in ((key, frames), (f"{key} random points", randoms)):
            if not batch:
                continue
            timings, wall, methods, fallbacks, solved = [], [], Counter(), 0, []
            if profiler is not None:
                profiler.start()
            for c in batch:
                t0 = time.perf_counter()
                sol = solve(c, p.camera, db, options=opts)
                wall.append((time.perf_counter() - t0) * 1e3)
                timings.append(sol.timings_ms)
                reason = getattr(getattr(sol, "reason", None), "value", None)  # older skyfix: no reason
                methods[sol.method if sol.solved else f"none ({reason or '-'})"] += 1
                solved.append(sol.solved)
                tried = getattr(sol, "methods_tried", ()) or ()
                fallbacks += len(tried) > 1 or reason == "time_limit"
            if profiler is not None:
                profiler.stop()
            print(_row(label, timings, np.array(wall), methods, fallbacks), flush=True)
            if args.by_stars and batch is frames:
                split.append((key, [len(c) for c in batch], wall, solved))
    for key, stars, wall, solved in split:
        print(_by_stars(key, np.array(stars), np.array(wall), np.array(solved)))
    if profiler is not None:
        print("\n```text\n" + profiler.output_text(unicode=False, color=False)[:8000] + "\n```")


if __name__ == "__main__":
    main()
