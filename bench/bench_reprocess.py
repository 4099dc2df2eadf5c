"""skyfix reprocess on a local Dask cluster against skyfix solve, from the command line.

    python -m bench.bench_reprocess --frames 100000 [--partition-frames 5000]

A recording of the 12-deg camera (1024 px, 6.0 Mv, 0.5 px, 2 false stars; ``skyfix sim``)
is solved by ``skyfix solve --workers 1`` (one process) and by ``skyfix reprocess --local 1``
and ``--local 2`` (LocalCluster worker processes), each a fresh command on the default
database, timed over the whole command (start-up, cluster start, warm-up and writing
included). The scheduler's overhead per partition is measured apart: the same 2,000 frames in
partitions of 20 and of 2,000 (the difference per extra partition). Ends with the paper
estimate of the workers a 3e8-frame campaign needs to finish in 4 hours.
"""

from __future__ import annotations

import argparse
import os
import shutil
import subprocess
import sys
import tempfile
import time
from collections.abc import Sequence
from pathlib import Path

SKYFIX = [sys.executable, "-c", "from service.cli import main; main()"]


def _run(args: list[str], stdout: int | None = subprocess.DEVNULL) -> float:
    t0 = time.perf_counter()
    done = subprocess.run([*SKYFIX, *args], stdout=stdout, stderr=subprocess.PIPE, text=True, check=False)
    if done.returncode != 0:
        raise SystemExit(f"skyfix {' '.join(args)} failed: {done.stderr[-2000:]}")
    return time.perf_counter() - t0


def main(argv: Sequence[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=100_000)
    ap.add_argument("--partition-frames", type=int, default=5000)
    args = ap.parse_args(argv)
    tmp = Path(tempfile.mkdtemp(prefix="skyfix-reprocess-"))
    try:
        rec = tmp / "frames.jsonl"
        _run(["sim", "--out", str(rec), "--n", str(args.frames), "--fov", "12", "--mag-limit", "6.0",
              "--noise", "0.5", "--false-stars", "2", "--seed", "7"])
        _run(["solve", str(rec), "--workers", "1"])  # the default database built and kernels cached
        rows = []
        with open(os.devnull, "w") as null:
            t = _run(["solve", str(rec), "--workers", "1"], stdout=null.fileno())
        rows.append(("skyfix solve --workers 1", t))
        for n in (1, 2):
            out = tmp / f"out{n}"
            t = _run(["reprocess", str(rec), "--out", str(out), "--local", str(n),
                      "--partition-frames", str(args.partition_frames)])
            rows.append((f"skyfix reprocess --local {n}", t))
            shutil.rmtree(out)
        small = tmp / "small.jsonl"
        with open(rec) as src, open(small, "w") as dst:
            for i, line in enumerate(src):
                if i == 2000:
                    break
                dst.write(line)
        t_few = _run(["reprocess", str(small), "--out", str(tmp / "few"), "--local", "1", "--partition-frames", "2000"])
        t_many = _run(["reprocess", str(small), "--out", str(tmp / "many"), "--local", "1", "--partition-frames", "20"])
        overhead_ms = (t_many - t_few) / (100 - 1) * 1e3
        print(f"{args.frames:,} frames, 12-deg camera, partitions of {args.partition_frames:,}; "
              f"{os.cpu_count()} cores, load average {os.getloadavg()[0]:.1f}\n")
        print("| command | wall s | frames/s | vs skyfix solve |\n|---|---|---|---|")
        base = rows[0][1]
        for name, t in rows:
            print(f"| `{name}` | {t:.1f} | {args.frames / t:,.0f} | {base / t:.2f}x |")
        per_worker = args.frames / rows[1][1]
        workers = 3e8 / (4 * 3600 * per_worker)
        print(f"\nScheduler overhead per partition: {overhead_ms:.1f} ms (2,000 frames as 100 partitions of 20 "
              f"vs 1 of 2,000: {t_many:.1f} s vs {t_few:.1f} s).")
        print(f"Paper estimate: one worker process does {per_worker:,.0f} frames/s here, so 3e8 frames in 4 h "
              f"({3e8 / 14400:,.0f} frames/s) need about {workers:,.0f} such workers (cores), e.g. "
              f"{workers / 32:,.0f} nodes of 32 cores, if the file system keeps up.")
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


if __name__ == "__main__":
    main()
