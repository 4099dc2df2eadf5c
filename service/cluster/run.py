"""The client side of a reprocessing campaign: plan, skip what is done, submit, record."""

from __future__ import annotations

import hashlib
import json
import logging
import os
import tempfile
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from .partition import Partition, plan_partitions

MANIFEST = "manifest.json"


@dataclass
class ReprocessSummary:
    """What a campaign did: partitions run and skipped, frame counts, solve-time percentiles."""

    partitions: int = 0
    skipped: int = 0
    frames: int = 0
    solved: int = 0
    no_solution: int = 0
    errors: int = 0
    wrong: int = 0
    checked: int = 0
    wall_s: float = 0.0
    ms_percentiles: dict[str, float] = field(default_factory=dict)

    def line(self) -> str:
        pct = self.ms_percentiles
        rate = self.frames / self.wall_s if self.wall_s > 0 else 0.0
        return (f"{self.solved}/{self.frames} identified ({100 * self.solved / max(self.frames, 1):.1f}%), "
                f"{self.no_solution} no_solution, {self.errors} error records, {self.wrong} wrong of {self.checked} "
                f"with truth; solve ms p50 {pct.get('p50', 0):.2f} p95 {pct.get('p95', 0):.2f} p99 "
                f"{pct.get('p99', 0):.2f}; {self.partitions} partitions run, {self.skipped} already done; "
                f"{rate:.0f} frames/s")


def _write_json(path: Path, data: Any) -> None:
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    with os.fdopen(fd, "w") as fh:
        json.dump(data, fh, indent=1)
        fh.flush()
        os.fsync(fh.fileno())
    os.replace(tmp, path)


def _sha256(path: Path) -> str | None:
    try:
        return hashlib.sha256(path.read_bytes()).hexdigest()
    except OSError:
        return None


def done_partitions(out: Path, parts: Sequence[Partition]) -> dict[int, dict[str, Any]]:
    """Partitions of ``parts`` whose output exists and matches the manifest's checksum."""
    try:
        manifest = json.loads((out / MANIFEST).read_text())
    except (OSError, ValueError):
        return {}
    recorded = {p["key"]: p for p in manifest.get("partitions", []) if isinstance(p, dict) and "key" in p}
    done = {}
    for part in parts:
        rec = recorded.get(part.key)
        if rec and rec.get("output") == part.output_name and _sha256(out / part.output_name) == rec.get("sha256"):
            done[part.index] = rec
    return done


def reprocess(
    inputs: Sequence[Path],
    out: Path,
    *,
    cluster: str | None = None,
    local: int | None = None,
    db: Path | None = None,
    method: str = "auto",
    sigma: float = 1.0,
    partition_frames: int = 5000,
    progress: Callable[[int, int, float], None] | None = None,
    client: Any = None,
) -> ReprocessSummary:
    """Solve every frame of ``inputs`` into ``out`` (``part-NNNNN.jsonl`` + ``manifest.json``).

    Parameters
    ----------
    inputs : paths of JSON Lines recordings
    out : output directory (created); partitions already done and verified there are skipped
    cluster : a Dask scheduler address (``tcp://host:8786``), or
    local : the number of worker processes of a ``LocalCluster`` started here (default 1)
    db : database every worker can read (None: the default database, built by each worker)
    partition_frames : lines a partition holds at most
    progress : ``progress(frames_done, frames_total, elapsed_s)`` after each partition
    client : an existing ``distributed.Client`` (tests, notebooks), instead of cluster/local
    """
    from distributed import Client, LocalCluster, as_completed

    from service.core.navdb import ensure_default_database

    from .work import DatabasePlugin, database_checksum, solve_partition

    t0 = time.perf_counter()
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    parts = plan_partitions(inputs, partition_frames)
    done = done_partitions(out, parts)
    db_path = Path(db).resolve() if db is not None else ensure_default_database()
    checksum = database_checksum(db_path)
    manifest: dict[str, Any] = {
        "format": "skyfix-reprocess", "inputs": [str(Path(p).resolve()) for p in inputs],
        "database": {"path": str(db_path) if db is not None else "default", "checksum": checksum},
        "method": method, "sigma_px": sigma, "partition_frames": partition_frames,
        "partitions": [{**p.to_dict(), "key": p.key, **done[p.index]} if p.index in done else
                       {**p.to_dict(), "key": p.key, "status": "pending"} for p in parts],
    }
    for rec in manifest["partitions"]:
        rec.pop("ms", None)
    _write_json(out / MANIFEST, manifest)
    todo = [p for p in parts if p.index not in done]
    summary = ReprocessSummary(partitions=len(todo), skipped=len(done))
    for rec in done.values():
        for k in ("frames", "solved", "no_solution", "errors", "wrong", "checked"):
            setattr(summary, k, getattr(summary, k) + int(rec.get(k, 0)))
    total = sum(p.lines for p in parts)
    ms: list[float] = []
    own = None
    if todo:
        if client is None:
            if cluster:
                own = Client(cluster)
            else:
                # workers' own logs stay quiet (a worker's last heartbeat racing the shutdown
                # logs a harmless traceback); the tasks' errors still reach this client
                lc = LocalCluster(n_workers=local or 1, threads_per_worker=1, processes=True,
                                  dashboard_address=":0", silence_logs=logging.CRITICAL)
                own = Client(lc)
            client = own
        try:
            client.register_plugin(DatabasePlugin(None if db is None else str(db_path), checksum))
            futures = {client.submit(solve_partition, p.to_dict(), str(out.resolve()), method, sigma,
                                     key=f"skyfix-part-{p.key}", pure=False, retries=3): p for p in todo}
            frames_done = summary.frames
            for fut in as_completed(futures):
                res = fut.result()  # a partition that failed on every retry raises here
                ms += res.pop("ms")
                rec = manifest["partitions"][res["index"]]
                rec.update(res, status="done")
                _write_json(out / MANIFEST, manifest)
                for k in ("frames", "solved", "no_solution", "errors", "wrong", "checked"):
                    setattr(summary, k, getattr(summary, k) + int(res[k]))
                frames_done += futures[fut].lines
                if progress is not None:
                    progress(frames_done, total, time.perf_counter() - t0)
        finally:
            if own is not None:
                cluster_obj = own.cluster
                own.close()
                if cluster_obj is not None:
                    cluster_obj.close()
    summary.wall_s = time.perf_counter() - t0
    if ms:
        a = np.asarray(ms)
        summary.ms_percentiles = {f"p{q}": float(np.percentile(a, q)) for q in (50, 95, 99)}
    return summary
