"""pso (seed 004): tables, build time, swarm vs deterministic tours, the four variants, depth.

    python -m bench.bench_pso                       # 200 frames per condition, 300 sampled tours
    python -m bench.bench_pso --frames 500 --tours 1000
    python -m bench.bench_pso --sections depth --frames 100   # the magnitude cuts (issue 16)

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
   missing; rate, wrong answers, median / p95 ms (5 s budget: the swarm is slow);
4. depth (issue 16): frames to other magnitude limits than the database's, on a table of one
   cut (``depth_steps=[0]``: the table and the search of before the cuts) and of the default
   cuts, with ``bench_every_method``'s frames (0.5 px, 2 false stars, 500 ms a frame, the same
   judge): the issue's database (12-17 deg, 6.5 Mv, as ``skyfix db build --fov-min 12
   --fov-max 17 --mag-limit 6.5``) with a 12-deg 1024-px camera, and the paper cameras of seeds
   003 and 004 on their own databases; then random points (20-119) on each, and the build time
   and size of both tables;
5. stress (``--sections stress``, not by default: ~10 minutes at 300 frames a cell): wrong
   answers of the tables with cuts over frames to 6.25, 6.0 and 5.5 Mv x 0.5, 1, 2 px x 0, 2, 5
   false stars x 0, 0.3 mag of magnitude noise, on seed 004's camera and the issue's.

Outputs ``bench/out/pso.{md,json}`` (``pso-depth.{md,json}``, ``pso-stress.json`` for those).
Timing: one single-threaded process.
"""
# ruff: noqa: I001

from __future__ import annotations

from bench import common  # (first: pins BLAS threads before numpy loads)

import argparse
import dataclasses
import itertools
import json
import math
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

from bench.common import SkyfixSolver, judge, summarize
from service.core.camera import Camera
from service.core.evaluate import score
from service.core.methods._tour import pso_tour
from service.core.methods.pso import CUT_STRIDE, KEY_STRIDE, PsoMatcher, angle_matrices
from service.core.navdb import BuildConfig, NavDatabase, build_database, open_database
from service.core.pipeline import SolveOptions, solve
from service.core.presets import PRESETS
from service.core.sim import BLEND_DEG, BLEND_PX, SimConfig, random_points, simulate_frames

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
    for r in rng.choice(int(np.searchsorted(key, CUT_STRIDE)), n, replace=False):  # cut 0: every star
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


DEPTH_CAMERAS: dict[str, tuple[Camera, BuildConfig, tuple[float, ...]]] = {
    "issue16 (12 deg, 1024 px; 12-17 deg database, 6.5 Mv)": (
        Camera.from_fov(12.0, 1024, 1024),
        BuildConfig(fov_min_deg=12.0, fov_max_deg=17.0, mag_limit=6.5, methods=("pso",)),
        (7.0, 6.5, 6.0, 5.5, 5.0)),
    "seed004 (20 deg; its database, 6.5 Mv)": (
        PRESETS["seed004"].camera, PRESETS["seed004"].build_config(("pso",)), (7.0, 6.5, 6.0, 5.5, 5.0)),
    "seed003 (15.2 deg; its database, 6.0 Mv)": (
        PRESETS["seed003"].camera, PRESETS["seed003"].build_config(("pso",)), (6.5, 6.0, 5.5, 5.0, 4.5)),
}
"""Depth section: camera, database, and the magnitude limits of the frames."""
DEPTH_TABLES = {"one cut": [0.0], "cuts": None}
"""``depth_steps`` of the two tables compared (None: the default, ``pso.DEPTH_STEPS``)."""


def depth(tmp: Path, frames_n: int, seed: int, random_n: int) -> list[dict[str, Any]]:
    """Frames to several magnitude limits on a table of one cut and of the default cuts."""
    rows: list[dict[str, Any]] = []
    for label, (camera, cfg, mags) in DEPTH_CAMERAS.items():
        frames = {mag: simulate_frames(camera, frames_n, SimConfig(mag_limit=mag, centroid_noise_px=0.5,
                                                                   false_stars=2), rng=seed)
                  for mag in mags}
        for table, steps in DEPTH_TABLES.items():
            params = {} if steps is None else {"pso": {"depth_steps": steps}}
            path = tmp / f"depth-{len(rows)}"
            t0 = time.perf_counter()
            build_database(path, dataclasses.replace(cfg, method_params=params))
            build_s = time.perf_counter() - t0
            db = open_database(path)
            prm = db.method_params("pso")
            size = sum(int(v.nbytes) for v in db.tables["pso"].values())
            base = {"camera": label, "table": table, "build_s": build_s, "records": prm["n_records"],
                    "cuts_mag": prm.get("cuts_mag"), "table_bytes": size}
            solver = SkyfixSolver(db, "pso", sigma=0.5)
            for mag, fr in frames.items():
                js = [judge(solver.solve(f.centroids, camera, 0.5), f.quaternion, f.hip.tolist(), f.blends)
                      for f in fr]
                rows.append({**base, "frames_mag": mag, **summarize(js)})
                print(json.dumps({k: rows[-1][k] for k in ("camera", "table", "frames_mag", "rate", "wrong",
                                                           "ms_median")}), flush=True)
            rand = [solver.solve(random_points(camera, 20 + (7 * i) % 100, rng=i), camera, 0.5)
                    for i in range(random_n)]
            solved = sum(a.solved for a in rand)
            rows.append({**base, "frames_mag": "random", "frames": random_n, "solved": solved,
                         "ms_median": float(np.median([a.ms for a in rand]))})
            print(json.dumps({k: rows[-1][k] for k in ("camera", "table", "solved", "ms_median", "build_s",
                                                       "table_bytes")}), flush=True)
    return rows


