"""``skyfix solve FRAMES.jsonl``: identify recorded frames of centroids on all cores."""

from __future__ import annotations

import sys
from collections import Counter
from itertools import islice
from pathlib import Path
from typing import Annotated, Any

import numpy as np
import orjson
import typer

from ._progress import err_console, resolve_db

BLOCK = 20_000
"""Lines of a recording file read, solved and written per block (bounds memory: ~70 MB)."""
PIPE_BLOCK = 64
"""Lines per block and worker from standard input, so that a live feed's answers come out
after at most this many frames (one at a time with one worker)."""
WRITE_EVERY = 256
"""Answers gathered before a write to stdout (one write per answer costs more than a frame's
formatting)."""


def solve_frames(
    frames: Annotated[Path, typer.Argument(help="Recording: JSON Lines, one frame a line ('-' = stdin).")],
    db: Annotated[Path | None, typer.Option(help="Database directory (default: the default one).")] = None,
    method: Annotated[str, typer.Option(help="Method name or 'auto'.")] = "auto",
    sigma: Annotated[float, typer.Option(help="Expected centroid error, px.")] = 1.0,
    workers: Annotated[int | None, typer.Option(min=1, help="Worker processes (default: all cores).")] = None,
    fov_max_error: Annotated[float | None, typer.Option(
        min=0.0, max=30.0,
        help="How far the camera's horizontal field may be off, deg: a frame not identified with it is searched "
        "over the focal lengths this allows, and `fov_deg` reports the one fitted.")] = None,
) -> None:
    """Print one JSON result per frame on stdout (in order), then a summary on stderr: the
    share identified, wrong answers against any truth, frames/s (reading, solving and writing,
    after the database is opened and warmed up), and no-solutions by reason."""
    import time

    if fov_max_error is not None and not fov_max_error > 0:
        raise typer.BadParameter("must be more than 0 deg", param_hint="--fov-max-error")
    from ..core.batch import FrameError, SolvePool
    from ..core.navdb import open_database
    from ..core.pipeline import SolveOptions
    from ..core.warmup import warm_up

    database = open_database(resolve_db(db))
    warm_up(database)  # before the clock: frames/s below is of solving, not of starting
    options = SolveOptions(centroid_sigma_px=sigma, fov_max_error_deg=fov_max_error)
    stream = sys.stdin if str(frames) == "-" else open(frames)
    pool = SolvePool(database, method=method, options=options, workers=workers, then=_answer, return_errors=True)
    n_workers = pool.workers  # default: the cores this process may use
    times: list[float] = []
    n = solved = wrong = checked = 0
    reasons: Counter[str] = Counter()
    size = BLOCK if stream is not sys.stdin else (1 if n_workers == 1 else PIPE_BLOCK * n_workers)
    t0 = time.perf_counter()
    with stream, pool:
        lineno = 0
        while True:
            block = list(islice(stream, size))
            if not block:
                break
            numbered = [(lineno + i + 1, line) for i, line in enumerate(block) if line.strip()]
            lineno += len(block)
            results = pool.imap([line for _, line in numbered])
            out: list[str] = []
            for (num, _), res in zip(numbered, results, strict=True):
                if isinstance(res, FrameError):
                    sys.stdout.write("".join(out))
                    results.close()  # cancels the frames not yet started
                    err_console.print(f"[red]line {num}:[/red] {res.message}")
                    raise typer.Exit(2)
                text, ok, reason, correct, ms = res
                out.append(text)
                n += 1
                solved += ok
                times.append(ms)
                if reason:
                    reasons[reason] += 1
                if correct is not None:
                    checked += 1
                    wrong += not correct
                if len(out) >= WRITE_EVERY:  # while the workers go on solving
                    sys.stdout.write("".join(out))
                    out.clear()
            sys.stdout.write("".join(out))
            sys.stdout.flush()
    wall = time.perf_counter() - t0
    t = np.array(times) if times else np.zeros(1)
    why = ", ".join(f"{k} {v}" for k, v in reasons.most_common())
    err_console.print(
        f"{solved}/{n} identified ({100 * solved / max(n, 1):.1f}%), {wrong} wrong of {checked} with truth; "
        f"solve ms p50 {np.percentile(t, 50):.2f} p95 {np.percentile(t, 95):.2f} "
        f"p99 {np.percentile(t, 99):.2f}; "
        f"{n / max(wall, 1e-9):.0f} frames/s on {n_workers} worker(s)"
        + (f"; no_solution by reason: {why}" if why else "")
    )


def _answer(rec: dict[str, Any], sol: Any) -> tuple[str, bool, str | None, bool | None, float]:
    """In the worker: the frame's JSON answer, whether it solved, why not, whether it matches
    the recording's truth (None without truth) and its solve time, ms."""
    from ..core.evaluate import correct_against_record

    correct = correct_against_record(rec, sol)
    reason = None if sol.reason is None else sol.reason.value
    text = orjson.dumps(sol.to_dict(rec.get("id")), option=orjson.OPT_APPEND_NEWLINE).decode()
    return text, sol.solved, reason, correct, sol.timings_ms.get("total", 0.0)
