"""skyfix against the public peers, tetra3rs and cedar-solve, on the same frames.

    python -m bench.peers.cedar setup                 # once: cedar-solve's own venv
    python -m bench.bench_peers                       # five paper cameras x three sweeps + real images
    python -m bench.bench_peers --camera seed000 --sweep noise --frames 1000 --skyfix auto,maxangle

Every solver gets the same simulated frames (the paper cameras; centroid noise 0-2 px with 2
false stars; 0-5 false stars at 0.5 px; magnitude noise 0-1 mag at 0.5 px with 2 false stars)
and the real images' centroids (``shared/data/real/matches.json``, against ``truth.json``).
Each builds its own database, through its public API, from the same star list (the stars
skyfix's database holds for that camera: Hipparcos to the preset's magnitude limit at epoch
2026.0, close doubles merged) for the same field of view. Solvers run one after another on each
frame in rotating order, in one single-threaded process each, so a load spike on this shared
machine hits all of them alike; the time of a solve is measured inside the process that runs
it, with its database already loaded; every solver has the same 500 ms budget per frame.
``--order blocked`` runs each solver over all of a point's frames in turn instead, as a batch
job runs one solver: a solve then follows the same solver's previous frame, not another
solver's, whose tables have pushed its own out of the processor's caches.

- skyfix: ``solve`` with ``SolveOptions(centroid_sigma_px=max(noise, 0.1))``.
- tetra3rs (Rust, PyPI): exact ``CameraModel``; pattern tolerance 0.001 (its default) and 0.002
  (cedar's default; at >= 1 px of noise the 0.001 default alone loses most frames).
- cedar-solve 0.5.1 (Python, own venv): ``solve_from_centroids`` with the true FOV as estimate,
  ``match_max_error`` 0.002 (its default), ``distortion`` 0.

Scoring is the same for all (``bench.common.judge``). Outputs ``bench/out/peers.{md,json}`` and
``bench/out/peers-<camera>-<sweep>.png``.
"""

from __future__ import annotations

import argparse
import gc
import json
import sys
import time
from pathlib import Path
from typing import Any

from bench import common  # noqa: I001  (first: pins BLAS threads before numpy loads)
from bench.common import (
    OUT,
    PRESETS,
    REAL_DIR,
    SWEEPS,
    SkyfixSolver,
    build_skyfix_db,
    fmt,
    judge,
    machine_info,
    machine_line,
    md_table,
    measure_open,
    real_frames,
    scenarios,
    summarize,
    write_json,
)
import numpy as np  # after bench.common (see there)
from bench.peers import StarRows, tetra3rs_peer
from bench.peers import cedar as cedar_mod
from service.core.catalog import load_hipparcos, select_stars
from service.core.methods import method_names
from service.core.navdb import BuildConfig, build_database, open_database
from service.core.warmup import warm_up

REAL_FOV = (6.0, 26.0)
"""Horizontal fields of the real images: 6.07 deg (openstartracker) to 25.4 deg (img_7660)."""
REAL_MAG = 8.0
REAL_EPOCH = 2022.0


