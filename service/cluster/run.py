"""The client side of a reprocessing campaign: plan, skip what is done, submit, record.

The campaign's record in ``out``:

- ``manifest.json``: the settings (inputs, database checksum, method, sigma, partition size)
  and every partition (file, byte range, lines; once done: output file, sha256, counts, frame
  ids). Written atomically at the start, at most every ``MANIFEST_EVERY_S`` during the run, and
  at the end.
- ``journal.jsonl``: one line a finished partition, appended and fsynced as it finishes (a
  constant cost a partition, where rewriting the manifest each time would grow with the
  campaign). Folded into the manifest at the end and removed.
"""

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
JOURNAL = "journal.jsonl"
MANIFEST_EVERY_S = 30.0
COUNTS = ("frames", "solved", "no_solution", "errors", "wrong", "checked")


@dataclass
class ReprocessSummary:
    """What a campaign did: partitions run and skipped, frame counts (the whole campaign's,
    skipped partitions included), solve-time percentiles (ms, the frames solved in this run),
    ``run_s`` from the plugin's registration (the workers open the database) to the last result
    (cluster start excluded), ``wall_s`` the whole call."""

    partitions: int = 0
    skipped: int = 0
    frames: int = 0
    solved: int = 0
    no_solution: int = 0
    errors: int = 0
    wrong: int = 0
    checked: int = 0
    wall_s: float = 0.0
    run_s: float = 0.0
    run_frames: int = 0
    ms_percentiles: dict[str, float] = field(default_factory=dict)

    def line(self) -> str:
        pct = self.ms_percentiles
        times = (f"solve ms p50 {pct['p50']:.2f} p95 {pct['p95']:.2f} p99 {pct['p99']:.2f}" if pct
                 else "no frame solved in this run")
        rate = (f"{self.run_frames / self.run_s:,.0f} frames/s on the workers, " if self.run_s > 0 else "")
        return (f"{self.solved}/{self.frames} identified ({100 * self.solved / max(self.frames, 1):.1f}%), "
                f"{self.no_solution} no_solution, {self.errors} error records, {self.wrong} wrong of {self.checked} "
                f"with truth; {times}; {self.partitions} partitions run, {self.skipped} already done; "
                f"{rate}{self.wall_s:.1f} s in all")


def _write_json(path: Path, data: Any) -> None:
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    with os.fdopen(fd, "w") as fh:
        json.dump(data, fh, indent=1)
        fh.flush()
        os.fsync(fh.fileno())
    os.replace(tmp, path)


def _sha256(path: Path) -> str | None:
    h = hashlib.sha256()
    try:
        with open(path, "rb") as fh:
            for block in iter(lambda: fh.read(1 << 20), b""):
                h.update(block)
    except OSError:
        return None
    return h.hexdigest()


def _recorded(out: Path) -> tuple[dict[str, Any] | None, dict[str, dict[str, Any]]]:
    """The manifest in ``out`` (None if none) and its finished partitions by key, the
    journal's included (a torn last line, from a client killed mid-write, is ignored)."""
    try:
        manifest = json.loads((out / MANIFEST).read_text())
    except (OSError, ValueError):
        return None, {}
    recs = {p["key"]: p for p in manifest.get("partitions", []) if isinstance(p, dict)
            and p.get("status") == "done" and "key" in p}
    try:
        with open(out / JOURNAL, "rb") as fh:
            for line in fh:
                try:
                    rec = json.loads(line)
                except ValueError:
                    continue
                if isinstance(rec, dict) and "key" in rec:
                    recs[rec["key"]] = {**rec, "status": "done"}
    except OSError:
        pass
    return manifest, recs


SETTINGS = ("method", "sigma_px", "partition_frames")


def check_same_campaign(manifest: dict[str, Any] | None, settings: dict[str, Any], out: Path) -> None:
    """Refuse to resume in ``out`` a campaign of other settings or another database (its
    finished partitions would be mixed with this run's)."""
    if manifest is None:
        return
    theirs = {k: manifest.get(k) for k in SETTINGS}
    theirs["database checksum"] = (manifest.get("database") or {}).get("checksum")
    ours = {k: settings[k] for k in SETTINGS}
    ours["database checksum"] = settings["database"]["checksum"]
    diff = [f"{k} {theirs[k]!r} there, {ours[k]!r} now" for k in ours if theirs[k] != ours[k]]
    if diff:
        raise ValueError(f"{out} holds a campaign of other settings ({'; '.join(diff)}): "
                         "give a new --out, or remove that directory to start again")


def done_partitions(out: Path, parts: Sequence[Partition]) -> dict[int, dict[str, Any]]:
    """Partitions of ``parts`` recorded as done whose output exists and matches its sha256."""
    _, recorded = _recorded(out)
    done = {}
    for part in parts:
        rec = recorded.get(part.key)
        if rec and rec.get("output") == part.output_name and _sha256(out / part.output_name) == rec.get("sha256"):
            done[part.index] = rec
    return done


