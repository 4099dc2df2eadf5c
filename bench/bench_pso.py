"""pso (seed 004): tables, build time, swarm vs deterministic tours, and the four variants.

    python -m bench.bench_pso                       # 200 frames per condition, 300 sampled tours
    python -m bench.bench_pso --frames 500 --tours 1000

Camera: seed 004's (20 x 20 deg, 1024 x 1024, 15 um, stars to 6.5 Mv); database stars merged at
the camera's blend radius (2 px), as the simulator merges them. Measured:

1. database build time (median of ``--builds``) and the size of every table;
2. tours: for ``--tours`` catalogue records drawn at random, the hybrid particle swarm (80
   particles, 200 iterations) on the record's own stars against the stored deterministic tour:
   how often the swarm's length differs (longer: it stopped short; shorter: the local search
   did), how often by more than the look-up tolerance at 0.5 px, and two swarm runs with
   different seeds against each other - the paper's failure mode, by star count;
3. identification of every variant ``sky_tour`` (``exact`` | ``pso``) x ``matching``
   (``robust`` | ``paper``) on the same frames, with up to 8 masters a frame and with 1: 0.5
   px, 1 px, 0.5 px + 2 false stars, 0.5 px + 5% missing stars, and 1.5 px + 3 false + 10%
   missing; rate, wrong answers, median / p95 ms (5 s budget: the swarm is slow).

Outputs ``bench/out/pso.{md,json}``. Timing: one single-threaded process.
"""
# ruff: noqa: I001

from __future__ import annotations

from bench import common  # (first: pins BLAS threads before numpy loads)

import argparse
import itertools
import json
import math
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

from service.core.evaluate import score
from service.core.methods._tour import pso_tour
from service.core.methods.pso import KEY_STRIDE, PsoMatcher, angle_matrices
from service.core.navdb import BuildConfig, NavDatabase, build_database, open_database
from service.core.pipeline import SolveOptions, solve
from service.core.presets import PRESETS
from service.core.sim import BLEND_DEG, BLEND_PX, SimConfig, simulate_frames

CAMERA = PRESETS["seed004"].camera
CONDITIONS = {
    "0.5 px": SimConfig(centroid_noise_px=0.5),
    "1 px": SimConfig(centroid_noise_px=1.0),
    "0.5 px + 2 false": SimConfig(centroid_noise_px=0.5, false_stars=2),
    "0.5 px + 5% missing": SimConfig(centroid_noise_px=0.5, missing_prob=0.05),
    "1.5 px + 3 false + 10% missing": SimConfig(centroid_noise_px=1.5, false_stars=3, missing_prob=0.1),
}
VARIANTS = [("exact", "robust"), ("exact", "paper"), ("pso", "robust"), ("pso", "paper")]


def config() -> BuildConfig:
    sep = max(BLEND_PX / CAMERA.f_px * 180 / math.pi, BLEND_DEG)
    return BuildConfig(fov_max_deg=CAMERA.diagonal_fov_deg + 0.2, fov_min_deg=CAMERA.fov_deg, mag_limit=6.5,
                       epoch=2026.0, double_star_sep_deg=sep, methods=("pso",))


def build(tmp: Path, n: int) -> tuple[NavDatabase, list[float]]:
    times = []
    for i in range(n):
        t0 = time.perf_counter()
        build_database(tmp / f"seed004-{i}", config())
        times.append(time.perf_counter() - t0)
    return open_database(tmp / "seed004-0"), times