STRESS_CAMERAS = {"seed004": (6.25, 6.0, 5.5), "issue16": (6.25, 6.0, 5.5)}
"""Stress section: the depth section's cameras (by the start of their label) and frame limits."""
STRESS_GRID = ((0.5, 1.0, 2.0), (0, 2, 5), (0.0, 0.3))
"""Centroid noise (px), false stars, magnitude noise: every combination, at every limit."""


def stress(tmp: Path, frames_n: int) -> list[dict[str, Any]]:
    """Wrong answers at scale on the tables with cuts: every cell of ``STRESS_GRID`` at every
    limit of ``STRESS_CAMERAS``; each wrong answer is printed with what replays it."""
    rows: list[dict[str, Any]] = []
    for name, mags in STRESS_CAMERAS.items():
        camera, cfg, _ = next(v for k, v in DEPTH_CAMERAS.items() if k.startswith(name))
        build_database(tmp / name, cfg)
        db = open_database(tmp / name)
        cells = itertools.product(mags, *STRESS_GRID)
        for k, (mag, noise, false, mag_noise) in enumerate(cells):
            sim = SimConfig(mag_limit=mag, centroid_noise_px=noise, false_stars=false, mag_noise=mag_noise)
            frames = simulate_frames(camera, frames_n, sim, rng=1000 + k)
            solver = SkyfixSolver(db, "pso", sigma=noise)
            js = [judge(solver.solve(f.centroids, camera, noise), f.quaternion, f.hip.tolist(), f.blends)
                  for f in frames]
            for i, j in enumerate(js):
                if j.solved and j.wrong:
                    print(f"WRONG {name}: {sim}, rng={1000 + k}, frame {i}", flush=True)
            rows.append({"camera": name, "frames_mag": mag, "noise_px": noise, "false_stars": false,
                         "mag_noise": mag_noise, **summarize(js)})
            print(json.dumps({k2: rows[-1][k2] for k2 in ("camera", "frames_mag", "noise_px", "false_stars",
                                                          "mag_noise", "right", "wrong")}), flush=True)
    return rows


def depth_report(rows: list[dict[str, Any]], args: argparse.Namespace) -> str:
    def cell(r: dict[str, Any]) -> str:
        if r["frames_mag"] == "random":
            return f"{r['solved']} of {r['frames']} solved ({r['ms_median']:.0f} ms)"
        return f"{100 * r['rate']:.1f}% ({r['wrong']} wrong, {r['ms_median']:.1f} ms)"

    by = {(r["camera"], r["table"], r["frames_mag"]): r for r in rows}
    lines = ["# pso: frames shallower and deeper than the database (issue 16)", "",
             common.machine_line(common.machine_info()), "",
             f"{args.frames} frames a cell at 0.5 px with 2 false stars (seed {args.depth_seed}, as "
             "bench_every_method), 500 ms a frame; cell = right (wrong answers, median ms a frame).", "",
             "| camera | frames to | " + " | ".join(DEPTH_TABLES) + " |",
             "|---|---|" + "---|" * len(DEPTH_TABLES)]
    for label, (_, _, mags) in DEPTH_CAMERAS.items():
        for mag in (*mags, "random"):
            what = "random points (20-119)" if mag == "random" else f"{mag:g} Mv"
            cells = " | ".join(cell(by[(label, t, mag)]) for t in DEPTH_TABLES)
            lines.append(f"| {label} | {what} | {cells} |")
    lines += ["", "| camera | table | cuts (Mv) | records | pso tables | build |",
              "|---|---|---|---|---|---|"]
    for label in DEPTH_CAMERAS:
        for t in DEPTH_TABLES:
            r = by[(label, t, "random")]
            lines.append(f"| {label} | {t} | {', '.join(f'{c:g}' for c in r['cuts_mag'])} | {r['records']} "
                         f"| {r['table_bytes'] / 1024:.0f} kB | {r['build_s']:.1f} s |")
    return "\n".join(lines) + "\n"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=200)
    ap.add_argument("--tours", type=int, default=300)
    ap.add_argument("--builds", type=int, default=3)
    ap.add_argument("--seed", type=int, default=4)
    ap.add_argument("--sections", default="variants,depth", help="comma-separated: variants, depth, stress")
    ap.add_argument("--depth-seed", type=int, default=16, help="depth: frames' seed")
    ap.add_argument("--random", type=int, default=100, help="depth: random-point frames per table")
    args = ap.parse_args()
    sections = set(args.sections.split(","))
    common.OUT.mkdir(parents=True, exist_ok=True)
    if "depth" in sections:
        with tempfile.TemporaryDirectory() as tmp:
            rows = depth(Path(tmp), args.frames, args.depth_seed, args.random)
        report = {"machine": common.machine_info(), "rows": rows}
        (common.OUT / "pso-depth.json").write_text(json.dumps(report, indent=1))
        md = depth_report(rows, args)
        (common.OUT / "pso-depth.md").write_text(md)
        print(md)
    if "stress" in sections:
        with tempfile.TemporaryDirectory() as tmp:
            rows = stress(Path(tmp), args.frames)
        report = {"machine": common.machine_info(), "rows": rows}
        (common.OUT / "pso-stress.json").write_text(json.dumps(report, indent=1))
        print(f"stress: {sum(r['frames'] for r in rows)} frames, {sum(r['solved'] for r in rows)} solved, "
              f"{sum(r['wrong'] for r in rows)} wrong")
    if "variants" not in sections:
        return
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
