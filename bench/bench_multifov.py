"""multifov (seed 001): pair index (piecewise-linear fit vs searchsorted) and rig identification.

    python -m bench.bench_multifov                  # 300 rig frames per condition
    python -m bench.bench_multifov --frames 1000

Rig: GF-7's two cameras (8.9 x 8.9 deg, 2048 x 2048, stars to 6.5 Mv), optical axes 70 deg
apart (``service.core.sim_rig``); body attitudes uniform on SO(3). Measured:

1. database build time (median of ``--builds``) and table sizes;
2. the pair index: the largest error of the paper's 1-deg straight-line segments (and of finer
   ones), and the time of a range query through them against ``np.searchsorted``, for batches
   of 1, 20 (one master's vote) and 1,000 queries;
3. identification, ``mode`` ``robust`` vs ``paper`` on the same frames: 0.5 px; 1 px; 0.5 px +
   2 false stars per camera; 0.5 px + 10% missing; 0.5 mag magnitude noise; all of 1 px, 2
   false stars and 0.5 mag together; axes 25 and 120 deg apart. Rate, wrong answers (any star
   of either camera against that camera's truth), stars matched, median / p95 ms;
4. random points in both cameras: how many solve (must be 0).

Outputs ``bench/out/multifov.{md,json}``. Timing: one single-threaded process.
"""
# ruff: noqa: I001

from __future__ import annotations

from bench import common  # (first: pins BLAS threads before numpy loads)

import argparse
import json
import math
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

from service.core.evaluate import score
from service.core.methods.multifov import MultiFovMatcher, SegmentIndex
from service.core.navdb import NavDatabase, build_database, open_database
from service.core.pipeline import SolveOptions, solve_rig
from service.core.presets import PRESETS
from service.core.sim import SimConfig
from service.core.sim_rig import gf7_rig, random_rig_points, simulate_rig_frames

CONDITIONS: dict[str, tuple[SimConfig, float]] = {
    "0.5 px": (SimConfig(centroid_noise_px=0.5), 70.0),
    "1 px": (SimConfig(centroid_noise_px=1.0), 70.0),
    "0.5 px + 2 false / camera": (SimConfig(centroid_noise_px=0.5, false_stars=2), 70.0),
    "0.5 px + 10% missing": (SimConfig(centroid_noise_px=0.5, missing_prob=0.1), 70.0),
    "0.5 px + 0.5 mag noise": (SimConfig(centroid_noise_px=0.5, mag_noise=0.5), 70.0),
    "1 px + 2 false + 0.5 mag": (SimConfig(centroid_noise_px=1.0, false_stars=2, mag_noise=0.5), 70.0),
    "0.5 px, axes 25 deg": (SimConfig(centroid_noise_px=0.5), 25.0),
    "0.5 px, axes 120 deg": (SimConfig(centroid_noise_px=0.5), 120.0),
}