class Peers:
    """The peers that are installed here, with the reason for any that is not."""

    def __init__(self, wanted: list[str], log: Path) -> None:
        self.missing: dict[str, str] = {}
        self.t3 = self.cedar = None
        self.solvers: list[Any] = []
        if any(p.startswith("tetra3rs") for p in wanted):
            ok, why = tetra3rs_peer.available()
            if ok:
                self.t3 = tetra3rs_peer.Tetra3rsDb()
                if "tetra3rs" in wanted:
                    self.solvers.append(tetra3rs_peer.Tetra3rsSolver(self.t3, None))
                if "tetra3rs-0.002" in wanted:
                    self.solvers.append(tetra3rs_peer.Tetra3rsSolver(self.t3, 0.002))
            else:
                self.missing["tetra3rs"] = why
        if "cedar" in wanted:
            ok, why = cedar_mod.available()
            if ok:
                self.cedar = cedar_mod.CedarWorker(log)
                self.solvers.append(cedar_mod.CedarSolver(self.cedar))
            else:
                self.missing["cedar-solve"] = why

    def prepare(self, key: str, rows: StarRows, max_fov: float, min_fov: float | None, mag: float,
                workdir: Path, reuse: bool) -> tuple[list[Any], list[Any], dict[str, str]]:
        """Build/load each peer's database for one camera; returns (ready solvers, reports, failures)."""
        reports, failed, ready = [], dict(self.missing), []
        for store, names in ((self.t3, ("tetra3rs", "tetra3rs tol 0.002")), (self.cedar, ("cedar-solve",))):
            if store is None:
                continue
            try:
                t0 = time.time()
                reports.append(store.prepare(key, rows, max_fov, min_fov, mag, workdir, reuse))
                print(f"  [{key}] {reports[-1].solver}: build {reports[-1].build_s} s, "
                      f"{reports[-1].size_bytes / 1e6:.1f} MB, open {reports[-1].open_ms} ms "
                      f"({time.time() - t0:.0f} s here)", flush=True)
                ready += [s for s in self.solvers if s.name in names]
            except Exception as exc:  # a peer that cannot build for this camera: say why, go on
                for n in names:
                    failed[n] = f"database build failed: {type(exc).__name__}: {exc}"[:300]
                print(f"  [{key}] {names[0]}: {failed[names[0]]}", flush=True)
        return ready, reports, failed

    def close(self) -> None:
        if self.cedar is not None:
            self.cedar.close()


def quiet_heap() -> None:
    """Collect, then freeze what is left (``gc.freeze``): a full collection would otherwise walk
    every object of the set-up (databases, compiled kernels, the peers' bindings; ~35 ms with the
    default database loaded) inside whichever solver's frame it fell on. ``skyfix serve`` freezes
    its heap after its warm-up in the same way."""
    gc.collect()
    gc.freeze()


ORDERS = ("rotating", "blocked")


def run_frames(solvers: list[Any], frames: list[tuple[Any, Any, Any, Any, Any]], noise: float,
               order: str = "rotating") -> dict[str, list]:
    """``frames``: (centroids, camera, q_true, hip_true, blends). ``order`` "rotating": every
    solver on each frame, the first one rotating from frame to frame; "blocked": each solver on
    every frame, one solver after the other (see the module's docstring)."""
    if order not in ORDERS:
        raise ValueError(f"order must be one of {ORDERS}, not {order!r}")
    judged: dict[str, list] = {s.name: [] for s in solvers}

    def one(s: Any, cents: Any, cam: Any, q: Any, hip: Any, blends: Any) -> None:
        try:
            a = s.solve(cents, cam, noise)
        except RuntimeError as exc:  # a peer's worker died: record a failure, keep going
            a = common.Answer(False, float("nan"), status=f"error: {exc}")
        judged[s.name].append(judge(a, q, hip, blends))

    if order == "blocked":
        for s in solvers:
            for frame in frames:
                one(s, *frame)
        return judged
    for i, frame in enumerate(frames):
        k = i % len(solvers)
        for s in solvers[k:] + solvers[:k]:
            one(s, *frame)
    return judged


