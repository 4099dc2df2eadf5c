"""What runs on a Dask worker: the database opened once per worker (a worker plugin), and the
solve of one partition into its output file."""

from __future__ import annotations

import hashlib
import json
import os
import tempfile
from pathlib import Path
from typing import Any

import orjson
from distributed import WorkerPlugin, get_worker

from .partition import Partition, read_lines

PLUGIN_NAME = "skyfix-database"


def database_checksum(path: Path) -> str:
    """A checksum of a database (or set) by its arrays' sha256s: equal for databases built
    identically, whatever their build time."""
    h = hashlib.sha256()
    for mpath in sorted(Path(path).resolve().glob("**/manifest.json")):
        manifest = json.loads(mpath.read_text())
        for name, spec in sorted((manifest.get("arrays") or {}).items()):
            h.update(f"{mpath.parent.name}/{name}:{spec.get('sha256')}\n".encode())
    return h.hexdigest()


class DatabasePlugin(WorkerPlugin):
    """Opens the navigation database once per worker process and checks it is the client's.

    ``path`` None means the default database, which each worker builds identically on first
    use (in its own ``SKYFIX_DB_DIR``). A worker that cannot open it, or opens a different one,
    keeps the reason; its tasks fail with it (naming the worker and the path)."""

    name = PLUGIN_NAME

    def __init__(self, path: str | None, checksum: str) -> None:
        self.path, self.checksum = path, checksum

    def setup(self, worker: Any) -> None:
        from service.core.navdb import open_database
        from service.core.warmup import warm_up

        where = self.path or "the default database"
        worker.skyfix_db = None  # a plugin registered again must not leave the previous database
        try:
            path = Path(self.path) if self.path else _default_database_locked()
            where = str(path)
            db = open_database(path)
            got = database_checksum(path)
            if got != self.checksum:
                raise RuntimeError(f"its checksum {got[:12]} differs from the client's {self.checksum[:12]}")
            once_more_on_system_error(lambda: warm_up(db))
        except Exception as exc:  # kept and raised by every task on this worker
            worker.skyfix_db_error = f"worker {worker.address}: cannot use the navigation database at {where}: {exc}"
            return
        worker.skyfix_db = db


def once_more_on_system_error(step: Any) -> Any:
    """``step()``, run a second time if the first raised ``SystemError``. CPython 3.11 can raise
    a spurious "AST constructor recursion depth mismatch" in a threaded program (python/cpython
    gh-106905): once in a CI run (session 23), while a worker thread's warm-up compiled the
    kernels of a fresh install. A second ``SystemError`` is raised."""
    try:
        return step()
    except SystemError:
        return step()


def _default_database_locked() -> Path:
    """The default database, built under an exclusive lock beside it: the workers of one
    machine (or of a shared ``SKYFIX_DB_DIR``) build it once, one after the other, instead of
    at once over each other's staging directories."""
    import fcntl

    from service.core.navdb import default_database_dir, ensure_default_database

    where = default_database_dir()
    where.mkdir(parents=True, exist_ok=True)
    with open(where / ".skyfix-build.lock", "a") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        try:
            return ensure_default_database()
        finally:
            fcntl.flock(lock, fcntl.LOCK_UN)


def _worker_db() -> Any:
    worker = get_worker()
    db = getattr(worker, "skyfix_db", None)
    if db is None:
        raise RuntimeError(getattr(worker, "skyfix_db_error", f"worker {worker.address}: no database plugin"))
    return db


def solve_partition(part: dict[str, Any], out_dir: str, method: str, sigma: float) -> dict[str, Any]:
    """Solve one partition on this worker; write its results (one JSON line per frame, an error
    record for a frame that cannot be parsed or solved) atomically to ``out_dir``; return its
    counts, the output's sha256 and the frames' solve times (ms)."""
    from service.core.batch import FrameError, solve_many
    from service.core.evaluate import correct_against_record
    from service.core.pipeline import SolveOptions

    p = Partition(**part)
    db = _worker_db()
    numbered = [(p.first_line + i, line) for i, line in enumerate(read_lines(p)) if line.strip()]

    def answer(rec: Any, sol: Any) -> tuple[str, bool, bool | None, float, Any]:
        # orjson: ~2 us an answer where json.dumps takes ~29 (the same JSON as skyfix solve's lines)
        return (orjson.dumps(sol.to_dict(rec.get("id"))).decode(), sol.solved, correct_against_record(rec, sol),
                sol.timings_ms.get("total", 0.0), rec.get("id"))

    results = solve_many([line for _, line in numbered], db, method=method,
                         options=SolveOptions(centroid_sigma_px=sigma), workers=1, then=answer, return_errors=True)
    out, ms, ids = [], [], []
    solved = wrong = checked = errors = 0
    for (lineno, _), res in zip(numbered, results, strict=True):
        if isinstance(res, FrameError):
            errors += 1
            out.append(json.dumps({"status": "error", "file": p.path, "line": lineno, "error": res.message,
                                   "field": res.field}))
            continue
        text, ok, correct, t, fid = res
        out.append(text)
        ids.append(fid)
        solved += ok
        ms.append(t)
        if correct is not None:
            checked += 1
            wrong += not correct
    data = ("\n".join(out) + "\n").encode() if out else b""
    target = Path(out_dir) / p.output_name
    fd, tmp = tempfile.mkstemp(dir=out_dir, prefix=f".{p.output_name}.", suffix=".tmp")
    with os.fdopen(fd, "wb") as fh:
        fh.write(data)
        fh.flush()
        os.fsync(fh.fileno())
    os.replace(tmp, target)
    return {"index": p.index, "key": p.key, "output": p.output_name, "sha256": hashlib.sha256(data).hexdigest(),
            "frames": len(numbered), "solved": solved, "no_solution": len(numbered) - solved - errors,
            "errors": errors, "wrong": wrong, "checked": checked, "ms": ms,
            "first_id": ids[0] if ids else None, "last_id": ids[-1] if ids else None, "worker": get_worker().address}