def _check_method(db_path: Path, method: str) -> None:
    """Refuse on the client a method the database lacks (UnknownMethodError, naming those it
    has), before a campaign of error records is written."""
    from service.core.errors import UnknownMethodError
    from service.core.methods import get_method
    from service.core.navdb import open_database

    if method == "auto":
        return
    get_method(method)
    has = open_database(db_path).methods
    if method not in has:
        raise UnknownMethodError(method, ["auto", *has])


def _task_key(part: Partition, out: Path, settings: dict[str, Any]) -> str:
    """A Dask key unique to this partition of this campaign (two campaigns on one client,
    e.g. in a notebook, never share a task)."""
    ident = json.dumps([part.key, str(out), settings["method"], settings["sigma_px"],
                        settings["database"]["checksum"]])
    return f"skyfix-part-{part.index:05d}-{hashlib.sha256(ident.encode()).hexdigest()[:16]}"


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
    progress: Callable[[int, int, int, float], None] | None = None,
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
    progress : ``progress(frames_done, frames_total, frames_this_run, elapsed_s)`` at the start
        and after each partition (frames of skipped partitions count as done, not as this run's)
    client : an existing ``distributed.Client`` (tests, notebooks), instead of cluster/local

    Raises
    ------
    ValueError
        ``out`` holds a campaign of other settings or another database.
    UnknownMethodError
        ``method`` is not one the database has.
    RuntimeError
        A partition failed on every try (e.g. a worker cannot open the database: the message
        names the worker and the path).
    """
    from distributed import Client, LocalCluster, as_completed

    from .work import DatabasePlugin, _default_database_locked, database_checksum, solve_partition

    t0 = time.perf_counter()
    out = Path(out).resolve()
    out.mkdir(parents=True, exist_ok=True)
    for stale in out.glob(".part-*.tmp"):  # left by a worker killed mid-write
        stale.unlink(missing_ok=True)
    parts = plan_partitions(inputs, partition_frames)
    db_path = Path(db).resolve() if db is not None else _default_database_locked()
    checksum = database_checksum(db_path)
    _check_method(db_path, method)
    settings: dict[str, Any] = {
        "format": "skyfix-reprocess", "inputs": [str(Path(p).resolve()) for p in inputs],
        "database": {"path": str(db_path) if db is not None else "default", "checksum": checksum},
        "method": method, "sigma_px": sigma, "partition_frames": partition_frames,
    }
    old, _ = _recorded(out)
    check_same_campaign(old, settings, out)
    done = done_partitions(out, parts)
    records = [{**p.to_dict(), "key": p.key, **done[p.index], "status": "done"} if p.index in done else
               {**p.to_dict(), "key": p.key, "status": "pending"} for p in parts]
    for rec in records:
        rec.pop("ms", None)
    manifest = {**settings, "partitions": records}
    _write_json(out / MANIFEST, manifest)
    (out / JOURNAL).unlink(missing_ok=True)  # its records are in the manifest now
    todo = [p for p in parts if p.index not in done]
    summary = ReprocessSummary(partitions=len(todo), skipped=len(done))
    for rec in done.values():
        for k in COUNTS:
            setattr(summary, k, getattr(summary, k) + int(rec.get(k, 0)))
    total = sum(p.lines for p in parts)
    frames_done = sum(p.lines for p in parts if p.index in done)
    if progress is not None:
        progress(frames_done, total, 0, 0.0)
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
        t_run = time.perf_counter()
        try:
            client.register_plugin(DatabasePlugin(None if db is None else str(db_path), checksum))
            futures = {client.submit(solve_partition, p.to_dict(), str(out), method, sigma,
                                     key=_task_key(p, out, settings), pure=False, retries=2): p for p in todo}
            last_manifest = time.monotonic()
            with open(out / JOURNAL, "a") as journal:
                for fut in as_completed(futures):
                    res = fut.result()  # a partition that failed on every try raises here
                    ms += res.pop("ms")
                    rec = manifest["partitions"][res["index"]]
                    rec.update(res, status="done")
                    journal.write(json.dumps(rec) + "\n")
                    journal.flush()
                    os.fsync(journal.fileno())
                    for k in COUNTS:
                        setattr(summary, k, getattr(summary, k) + int(res[k]))
                    summary.run_frames += int(res["frames"])
                    frames_done += futures[fut].lines
                    if time.monotonic() - last_manifest > MANIFEST_EVERY_S:
                        _write_json(out / MANIFEST, manifest)
                        last_manifest = time.monotonic()
                    if progress is not None:
                        progress(frames_done, total, summary.run_frames, time.perf_counter() - t_run)
            summary.run_s = time.perf_counter() - t_run
            _write_json(out / MANIFEST, manifest)
            (out / JOURNAL).unlink(missing_ok=True)
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