def run(args: argparse.Namespace) -> int:
    info = machine_info()
    cameras = [] if args.camera == ["none"] else (list(PRESETS) if args.camera == ["all"] else args.camera)
    sweeps = list(SWEEPS) if args.sweep == ["all"] else args.sweep
    out = Path(args.out)
    (out / "logs").mkdir(parents=True, exist_ok=True)
    peers = Peers(args.peers, out / "logs" / "cedar-worker.log")
    cmd = "python -m bench.bench_peers " + " ".join(sys.argv[1:])
    results: dict[str, Any] = {"machine": info, "command": cmd, "args": vars(args), "db": [], "sweeps": [],
                               "real": None, "unavailable": {}}
    pdir = Path(args.db_dir)
    try:
        for cam in cameras:
            preset = PRESETS[cam]
            print(f"[{cam}] databases", flush=True)
            build = method_names() if "auto" in args.skyfix else [m for m in args.skyfix if m in method_names()]
            dbpath, dbrep = build_skyfix_db(preset, build, pdir / cam, reuse=args.reuse_db)
            db = open_database(dbpath)
            sky = [m for m in args.skyfix if m == "auto" or m in db.methods]
            probe = scenarios(cam, "noise", [0.5])[0].frames(1, args.seed + 999)[0]
            dbrep.open_ms, dbrep.first_solve_ms = measure_open(dbpath, [m for m in sky if m != "auto"] or ["auto"],
                                                               preset.camera, probe)
            results["db"].append(dbrep.__dict__)
            rows = StarRows.from_table(db.stars)
            ready, reps, failed = peers.prepare(cam, rows, preset.camera.fov_deg, None, preset.mag_limit,
                                                pdir / "peers", not args.rebuild_peers)
            results["db"] += [r.__dict__ for r in reps]
            results["unavailable"][cam] = failed
            solvers = [SkyfixSolver(db, m) for m in sky] if "camera" in args.skyfix_db else []
            if "default" in args.skyfix_db:
                solvers = [SkyfixSolver(default_set(pdir, args.reuse_db), "auto", label=" @default")] + solvers
            solvers += ready
            for sweep in sweeps:
                t0 = time.time()
                for scen in scenarios(cam, sweep, args.values):
                    fr = [(f.centroids, preset.camera, f.quaternion, f.hip.tolist(), f.blends)
                          for f in scen.frames(args.frames, args.seed)]
                    quiet_heap()
                    judged = run_frames(solvers, fr, scen.noise_px, args.order)
                    row = {"camera": cam, "sweep": sweep, "value": scen.value, "scenario": scen.label,
                           "solvers": {n: summarize(js) for n, js in judged.items()}}
                    row["ratio"] = time_ratio(row["solvers"])
                    row["split"] = split_by_peer(judged)
                    row["per_frame"] = per_frame(judged)
                    results["sweeps"].append(row)
                    print(f"[{cam} {sweep} {scen.value:g}] " + "  ".join(
                        f"{n}: {fmt(s['rate'], 1, True)} {s['wrong']}w {fmt(s['ms_median'])}ms"
                        for n, s in row["solvers"].items()), flush=True)
                print(f"[{cam} {sweep}] {time.time() - t0:.0f} s", flush=True)
                if not args.no_plot:
                    plot(out / f"peers-{cam}-{sweep}.png", cam, sweep,
                         [r for r in results["sweeps"] if r["camera"] == cam and r["sweep"] == sweep])
                write_json(out / "peers.json", results)
        if args.real and (REAL_DIR / "truth.json").is_file():
            results["real"] = run_real(args, peers, pdir)
    finally:
        peers.close()
    write_json(out / "peers.json", results)
    (out / "peers.md").write_text(render(results, args, info, cmd))
    print(f"wrote {out / 'peers.md'}", flush=True)
    return 0


def default_set(pdir: Path, reuse: bool) -> Any:
    """The default database set (what the README's quick start serves), built once per run."""
    from service.core.navdb.builder import build_database_set
    from service.core.navdb.default import DEFAULT_MEMBERS

    path = pdir / "default-set"
    if not (reuse and (path / "manifest.json").is_file() and common.opens(path)):
        build_database_set(path, DEFAULT_MEMBERS)
    db = open_database(path)
    solve_probe = scenarios("seed000", "noise", [0.5])[0].frames(1, 999)[0]
    SkyfixSolver(db, "auto").solve(solve_probe.centroids, PRESETS["seed000"].camera, 0.5)  # warm the kernels
    return db


def time_ratio(solvers: dict[str, dict[str, Any]]) -> dict[str, Any]:
    """skyfix's median time over the fastest peer's, for each skyfix entry (same run, same frames)."""
    peers = {n: s["ms_median"] for n, s in solvers.items() if not n.startswith("skyfix") and s["ms_median"]}
    if not peers:
        return {}
    fastest = min(peers, key=peers.get)
    return {"fastest_peer": fastest, **{n: s["ms_median"] / peers[fastest] for n, s in solvers.items()
                                        if n.startswith("skyfix") and s["ms_median"]}}


def per_frame(judged: dict[str, list]) -> dict[str, dict[str, list]]:
    """Each solver's time (ms, 4 decimals) and outcome on every frame of a point, in frame
    order: "right", "wrong" or "none" (``peers.json`` ``per_frame``; any figure of a point,
    such as the median of the frames one solver refuses, can be taken from it afresh)."""
    return {name: {"ms": [round(j.ms, 4) for j in js],
                   "outcome": ["wrong" if j.solved and j.wrong else "right" if j.solved else "none" for j in js]}
            for name, js in judged.items()}


