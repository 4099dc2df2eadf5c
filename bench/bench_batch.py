"""Batch throughput from the command line: `skyfix solve --workers N` on a recording, frames/s.

    python -m bench.bench_batch --frames 10000 --workers 1,2

The recording is made once with `skyfix sim` (default: the 12-deg camera of issue 11, 1024 px,
6.0 Mv, 0.5 px centroid noise, 2 false stars) and solved by `skyfix solve --sigma NOISE
--workers N` in a subprocess (BLAS/OpenMP threads pinned to 1), on the default database unless
``--db``. Per run: wall time of the whole command and frames/s over it; the command's start
(import, open, warm-up: the same command on a one-frame recording); frames/s of solving as
the command prints it (reading, solving, writing, after the warm-up); the CPU seconds of the
command and its workers per frame; the share identified and wrong answers it printed.
Each worker count runs ``--repeat`` times (default 3), the counts in turn, and the median
run of each is reported with every run's frames/s: one run of 10,000 frames lasts about a
second, and on this shared 2-core VM two runs in a row differ by up to 10%.
The machine's load average is printed beside the table: on a shared machine the wall times
(and so the speed-up of N workers) hold only when nothing else runs.
"""

from __future__ import annotations

from . import common  # noqa: F401  (pins threads before numpy)

import argparse  # noqa: E402
import os  # noqa: E402
import resource  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from collections.abc import Sequence  # noqa: E402
from pathlib import Path  # noqa: E402
from typing import Any  # noqa: E402

SKYFIX = [sys.executable, "-c", "from service.cli import main; main()"]


def _children_cpu() -> float:
    ru = resource.getrusage(resource.RUSAGE_CHILDREN)
    return ru.ru_utime + ru.ru_stime


def run_solve(recording: Path, workers: int, noise: float, db: str | None) -> dict[str, Any]:
    """Time one `skyfix solve` of ``recording`` on ``workers``; its summary line as printed."""
    cmd = [*SKYFIX, "solve", str(recording), "--sigma", str(noise), "--workers", str(workers)]
    if db:
        cmd += ["--db", db]
    cpu0, t0 = _children_cpu(), time.perf_counter()
    proc = subprocess.run(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True,
                          env=common.pin_threads(dict(os.environ)), timeout=3600)
    wall, cpu = time.perf_counter() - t0, _children_cpu() - cpu0
    if proc.returncode != 0:
        raise RuntimeError(f"skyfix solve failed: {proc.stderr[-2000:]}")
    return {"wall_s": wall, "cpu_s": cpu, "summary": proc.stderr.strip().splitlines()[-1]}


def make_recording(path: Path, args: argparse.Namespace, n: int) -> Path:
    if not path.is_file():
        cmd = [*SKYFIX, "sim", "--out", str(path), "--n", str(n), "--fov", str(args.fov), "--width", "1024",
               "--height", "1024", "--mag-limit", str(args.mag_limit), "--noise", str(args.noise),
               "--false-stars", str(args.false_stars), "--seed", str(args.seed)]
        subprocess.run(cmd, check=True, capture_output=True, env=common.pin_threads(dict(os.environ)))
    return path


def main(argv: Sequence[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=10_000)
    ap.add_argument("--workers", default="1,2", help="comma-separated worker counts")
    ap.add_argument("--fov", type=float, default=12.0)
    ap.add_argument("--mag-limit", type=float, default=6.0)
    ap.add_argument("--noise", type=float, default=0.5)
    ap.add_argument("--false-stars", type=int, default=2)
    ap.add_argument("--seed", type=int, default=2)
    ap.add_argument("--repeat", type=int, default=3, help="runs of each worker count (the median is reported)")
    ap.add_argument("--db", default=None, help="database directory (default: the default database)")
    ap.add_argument("--out", type=Path, default=common.OUT / "batch")
    args = ap.parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)
    stem = (f"fov{args.fov:g}_mag{args.mag_limit:g}_noise{args.noise:g}_false{args.false_stars}"
            f"_seed{args.seed}")
    rec = make_recording(args.out / f"{stem}_n{args.frames}.jsonl", args, args.frames)
    one = args.out / f"{stem}_n1.jsonl"
    with rec.open() as f:
        one.write_text(f.readline())
    info = common.machine_info()
    counts = [int(x) for x in args.workers.split(",")]
    runs: dict[int, list[dict[str, Any]]] = {w: [] for w in counts}
    for _ in range(args.repeat):  # the worker counts in turn, so a slow spell hits them alike
        for w in counts:
            start = run_solve(one, w, args.noise, args.db)["wall_s"]
            r = run_solve(rec, w, args.noise, args.db)
            solving = float(r["summary"].rsplit(" frames/s", 1)[0].rsplit(" ", 1)[1])
            r.update(workers=w, start_s=start, frames=args.frames, fps=args.frames / r["wall_s"],
                     fps_solving=solving, cpu_ms_per_frame=1e3 * r["cpu_s"] / args.frames)
            runs[w].append(r)
    rows, results = [], []
    for w in counts:
        r = sorted(runs[w], key=lambda x: x["fps_solving"])[len(runs[w]) // 2]  # the median run
        results.append(r)
        rows.append([w, f"{r['wall_s']:.2f}", f"{r['start_s']:.2f}", f"{r['fps']:.0f}", f"{r['fps_solving']:.0f}",
                     " ".join(f"{x['fps_solving']:.0f}" for x in runs[w]),
                     f"{r['cpu_ms_per_frame']:.3f}", r["summary"].split(";")[0]])
    base = results[0]["fps_solving"]
    print(f"recording: {rec} ({args.frames} frames); each worker count run {args.repeat} times in turn, "
          "the median run shown")
    print(common.md_table(["workers", "wall s", "start s (1 frame)", "frames/s (wall)", "frames/s (solving)",
                           "frames/s (solving), every run", "CPU ms/frame", "answers"], rows))
    for r in results[1:]:
        per_run = [b["fps_solving"] / a["fps_solving"] for a, b in zip(runs[counts[0]], runs[r["workers"]], strict=True)]
        print(f"speed-up of {r['workers']} workers over {results[0]['workers']} (solving, medians): "
              f"{r['fps_solving'] / base:.2f}x; run by run: {' '.join(f'{x:.2f}x' for x in per_run)}")
    print(f"load average after: {[round(x, 2) for x in os.getloadavg()]}")
    print(common.machine_line(info))
    common.write_json(args.out / "bench_batch.json",
                      {"args": vars(args), "machine": info, "results": results,
                       "runs": {str(w): runs[w] for w in counts}})


if __name__ == "__main__":
    main()