def index_timing(db: NavDatabase) -> dict[str, Any]:
    angles = np.asarray(db.tables["multifov"]["angles"])
    out: dict[str, Any] = {"pairs": len(angles), "segments": []}
    rng = np.random.default_rng(0)
    lo = rng.uniform(0, angles[-1], 20000)
    hi = lo + 4e-4
    for width_deg in (1.0, 0.25, 0.05):
        seg = SegmentIndex.build(angles, math.radians(width_deg))
        row: dict[str, Any] = {"width_deg": width_deg, "max_err": int(seg.err.max()), "us": {}}
        for q in (1, 20, 1000):
            reps = max(1, 20000 // q)
            t0 = time.perf_counter()
            for k in range(reps):
                np.searchsorted(angles, lo[k % 20:k % 20 + q], "left")
                np.searchsorted(angles, hi[k % 20:k % 20 + q], "right")
            t1 = time.perf_counter()
            for k in range(reps):
                seg.range(lo[k % 20:k % 20 + q], hi[k % 20:k % 20 + q])
            t2 = time.perf_counter()
            row["us"][q] = {"searchsorted": 1e6 * (t1 - t0) / reps, "segments": 1e6 * (t2 - t1) / reps}
        out["segments"].append(row)
        print(json.dumps(row), flush=True)
    return out


def identify(db: NavDatabase, n: int, seed: int) -> list[dict[str, Any]]:
    results = []
    for cname, (cfg, angle) in CONDITIONS.items():
        rig = gf7_rig(angle)
        frames = simulate_rig_frames(rig, n, cfg, rng=seed)
        opts = SolveOptions(centroid_sigma_px=max(cfg.centroid_noise_px, 0.1))
        for mode in ("robust", "paper"):
            db.__dict__.setdefault("_matchers", {})["multifov"] = MultiFovMatcher(db, mode=mode)
            solved = wrong = 0
            ms, frac = [], []
            for f in frames:
                sol = solve_rig(f.inputs(rig), db, method="multifov", options=opts)
                ms.append(sol.timings_ms["total"])
                if not sol.solved:
                    continue
                solved += 1
                wrong += not all(score(sol, f.quaternion, sf.hip.tolist(), camera=c, blends=sf.blends).correct
                                 for c, sf in enumerate(f.frames))
                frac.append(len(sol.stars) / sum(int((sf.hip >= 0).sum()) for sf in f.frames))
            results.append({"condition": cname, "mode": mode, "frames": n, "rate": solved / n, "wrong": wrong,
                            "stars_matched": float(np.mean(frac)) if frac else 0.0,
                            "ms_median": float(np.median(ms)), "ms_p95": float(np.percentile(ms, 95))})
            print(json.dumps(results[-1]), flush=True)
    db.__dict__["_matchers"].pop("multifov", None)
    return results


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=300)
    ap.add_argument("--builds", type=int, default=3)
    ap.add_argument("--random", type=int, default=200)
    ap.add_argument("--seed", type=int, default=1)
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        build_s = []
        for i in range(args.builds):
            t0 = time.perf_counter()
            build_database(Path(tmp) / f"seed001-{i}", PRESETS["seed001"].build_config(("multifov",)))
            build_s.append(time.perf_counter() - t0)
        db = open_database(Path(tmp) / "seed001-0")
        sizes = {k: int(v.nbytes) for k, v in db.tables["multifov"].items()}
        index = index_timing(db)
        ident = identify(db, args.frames, args.seed)
        rig = gf7_rig()
        opts = SolveOptions(centroid_sigma_px=0.5)
        rnd = sum(solve_rig(random_rig_points(rig, [3 + i % 25, 3 + (7 * i) % 25], rng=i), db,
                            method="multifov", options=opts).solved for i in range(args.random))
    report = {"machine": common.machine_info(), "build_s": build_s, "table_bytes": sizes, "index": index,
              "identify": ident, "random_solved": rnd, "random_frames": args.random}
    common.OUT.mkdir(parents=True, exist_ok=True)
    (common.OUT / "multifov.json").write_text(json.dumps(report, indent=1))
    lines = [
        "# multifov (seed 001): pair index and rig identification", "",
        common.machine_line(report["machine"]), "",
        f"Database: {index['pairs']} pairs, build {np.median(build_s):.1f} s (median of {len(build_s)}); "
        "tables: " + ", ".join(f"{k} {v / 1024:.0f} kB" for k, v in sizes.items()), "",
        "## Pair index: straight-line segments vs np.searchsorted (us per batch)", "",
        "| segment | largest fit error (entries) | 1 query | 20 queries | 1,000 queries |",
        "|---|---|---|---|---|",
    ]
    for row in index["segments"]:
        us = row["us"]
        cells = [f"{us[q]['segments']:.1f} vs {us[q]['searchsorted']:.1f}" for q in (1, 20, 1000)]
        lines.append(f"| {row['width_deg']} deg | {row['max_err']} | " + " | ".join(cells) + " |")
    lines += ["", "## Identification (GF-7 rig)", "",
              "| condition | mode | rate | wrong | stars matched | median ms | p95 ms |",
              "|---|---|---|---|---|---|---|"]
    for r in ident:
        lines.append(f"| {r['condition']} | {r['mode']} | {r['rate']:.1%} | {r['wrong']} | "
                     f"{r['stars_matched']:.1%} | {r['ms_median']:.1f} | {r['ms_p95']:.1f} |")
    lines += ["", f"Random points in both cameras: {rnd} of {args.random} solved."]
    (common.OUT / "multifov.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