def split_by_peer(judged: dict[str, list]) -> dict[str, dict[str, Any]]:
    """skyfix's first entry against each peer on the same frames, split by outcome: frames both
    solve right (``both``: each one's mean and median ms) and frames only skyfix solves right
    (``only_skyfix``: skyfix's mean ms there, the peer's too). Where skyfix solves frames a peer
    refuses, its mean over all frames pays for them; this shows what the common frames cost."""
    names = list(judged)
    sk = next((n for n in names if n.startswith("skyfix")), None)
    if sk is None:
        return {}
    mine = judged[sk]
    right = [j.solved and not j.wrong for j in mine]
    out: dict[str, dict[str, Any]] = {}
    for peer in (n for n in names if not n.startswith("skyfix")):
        theirs = judged[peer]
        both = [i for i, (a, b) in enumerate(zip(right, theirs, strict=True)) if a and b.solved and not b.wrong]
        only = [i for i, (a, b) in enumerate(zip(right, theirs, strict=True))
                if a and not (b.solved and not b.wrong)]
        out[peer] = {
            "both": len(both),
            "both_skyfix_ms_mean": float(np.mean([mine[i].ms for i in both])) if both else None,
            "both_peer_ms_mean": float(np.mean([theirs[i].ms for i in both])) if both else None,
            "both_skyfix_ms_median": _median([mine[i].ms for i in both]),
            "both_peer_ms_median": _median([theirs[i].ms for i in both]),
            "only_skyfix": len(only),
            "only_skyfix_ms_mean": float(np.mean([mine[i].ms for i in only])) if only else None,
            "only_skyfix_peer_ms_mean": float(np.mean([theirs[i].ms for i in only])) if only else None,
        }
    return out


def _median(xs: list[float]) -> float | None:
    return float(np.median(xs)) if xs else None


def run_real(args: argparse.Namespace, peers: Peers, pdir: Path) -> dict[str, Any]:
    """The real images' centroid lists; one database per solver covering 6-26 deg."""
    frames = real_frames(REAL_DIR)
    print(f"[real] {len(frames)} images", flush=True)
    path = pdir / "real"
    try:
        from service.core.navdb.builder import build_database_set
        from service.core.navdb.default import DEFAULT_MEMBERS

        t0 = time.perf_counter()
        if not (args.reuse_db and (path / "manifest.json").is_file() and common.opens(path)):
            build_database_set(path, DEFAULT_MEMBERS)
        build_s, what = time.perf_counter() - t0, "skyfix's default database set (narrow 8.0 Mv + wide 6.5 Mv)"
    except ImportError:
        t0 = time.perf_counter()
        build_database(path, BuildConfig(fov_min_deg=5.0, fov_max_deg=32.0, mag_limit=7.0, epoch=REAL_EPOCH,
                                         density_cap=12, density_radius_deg=4.0, methods=tuple(method_names())))
        build_s, what = time.perf_counter() - t0, "one database 5-32 deg, 7.0 Mv, density-capped"
    db = open_database(path)
    warm_up(db)  # as default_set warms its own: the first frame does not carry the one-off set-up
    sky = [m for m in args.skyfix if m == "auto" or m in db.methods]
    stars = select_stars(load_hipparcos(), epoch=REAL_EPOCH, mag_limit=REAL_MAG, double_star_sep_deg=0.01)
    rows = StarRows.from_table(stars)
    ready, reps, failed = peers.prepare("real", rows, REAL_FOV[1], REAL_FOV[0], REAL_MAG, pdir / "peers",
                                        not args.rebuild_peers)
    solvers = [SkyfixSolver(db, m, sigma=1.0) for m in sky] + ready
    fr = [(f.centroids, f.camera, f.quaternion, f.hip, None) for f in frames]
    quiet_heap()
    judged = run_frames(solvers, fr, 1.0, getattr(args, "order", "rotating"))
    per_image = {n: [{"image": f.name, "solved": j.solved, "wrong": j.wrong, "cross": j.cross_arcsec, "ms": j.ms}
                     for f, j in zip(frames, js)] for n, js in judged.items()}
    return {"skyfix_db": {"what": what, "build_s": round(build_s, 3), "size_bytes": common.dir_bytes(path)},
            "peer_db": [r.__dict__ for r in reps], "unavailable": failed,
            "solvers": {n: summarize(js) for n, js in judged.items()}, "per_image": per_image,
            "peer_stars": f"Hipparcos to {REAL_MAG} Mv at {REAL_EPOCH}, doubles < 0.01 deg merged ({len(rows)} stars)"}


