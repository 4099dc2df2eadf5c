"""Star detection and centroiding: speed, accuracy vs SNR, false alarms, real images.

    python -m bench.bench_centroid --out bench/out            # full run, ~1 min
    python -m bench.bench_centroid --out bench/out --quick    # fewer repeats and fields
    python -m bench.bench_centroid --against HEAD~3           # detection time, that commit vs now

Writes ``centroid.md`` (markdown tables), ``centroid.json`` and ``centroid_rms_vs_snr.png``
into ``--out``:

- **timing**: :func:`service.core.centroid.extract` on rendered 16-bit frames, 1024x1024 with
  300 stars and 4096x4096 with 3000 (PSF sigma 1 px, background 100, read noise 5, 50 hot
  pixels), median and p95 over repeats, wall clock on this machine, default OpenCV threads,
  and the least CPU time (``process_time``, all threads) of the repeats.
- **against** (``--against REV``, instead of everything else): the same frames timed with
  ``service/core/centroid`` as committed at git ``REV`` and as it is now, alternately in one
  process, so that the machine's load hits both alike; least wall and CPU time of the repeats.
- **accuracy**: random fields, SNR log-uniform in [3, 300] (``render.star_snr``: the SNR of an
  ideal PSF fit), stars >= 5 px apart (7 px for the 1.6 px PSF); per SNR bin the completeness
  (a detection within 1 px) and the 2-D RMS error of the matched stars, next to the
  Cramer-Rao bound ``2 sigma / SNR`` of a background-limited Gaussian star (photon-limited
  bright stars can do better, down to ``sqrt(2) sigma / SNR``).
- **false alarms** per megapixel on pure-noise frames (16-bit and 8-bit).
- **deblending**: how often both stars of a pair are found (within 0.5 px) by separation and
  flux ratio.
- **real images** (when ../shared/data/real exists): listed catalogue stars found within 2 px.
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import os
import platform
import re
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import cv2
import numpy as np
from scipy.spatial import cKDTree

from service.core.centroid import decode_image, extract
from service.core.render import random_positions, render_image, star_snr

SNR_BINS = [(5, 10), (10, 20), (20, 40), (40, 80), (80, 160), (160, 300), (20, 300)]


def _flux_for_snr(snr: np.ndarray, sigma: float) -> np.ndarray:
    """Invert :func:`star_snr` (background 100, read noise 5) by interpolation."""
    grid = np.geomspace(1.0, 1e8, 4000)
    return np.interp(snr, star_snr(grid, psf_sigma_px=sigma, background=100.0, read_noise=5.0), grid)


def _timing_frames() -> list[tuple[int, int, np.ndarray]]:
    """(size, stars, 16-bit frame) for the timing runs."""
    frames = []
    for size, n_stars in ((1024, 300), (4096, 3000)):
        rng = np.random.default_rng(size)
        xy = random_positions(n_stars, width=size, height=size, rng=rng)
        flux = _flux_for_snr(10 ** rng.uniform(np.log10(3), np.log10(300), n_stars), 1.0)
        img = render_image(xy, flux, width=size, height=size, hot_pixels=50, rng=rng)
        frames.append((size, n_stars, img))
    return frames


def _timed(fn: Callable[..., Any], *args: Any) -> tuple[float, float, Any]:
    """Wall and CPU seconds of one call ``fn(*args)``, and its result."""
    t0, c0 = time.perf_counter(), time.process_time()
    out = fn(*args)
    return time.perf_counter() - t0, time.process_time() - c0, out


def bench_timing(repeats: int) -> list[dict[str, Any]]:
    rows = []
    for size, n_stars, img in _timing_frames():
        reps = repeats if size <= 1024 else max(5, repeats // 2)
        extract(img)  # warm-up
        runs = [_timed(extract, img) for _ in range(reps)]
        ms = np.array([r[0] for r in runs]) * 1e3
        rows.append({"size": f"{size}x{size}", "stars": n_stars, "repeats": reps,
                     "detected": len(runs[-1][2]), "median_ms": float(np.median(ms)),
                     "p95_ms": float(np.percentile(ms, 95)), "min_ms": float(ms.min()),
                     "cpu_min_ms": min(r[1] for r in runs) * 1e3})
    return rows


def extract_at(rev: str) -> Callable[..., Any]:
    """``extract`` of ``service/core/centroid`` as committed at git ``rev``, imported from a
    temporary copy (its ``..`` imports pointed at today's ``service.core``)."""
    root = Path(__file__).resolve().parents[1]
    git = ["git", "-C", str(root)]
    names = subprocess.run([*git, "ls-tree", "--name-only", rev, "service/core/centroid/"], check=True,
                           capture_output=True, text=True).stdout.split()
    pkg = Path(tempfile.mkdtemp(prefix="centroid_at_")) / "centroid_at_rev"
    pkg.mkdir()
    for name in names:
        if name.endswith(".py"):
            text = subprocess.run([*git, "show", f"{rev}:{name}"], check=True, capture_output=True,
                                  text=True).stdout
            (pkg / Path(name).name).write_text(re.sub(r"from \.\.(\w)", r"from service.core.\1", text))
    spec = importlib.util.spec_from_file_location(pkg.name, pkg / "__init__.py",
                                                  submodule_search_locations=[str(pkg)])
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules[pkg.name] = module
    spec.loader.exec_module(module)
    return module.extract  # type: ignore[no-any-return]


def bench_against(rev: str, repeats: int) -> list[dict[str, Any]]:
    """Least wall and CPU time of ``extract`` at ``rev`` and now, called alternately."""
    old = extract_at(rev)
    rows = []
    for size, n_stars, img in _timing_frames():
        reps = repeats if size <= 1024 else max(5, repeats // 2)
        old(img), extract(img)  # warm-up
        runs: dict[str, list[tuple[float, float, Any]]] = {"old": [], "new": []}
        for _ in range(reps):
            runs["old"].append(_timed(old, img))
            runs["new"].append(_timed(extract, img))
        best = {k: (min(r[0] for r in v) * 1e3, min(r[1] for r in v) * 1e3) for k, v in runs.items()}
        rows.append({"size": f"{size}x{size}", "stars": n_stars, "repeats": reps,
                     "old_wall_ms": best["old"][0], "new_wall_ms": best["new"][0],
                     "wall_ratio": best["old"][0] / best["new"][0],
                     "old_cpu_ms": best["old"][1], "new_cpu_ms": best["new"][1],
                     "cpu_ratio": best["old"][1] / best["new"][1],
                     "same_detections": bool(np.array_equal(runs["old"][-1][2].centroids.xy,
                                                            runs["new"][-1][2].centroids.xy))})
    return rows


def bench_accuracy(fields: int) -> dict[str, dict[str, Any]]:
    out: dict[str, dict[str, Any]] = {}
    for sigma, sep in ((1.0, 5.0), (1.6, 7.0)):
        dists, snrs, false, n_det = [], [], 0, 0
        for seed in range(fields):
            rng = np.random.default_rng(1000 + seed)
            xy = random_positions(300, width=1024, height=1024, min_separation_px=sep, rng=rng)
            snr = 10 ** rng.uniform(np.log10(3), np.log10(300), len(xy))
            flux = _flux_for_snr(snr, sigma)
            img = render_image(xy, flux, width=1024, height=1024, psf_sigma_px=sigma, rng=rng)
            det = extract(img, max_stars=None)
            dist, _ = cKDTree(det.centroids.xy).query(xy)
            back, _ = cKDTree(xy).query(det.centroids.xy)
            dists.append(dist)
            snrs.append(snr)
            false += int((back > 2.0).sum())
            n_det += len(det)
        dist, snr = np.concatenate(dists), np.concatenate(snrs)
        rows = []
        for lo, hi in SNR_BINS:
            sel = (snr >= lo) & (snr < hi)
            hit = sel & (dist <= 1.0)
            rms = float(np.sqrt(np.mean(dist[hit] ** 2))) if hit.any() else float("nan")
            bound = float(np.sqrt(np.mean((2 * sigma / snr[hit]) ** 2))) if hit.any() else float("nan")
            rows.append({"snr": f"[{lo}, {hi})", "stars": int(sel.sum()),
                         "completeness": float(hit.sum() / max(sel.sum(), 1)),
                         "rms_px": rms, "crlb_px": bound})
        out[f"psf_sigma={sigma}"] = {"bins": rows, "false": false, "detections": n_det, "fields": fields,
                                     "min_separation_px": sep}
    return out


def bench_false_alarms(frames: int) -> list[dict[str, Any]]:
    rows = []
    for label, kw in (("16-bit, bg 100, rn 5", {}),
                      ("8-bit, bg 8, rn 2", {"bit_depth": 8, "background": 8.0, "read_noise": 2.0})):
        count = 0
        for seed in range(frames):
            img = render_image(np.zeros((0, 2)), [], width=1024, height=1024, rng=5000 + seed,
                               **kw)  # type: ignore[arg-type]
            count += len(extract(img, max_stars=None))
        mp = frames * 1024 * 1024 / 1e6
        rows.append({"frames": label, "megapixels": mp, "false": count, "per_megapixel": count / mp})
    return rows


def bench_deblend(trials: int) -> dict[str, list[float]]:
    rng = np.random.default_rng(7)
    seps = [3, 4, 5, 6, 7, 8]
    table: dict[str, list[float]] = {}
    for ratio in (1, 3, 10, 30):
        row = []
        for sep in seps:
            ok = 0
            for _ in range(trials):
                ang = rng.uniform(0, 2 * np.pi)
                c = np.array([32.0, 32.0]) + rng.random(2)
                xy = np.array([c, c + sep * np.array([np.cos(ang), np.sin(ang)])])
                img = render_image(xy, [20000.0, 20000.0 / ratio], width=64, height=64, rng=rng)
                det = extract(img)
                ok += bool(len(det) and np.all(cKDTree(det.centroids.xy).query(xy)[0] < 0.5))
            row.append(ok / trials)
        table[f"{ratio}:1"] = row
    table["separation_px"] = [float(s) for s in seps]
    return table


def bench_real(root: Path) -> list[dict[str, Any]]:
    path = root / "matches.json"
    if not path.is_file():
        return []
    rows = []
    for name, entry in sorted(json.loads(path.read_text())["images"].items()):
        img = decode_image((root / name).read_bytes())
        truth = np.array([[m["x"] - 0.5, m["y"] - 0.5] for m in entry["matches"]])
        t0 = time.perf_counter()
        det = extract(img, max_stars=None)
        ms = (time.perf_counter() - t0) * 1e3
        dist, rank = cKDTree(det.centroids.xy).query(truth)
        found = dist <= 2.0
        rows.append({"image": name, "shape": f"{img.shape[1]}x{img.shape[0]}", "listed": len(truth),
                     "found": int(found.sum()), "top30": int((found & (rank < 30)).sum()),
                     "top200": int((found & (rank < 200)).sum()), "detections": len(det),
                     "median_offset_px": float(np.median(dist[found])) if found.any() else float("nan"),
                     "ms": ms})
    return rows


def _table(rows: list[dict[str, Any]], cols: list[str]) -> str:
    def fmt(v: Any) -> str:
        if isinstance(v, float):
            return "-" if np.isnan(v) else f"{v:.3f}" if abs(v) < 10 else f"{v:.1f}"
        return str(v)

    lines = ["| " + " | ".join(cols) + " |", "|" + "---|" * len(cols)]
    lines += ["| " + " | ".join(fmt(r[c]) for c in cols) + " |" for r in rows]
    return "\n".join(lines)


def _plot(acc: dict[str, dict[str, Any]], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6, 4))
    for key, entry in acc.items():
        rows = [r for r in entry["bins"] if r["snr"] != "[20, 300)"]
        lo = [float(r["snr"].strip("[)").split(",")[0]) for r in rows]
        hi = [float(r["snr"].strip("[)").split(",")[1]) for r in rows]
        mid = np.sqrt(np.array(lo) * np.array(hi))
        line = ax.loglog(mid, [r["rms_px"] for r in rows], "o-", label=f"extract, {key}")[0]
        ax.loglog(mid, [r["crlb_px"] for r in rows], "--", color=line.get_color(), alpha=0.6,
                  label=f"2 sigma / SNR (background-limited bound), {key}")
    ax.axhline(0.1, color="grey", lw=0.8)
    ax.set_xlabel("star SNR (ideal PSF fit)")
    ax.set_ylabel("centroid RMS error, px (2-D)")
    ax.set_title("Centroid error vs SNR (rendered 1024x1024 fields)")
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=Path("bench/out"))
    ap.add_argument("--quick", action="store_true", help="fewer repeats and fields")
    default_real = os.environ.get("SKYFIX_REAL_DATA") or str(
        Path(__file__).resolve().parents[1] / ".." / "shared" / "data" / "real")
    ap.add_argument("--real", type=Path, default=Path(default_real), help="dir holding matches.json")
    ap.add_argument("--against", metavar="REV", help="only time detection at git REV against now")
    args = ap.parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)
    q = args.quick
    if args.against:
        rows = bench_against(args.against, 10 if q else 30)
        md_against = "\n".join([
            f"# Detection time, {args.against} vs now", "",
            f"`python -m bench.bench_centroid --against {args.against}{' --quick' if q else ''}` — "
            f"{os.cpu_count()} CPUs, load average {os.getloadavg()[0]:.2f} at the start; least of the "
            "repeats, old and new called alternately.", "",
            _table(rows, ["size", "stars", "repeats", "old_wall_ms", "new_wall_ms", "wall_ratio",
                          "old_cpu_ms", "new_cpu_ms", "cpu_ratio", "same_detections"]), ""])
        (args.out / "centroid_against.md").write_text(md_against)
        print(md_against)  # noqa: T201
        return
    result: dict[str, Any] = {
        "machine": {"python": platform.python_version(), "cpus": os.cpu_count(), "numpy": np.__version__,
                    "opencv": cv2.__version__, "opencv_threads": cv2.getNumThreads(),
                    "load_avg_1min": os.getloadavg()[0]},
        "timing": bench_timing(10 if q else 40),
        "accuracy": bench_accuracy(3 if q else 10),
        "false_alarms": bench_false_alarms(4 if q else 16),
        "deblend": bench_deblend(5 if q else 20),
        "real": bench_real(args.real),
    }
    md = ["# Centroiding benchmark", "",
          f"`python -m bench.bench_centroid --out {args.out}{' --quick' if q else ''}` — "
          f"Python {result['machine']['python']}, {result['machine']['cpus']} CPUs, numpy "
          f"{result['machine']['numpy']}, OpenCV {result['machine']['opencv']}, load average "
          f"{result['machine']['load_avg_1min']:.2f} at the start.", "",
          "## Detection time (extract, 16-bit)", "",
          _table(result["timing"], ["size", "stars", "detected", "repeats", "median_ms", "p95_ms", "min_ms",
                                    "cpu_min_ms"]),
          ""]
    for key, acc in result["accuracy"].items():
        md += [f"## Accuracy vs SNR, {key} px", "",
               f"{acc['fields']} fields of 1024x1024 with 300 stars "
               f">= {acc['min_separation_px']:.0f} px apart; "
               f"completeness = a detection within 1 px; rms_px over those; crlb_px = RMS of 2 sigma / SNR "
               f"over the same stars. False detections (> 2 px from every star): {acc['false']} of "
               f"{acc['detections']}.", "",
               _table(acc["bins"], ["snr", "stars", "completeness", "rms_px", "crlb_px"]), ""]
    md += ["## False detections on pure noise", "",
           _table(result["false_alarms"], ["frames", "megapixels", "false", "per_megapixel"]), ""]
    deb = result["deblend"]
    md += ["## Deblending: both stars of a pair found (PSF sigma 1 px, brighter star 20000 counts)", "",
           "| flux ratio | " + " | ".join(f"{s:.0f} px" for s in deb["separation_px"]) + " |",
           "|---|" + "---|" * len(deb["separation_px"])]
    md += [f"| {k} | " + " | ".join(f"{v:.2f}" for v in vals) + " |" for k, vals in deb.items()
           if k != "separation_px"]
    md.append("")
    if result["real"]:
        md += ["## Real images: listed catalogue stars found within 2 px (max_stars=None)", "",
               _table(result["real"], ["image", "shape", "listed", "found", "top30", "top200", "detections",
                                       "median_offset_px", "ms"]), ""]
        groups: dict[str, list[int]] = {}
        for r in result["real"]:
            g = groups.setdefault(r["image"].split("/")[0], [0, 0, 0, 0])
            g[0] += r["listed"]
            g[1] += r["found"]
            g[2] += r["top30"]
            g[3] += r["top200"]
        md += ["| group | listed | found | in top 30 | in top 200 |", "|---|---|---|---|---|"]
        md += [f"| {k} | {v[0]} | {v[1]} ({v[1] / v[0]:.0%}) | {v[2]} | {v[3]} |" for k, v in groups.items()]
        md.append("")
    (args.out / "centroid.md").write_text("\n".join(md))
    (args.out / "centroid.json").write_text(json.dumps(result, indent=1))
    _plot(result["accuracy"], args.out / "centroid_rms_vs_snr.png")
    print("\n".join(md))  # noqa: T201


if __name__ == "__main__":
    main()
