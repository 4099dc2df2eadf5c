"""skyfix reprocess on a local Dask cluster against skyfix solve, from the command line.

    python -m bench.bench_reprocess --frames 100000 --workdir /tmp/rp            # every step
    python -m bench.bench_reprocess --frames 100000 --workdir /tmp/rp --step solve   # one step

A recording of the 12-deg camera (1024 px, 6.0 Mv, 0.5 px, 2 false stars; ``skyfix sim``)
is solved by ``skyfix solve --workers 1`` (one process) and by ``skyfix reprocess --local 1``
and ``--local 2`` (LocalCluster worker processes), each a fresh command on the default
database, timed over the whole command (start-up, cluster start, warm-up and writing
included). The scheduler's overhead per partition is measured apart: the same 2,000 frames in
partitions of 20 and of 2,000 (the difference per extra partition). ``report`` prints the
table and the paper estimate of the workers a 3e8-frame campaign needs to finish in 4 hours.

Steps (``--step``, default all in order): sim, solve, local1, local2, overhead, report. The
recording and each step's time stay in ``--workdir`` (``times.json``), so the steps can run as
separate commands on a shared machine.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import time
from collections.abc import Sequence
from pathlib import Path

SKYFIX = [sys.executable, "-c", "from service.cli import main; main()"]
STEPS = ("sim", "solve", "local1", "local2", "overhead", "report")


def _run(args: list[str]) -> float:
    t0 = time.perf_counter()
    with open(os.devnull, "w") as null:
        done = subprocess.run([*SKYFIX, *args], stdout=null, stderr=subprocess.PIPE, text=True, check=False)
    if done.returncode != 0:
        raise SystemExit(f"skyfix {' '.join(args)} failed: {done.stderr[-2000:]}")
    return time.perf_counter() - t0


def _roundtrip_ms(n: int = 500) -> float:
    """A trivial task's round trip through a LocalCluster of one worker process (ms a task,
    ``n`` tasks submitted at once, as reprocess submits its partitions)."""
    from distributed import Client, LocalCluster

    with LocalCluster(n_workers=1, threads_per_worker=1, processes=True, dashboard_address=":0") as lc, \
            Client(lc) as client:
        client.gather(client.map(abs, range(-50, 0), pure=False))  # connections warm
        t0 = time.perf_counter()
        client.gather(client.map(abs, range(-n, 0), pure=False))
        return (time.perf_counter() - t0) / n * 1e3


def _step(name: str, rec: Path, work: Path, args: argparse.Namespace) -> dict[str, float]:
    if name == "sim":
        _run(["sim", "--out", str(rec), "--n", str(args.frames), "--fov", "12", "--mag-limit", "6.0",
              "--noise", "0.5", "--false-stars", "2", "--seed", "7"])
        _run(["db", "info"])  # the default database built before anything is timed
        return {}
    if name == "solve":
        return {"solve": _run(["solve", str(rec), "--workers", "1"])}
    if name in ("local1", "local2"):
        out = work / f"out-{name}"
        shutil.rmtree(out, ignore_errors=True)
        t = _run(["reprocess", str(rec), "--out", str(out), "--local", name[-1],
                  "--partition-frames", str(args.partition_frames)])
        shutil.rmtree(out)
        return {name: t}
    if name == "overhead":
        small = work / "small.jsonl"
        with open(rec) as src, open(small, "w") as dst:
            for i, line in enumerate(src):
                if i == 2000:
                    break
                dst.write(line)
        lines = sum(1 for _ in open(small))
        times = {"overhead_lines": float(lines), "roundtrip_ms": _roundtrip_ms()}
        for key, size in (("few", lines), ("many", 20)):
            shutil.rmtree(work / key, ignore_errors=True)
            times[key] = _run(["reprocess", str(small), "--out", str(work / key), "--local", "1",
                               "--partition-frames", str(size)])
        return times
    return {}


def report(t: dict[str, float], args: argparse.Namespace) -> None:
    print(f"{args.frames:,} frames, 12-deg camera, partitions of {args.partition_frames:,}; "
          f"{os.cpu_count()} cores, load average {os.getloadavg()[0]:.1f}\n")
    print("| command | wall s | frames/s | vs skyfix solve |\n|---|---|---|---|")
    rows = [("skyfix solve --workers 1", "solve"), ("skyfix reprocess --local 1", "local1"),
            ("skyfix reprocess --local 2", "local2")]
    for name, key in rows:
        if key in t:
            print(f"| `{name}` | {t[key]:.1f} | {args.frames / t[key]:,.0f} | "
                  f"{t['solve'] / t[key] if 'solve' in t else float('nan'):.2f}x |")
    if "many" in t:
        lines = int(t["overhead_lines"])
        many = -(-lines // 20)
        overhead_ms = (t["many"] - t["few"]) / (many - 1) * 1e3
        print(f"\nScheduler overhead per partition: a trivial task's round trip {t['roundtrip_ms']:.2f} ms "
              f"(500 at once, one worker process); {overhead_ms:.1f} ms per extra partition in skyfix reprocess "
              f"({lines:,} frames as {many} partitions of 20 vs 1 of {lines:,} on one worker: "
              f"{t['many']:.1f} s vs {t['few']:.1f} s).")
    if "local1" in t:
        per_worker = args.frames / t["local1"]
        workers = 3e8 / (4 * 3600 * per_worker)
        print(f"Paper estimate: one worker process does {per_worker:,.0f} frames/s here, so 3e8 frames in 4 h "
              f"({3e8 / 14400:,.0f} frames/s) need about {workers:,.0f} such workers (cores), e.g. "
              f"{-(-workers // 32):,.0f} nodes of 32 cores, if the file system keeps up.")


def main(argv: Sequence[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    ap.add_argument("--frames", type=int, default=100_000)
    ap.add_argument("--partition-frames", type=int, default=5000)
    ap.add_argument("--workdir", type=Path, default=None, help="kept between steps (default: a temporary one)")
    ap.add_argument("--step", choices=STEPS, action="append", help="run only these steps (repeatable)")
    args = ap.parse_args(argv)
    work = args.workdir or Path(f"/tmp/skyfix-bench-reprocess-{os.getpid()}")
    work.mkdir(parents=True, exist_ok=True)
    rec, store = work / "frames.jsonl", work / "times.json"
    times = json.loads(store.read_text()) if store.is_file() else {}
    try:
        for name in args.step or STEPS:
            if name == "report":
                report(times, args)
                continue
            if name != "sim" and not rec.is_file():
                _step("sim", rec, work, args)
            times.update(_step(name, rec, work, args))
            store.write_text(json.dumps(times))
    finally:
        if args.workdir is None:
            shutil.rmtree(work, ignore_errors=True)


if __name__ == "__main__":
    main()