def render(res: dict[str, Any], args: argparse.Namespace, info: dict[str, Any], cmd: str) -> str:
    out = ["## skyfix vs tetra3rs and cedar-solve", "",
           f"Command: `{cmd}`  ", f"Machine: {machine_line(info)}.", "",
           f"{args.frames} frames per point; attitudes uniform on SO(3); every solver on the same frames in "
           f"{getattr(args, 'order', 'rotating')} order; time = in-process wall time of one solve call with the "
           "database loaded "
           f"(median and p95 over all frames); budget {common.TIMEOUT_MS:g} ms per solve for all. "
           "Right = attitude within 360\" cross-boresight and 3600\" roll and every matched star the true one "
           "(a false star paired with a catalogue star is wrong). A cell reads: right % / wrong answers "
           "(of which N att = attitude off; the rest have the right attitude but pair some centroid with the "
           "wrong star) / ms median · mean · p99; `@default` = the default database set (the README's path); [N%] = frames solved with the right attitude, when that differs from the right "
           "rate because of wrong star pairs.", ""]
    if res["db"]:
        out += ["### Databases", ""]
        head = ["camera", "solver", "build s", "size MB", "open ms", "notes"]
        out += [md_table(head, [[d["preset"], d["solver"], fmt(d["build_s"]), fmt(d["size_bytes"] / 1e6, 1),
                                 fmt(d["open_ms"]), d["note"] + (f"; first solve {d['first_solve_ms']} ms"
                                                                 if d.get("first_solve_ms") else "")]
                                for d in res["db"]]), ""]
    for cam in dict.fromkeys(r["camera"] for r in res["sweeps"]):
        una = res["unavailable"].get(cam) or {}
        for sweep in dict.fromkeys(r["sweep"] for r in res["sweeps"] if r["camera"] == cam):
            rs = [r for r in res["sweeps"] if r["camera"] == cam and r["sweep"] == sweep]
            names = list(rs[0]["solvers"])
            sk = [n for n in names if n.startswith("skyfix")]
            out += [f"### {cam}: {SWEEPS[sweep].label} ({PRESETS[cam].paper})", ""]
            cedar = "cedar-solve" if "cedar-solve" in names else None
            head = ([SWEEPS[sweep].label.split(" (")[0]] + names + [f"{n} / fastest peer (time)" for n in sk[:1]]
                    + ([f"{sk[0]} / cedar-solve (time)"] if sk and cedar else []))
            body = []
            for r in rs:
                cells = [f"{r['value']:g}"]
                for n in names:
                    s = r["solvers"][n]
                    w = f"{s['wrong']}" + (f" ({s['wrong_attitude']} att)" if s["wrong"] else "")
                    att = (s["solved"] - s["wrong_attitude"]) / s["frames"]
                    rate = fmt(s["rate"], 1, True) + (f" [{fmt(att, 1, True)}]" if s["wrong"] > s["wrong_attitude"] else "")
                    cells.append(f"{rate} / {w} / {fmt(s['ms_median'])} · {fmt(s['ms_mean'])} · {fmt(s['ms_p99'])}")
                if sk:
                    ra = r["ratio"]
                    cells.append(f"{fmt(ra.get(sk[0]))} ({ra.get('fastest_peer', '-')})" if ra else "-")
                    if cedar:
                        a, b = r["solvers"][sk[0]]["ms_median"], r["solvers"][cedar]["ms_median"]
                        cells.append(fmt(a / b) if a and b else "-")
                body.append(cells)
            out += [md_table(head, body), ""]
            p95 = "; ".join(f"{n} {fmt(min(r['solvers'][n]['ms_p95'] for r in rs))}-"
                            f"{fmt(max(r['solvers'][n]['ms_p95'] for r in rs))}" for n in names)
            out += [f"p95 ms over the sweep: {p95}. Attitude error of right answers (median cross-boresight, "
                    "arcsec, at the highest value): " + "; ".join(
                        f"{n} {fmt(rs[-1]['solvers'][n]['cross_arcsec_median'], 1)}" for n in names) + "."]
            if una:
                out += ["", "Not measured here: " + "; ".join(f"{k}: {v}" for k, v in una.items()) + "."]
            out += [""] + split_table(rs, sk[:1])
    out += goals(res)
    if res.get("real"):
        re_ = res["real"]
        out += ["### Real images (centroid lists from matches.json)", "",
                f"38 real images from four public projects, as the centroids matches.json lists (stars only, "
                "brightest first by catalogue magnitude), on a pinhole camera with the reference FOV; truth = "
                f"truth.json's reference attitude and matches.json's HIP. skyfix: {re_['skyfix_db']['what']} "
                f"(built in {fmt(re_['skyfix_db']['build_s'])} s, {re_['skyfix_db']['size_bytes'] / 1e6:.0f} MB), "
                "centroid_sigma_px 1.0. Peers: their own database for 6-26 deg from "
                f"{re_['peer_stars']}.", ""]
        head = ["solver", "solved", "right", "wrong", "cross-boresight median \"", "median ms", "p95 ms"]
        out += [md_table(head, [[n, s["solved"], s["right"], s["wrong"], fmt(s["cross_arcsec_median"], 1),
                                 fmt(s["ms_median"]), fmt(s["ms_p95"])] for n, s in re_["solvers"].items()]), ""]
        if re_["unavailable"]:
            out += ["Not measured: " + "; ".join(f"{k}: {v}" for k, v in re_["unavailable"].items()), ""]
    return "\n".join(out)