def tours(db: NavDatabase, n: int, seed: int) -> dict[str, Any]:
    """Swarm against stored deterministic tours on catalogue records."""
    t = db.tables["pso"]
    key = np.asarray(t["key"])
    ids = np.asarray(t["ids"])
    vec = db.stars.vec
    radii = [math.radians(r) for r in db.method_params("pso")["radii_deg"]]
    rng = np.random.default_rng(seed)
    tol_px = (3 * math.sqrt(2) * 0.5 + 0.5) / CAMERA.f_px  # per-side tolerance at 0.5 px
    rows = []
    t_pso = []
    for r in rng.choice(len(key), n, replace=False):
        code = int(key[r] // KEY_STRIDE)
        stored = float(key[r] - code * KEY_STRIDE)
        c = int(ids[r, 0])
        near = np.flatnonzero(vec @ vec[c] >= math.cos(radii[code]))
        nodes = np.concatenate([[c], near[near != c]])
        d = angle_matrices(vec[nodes][None])[0]
        t0 = time.perf_counter()
        _, l1 = pso_tour(d, rng=int(r))
        t_pso.append(time.perf_counter() - t0)
        _, l2 = pso_tour(d, rng=int(r) + 1)
        tol_len = tol_px * math.sqrt(len(nodes))
        rows.append((len(nodes), l1 - stored, l2 - l1, tol_len))
    a = np.array(rows)
    out: dict[str, Any] = {"tours": n, "pso_ms_median": 1e3 * float(np.median(t_pso)), "by_size": []}
    eps = 1e-9
    for lo, hi in ((3, 10), (11, 15), (16, 20), (21, 26), (27, 99)):
        s = a[(a[:, 0] >= lo) & (a[:, 0] <= hi)]
        if len(s) == 0:
            continue
        out["by_size"].append({
            "stars": f"{lo}-{hi}", "n": len(s),
            "pso_longer": float(np.mean(s[:, 1] > eps)), "pso_shorter": float(np.mean(s[:, 1] < -eps)),
            "beyond_tol": float(np.mean(np.abs(s[:, 1]) > s[:, 3])),
            "two_runs_differ": float(np.mean(np.abs(s[:, 2]) > eps)),
            "two_runs_beyond_tol": float(np.mean(np.abs(s[:, 2]) > s[:, 3])),
        })
    out["all"] = {"pso_longer": float(np.mean(a[:, 1] > eps)), "pso_shorter": float(np.mean(a[:, 1] < -eps)),
                  "beyond_tol": float(np.mean(np.abs(a[:, 1]) > a[:, 3])),
                  "two_runs_differ": float(np.mean(np.abs(a[:, 2]) > eps)),
                  "two_runs_beyond_tol": float(np.mean(np.abs(a[:, 2]) > a[:, 3]))}
    return out


def identify(db: NavDatabase, frames_n: int, seed: int) -> list[dict[str, Any]]:
    results = []
    for cname, cfg in CONDITIONS.items():
        frames = simulate_frames(CAMERA, frames_n, cfg, rng=seed)
        sigma = max(cfg.centroid_noise_px, 0.1)
        opts = SolveOptions(centroid_sigma_px=sigma, timeout_ms=5000)
        for (sky_tour, matching), masters in itertools.product(VARIANTS, (8, 1)):
            m = PsoMatcher(db, sky_tour=sky_tour, matching=matching, max_masters=masters)
            db.__dict__.setdefault("_matchers", {})["pso"] = m
            solved = wrong = 0
            ms = []
            for f in frames:
                sol = solve(f.centroids, CAMERA, db, method="pso", options=opts)
                s = score(sol, f.quaternion, f.hip.tolist(), blends=f.blends)
                solved += s.solved
                wrong += bool(s.solved and not s.correct)
                ms.append(sol.timings_ms["total"])
            results.append({"condition": cname, "sky_tour": sky_tour, "matching": matching,
                            "masters": masters,
                            "frames": len(frames), "rate": solved / len(frames), "wrong": wrong,
                            "ms_median": float(np.median(ms)), "ms_p95": float(np.percentile(ms, 95)),
                            "tours_per_frame": m.tours / len(frames)})
            print(json.dumps(results[-1]), flush=True)
    db.__dict__["_matchers"].pop("pso", None)
    return results


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=200)
    ap.add_argument("--tours", type=int, default=300)
    ap.add_argument("--builds", type=int, default=3)
    ap.add_argument("--seed", type=int, default=4)
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        db, build_s = build(Path(tmp), args.builds)
        sizes = {k: int(v.nbytes) for k, v in db.tables["pso"].items()}
        prm = db.method_params("pso")
        print(f"build {np.median(build_s):.1f} s (runs {[round(b, 1) for b in build_s]}), "
              f"{prm['n_records']} records, {len(db.stars)} stars, tables {sizes}", flush=True)
        tour = tours(db, args.tours, args.seed)
        print(json.dumps(tour), flush=True)
        ident = identify(db, args.frames, args.seed)
    report = {"machine": common.machine_info(), "build_s": build_s, "records": prm["n_records"],
              "stars": len(db.stars), "table_bytes": sizes, "tours": tour, "identify": ident}
    common.OUT.mkdir(parents=True, exist_ok=True)
    (common.OUT / "pso.json").write_text(json.dumps(report, indent=1))
    lines = [
        "# pso (seed 004): variants and tours", "", common.machine_line(report["machine"]), "",
        f"Database: {len(db.stars)} stars, {prm['n_records']} records, build {np.median(build_s):.1f} s "
        f"(median of {len(build_s)}); tables: "
        + ", ".join(f"{k} {v / 1024:.0f} kB" for k, v in sizes.items()),
        "", f"## Swarm (80 x 200) vs deterministic tour, {tour['tours']} catalogue records", "",
        "| stars | n | swarm longer | swarm shorter | beyond 0.5-px tolerance | 2 swarm runs differ | "
        "... beyond tolerance |", "|---|---|---|---|---|---|---|",
    ]
    for row in tour["by_size"] + [{"stars": "all", "n": tour["tours"], **tour["all"]}]:
        lines.append(f"| {row['stars']} | {row['n']} | {row['pso_longer']:.1%} | {row['pso_shorter']:.1%} "
                     f"| {row['beyond_tol']:.1%} | {row['two_runs_differ']:.1%} "
                     f"| {row['two_runs_beyond_tol']:.1%} |")
    lines += ["", f"Swarm time per tour: median {tour['pso_ms_median']:.0f} ms.", "",
              "## Identification", "",
              "Up to 8 masters a frame (the default), and 1 (the success rate of a single master, which",
              "shows what each variant's matching is worth on its own).", "",
              "| condition | sky tour | matching | masters | rate | wrong | median ms | p95 ms |",
              "|---|---|---|---|---|---|---|---|"]
    for r in ident:
        lines.append(f"| {r['condition']} | {r['sky_tour']} | {r['matching']} | {r['masters']} "
                     f"| {r['rate']:.1%} | {r['wrong']} | {r['ms_median']:.1f} | {r['ms_p95']:.1f} |")
    (common.OUT / "pso.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