def split_table(rs: list[dict[str, Any]], sk: list[str]) -> list[str]:
    """The same frames, split by outcome (:func:`split_by_peer`), for each peer of the sweep."""
    peers = list((rs[0].get("split") or {}) if sk else {})
    if not peers:
        return []
    head = ["value"] + [f"{sk[0]} · {p}: both right n / mean ms / median ms; only skyfix n / mean ms" for p in peers]
    body = []
    for r in rs:
        cells = [f"{r['value']:g}"]
        for p in peers:
            x = r["split"][p]
            cells.append(f"{x['both']} / {fmt(x['both_skyfix_ms_mean'])} vs {fmt(x['both_peer_ms_mean'])} / "
                         f"{fmt(x['both_skyfix_ms_median'])} vs {fmt(x['both_peer_ms_median'])}; "
                         f"{x['only_skyfix']} / {fmt(x['only_skyfix_ms_mean'])}")
        body.append(cells)
    return ["The same frames by outcome (skyfix vs the peer on frames both solve right; skyfix's time on the "
            "frames only it solves right):", "", md_table(head, body), ""]


def goals(res: dict[str, Any]) -> list[str]:
    """Where skyfix (its first entry, normally auto) falls short of the goals, point by point."""
    lose_rate, lose_wrong, lose_time, n = [], [], [], 0
    for r in res["sweeps"]:
        names = list(r["solvers"])
        sk = next((n for n in names if n.startswith("skyfix")), None)
        peers = [n for n in names if not n.startswith("skyfix")]
        if not sk or not peers:
            continue
        n += 1
        s = r["solvers"][sk]
        best = max(peers, key=lambda p: r["solvers"][p]["rate"] or 0)
        where = f"{r['camera']} {r['sweep']} {r['value']:g}"
        if (s["rate"] or 0) < (r["solvers"][best]["rate"] or 0):
            lose_rate.append(f"{where} ({fmt(s['rate'], 1, True)} < {best} {fmt(r['solvers'][best]['rate'], 1, True)})")
        fewest = min(r["solvers"][p]["wrong"] for p in peers)
        if s["wrong"] > 0 and s["wrong"] >= fewest:
            lose_wrong.append(f"{where} ({s['wrong']} wrong, best peer {fewest})")
        ra = r.get("ratio") or {}
        if ra.get(sk, 0) > 1:
            lose_time.append((r["camera"], ra[sk]))
    if not n:
        return []
    out = ["### Goals (skyfix = its first solver in the tables)", "",
           f"Over {n} scenario points: skyfix solves at least as many frames right as the best peer in "
           f"{n - len(lose_rate)}, has fewer wrong answers (or none) in {n - len(lose_wrong)}, and is no slower "
           f"(median) than the fastest peer in {n - len(lose_time)}.", ""]
    for title, xs in (("Fewer right than the best peer", lose_rate), ("Wrong answers not below the peers'", lose_wrong)):
        if xs:
            out += [f"- {title}: " + "; ".join(xs)]
    if lose_time:
        per = {}
        for cam, x in lose_time:
            per.setdefault(cam, []).append(x)
        out += ["- Slower than the fastest peer (skyfix median / fastest peer's median, per camera: min, median, "
                "max over the points where skyfix is slower): " + "; ".join(
                    f"{c} {len(xs)} points, {min(xs):.1f}x / {sorted(xs)[len(xs) // 2]:.1f}x / {max(xs):.1f}x"
                    for c, xs in per.items())]
    return out + [""]


def plot(path: Path, cam: str, sweep: str, rows: list[dict[str, Any]]) -> None:
    try:
        import matplotlib
    except ImportError:
        return
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (a1, a2) = plt.subplots(1, 2, figsize=(11, 4.2))
    for n in rows[0]["solvers"]:
        x = [r["value"] for r in rows]
        (ln,) = a1.plot(x, [100 * (r["solvers"][n]["rate"] or 0) for r in rows], "o-", label=n)
        a2.plot(x, [r["solvers"][n]["ms_median"] for r in rows], "o-", color=ln.get_color(), label=n)
        a2.plot(x, [r["solvers"][n]["ms_p95"] for r in rows], ":", color=ln.get_color())
    for a, t, y in ((a1, "identified right (%)", "rate"), (a2, "ms per frame (solid median, dotted p95)", "time")):
        a.set_xlabel(SWEEPS[sweep].label)
        a.set_ylabel(t)
        a.set_title(f"{cam}: {y}")
        a.grid(alpha=0.3, which="both")
    a2.set_yscale("log")
    a1.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def parse(argv: list[str] | None = None) -> argparse.Namespace:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--camera", default="all", help="preset(s), comma-separated, all, or none (real images only)")
    ap.add_argument("--sweep", default="all", help="noise, false, magnoise (comma-separated) or all")
    ap.add_argument("--frames", type=int, default=1000)
    ap.add_argument("--values", default=None, help="override the sweep's values, comma-separated")
    ap.add_argument("--skyfix", default="auto," + ",".join(method_names()),
                    help="skyfix methods to run (auto first: it is the one the goals compare)")
    ap.add_argument("--peers", default="tetra3rs,tetra3rs-0.002,cedar")
    ap.add_argument("--skyfix-db", default="default,camera",
                    help="skyfix's databases: default (the default set, as the README serves it, with auto), "
                         "camera (one built for each camera), comma-separated")
    ap.add_argument("--no-real", dest="real", action="store_false", help="skip the real images")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--order", choices=ORDERS, default="rotating",
                    help="rotating: every solver on each frame in turn; blocked: each solver on all of a point's "
                         "frames in turn (as a batch job runs one solver)")
    ap.add_argument("--db-dir", default=str(OUT / "db"))
    ap.add_argument("--reuse-db", action="store_true", help="keep skyfix databases built by an earlier run")
    ap.add_argument("--rebuild-peers", action="store_true", help="rebuild the peers' cached databases")
    ap.add_argument("--no-plot", action="store_true")
    ap.add_argument("--out", default=str(OUT), help="output directory (default bench/out)")
    a = ap.parse_args(argv)
    a.camera, a.sweep = a.camera.split(","), a.sweep.split(",")
    a.skyfix, a.peers = a.skyfix.split(","), a.peers.split(",")
    a.skyfix_db = a.skyfix_db.split(",")
    a.values = [float(v) for v in a.values.split(",")] if a.values else None
    for c in a.camera:
        if c not in ("all", "none") and c not in PRESETS:
            ap.error(f"unknown camera {c!r}")
    return a


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    if argv[:1] == ["--render"]:  # re-render the markdown of an earlier run: --render peers.json [out.md]
        res = json.loads(Path(argv[1]).read_text())
        args = argparse.Namespace(**res["args"])
        md = render(res, args, res["machine"], res["command"])
        Path(argv[2] if len(argv) > 2 else Path(argv[1]).with_suffix(".md")).write_text(md)
        return 0
    return run(parse(argv))


if __name__ == "__main__":
    sys.exit(main())
