"""``skyfix solve FRAMES.jsonl``: identify recorded frames of centroids on all cores."""

from __future__ import annotations

import os
import stat
import sys
from collections import Counter
from collections.abc import Iterator
from dataclasses import dataclass, field
from itertools import islice
from pathlib import Path
from typing import Annotated, Any

import numpy as np
import orjson
import typer

from ._progress import err_console, resolve_db

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
    from ..core.batch import SolvePool
    from ..core.navdb import open_database
    from ..core.pipeline import SolveOptions
    from ..core.warmup import warm_up

    database = open_database(resolve_db(db))
    warm_up(database)  # before the clock: frames/s below is of solving, not of starting
    options = SolveOptions(centroid_sigma_px=sigma, fov_max_error_deg=fov_max_error)
    # bytes, not text: orjson parses a line's bytes as they are (a str costs it a UTF-8 encoding,
    # and the pool pickles bytes as one copy) and the answers go out as orjson makes them
    stream = sys.stdin.buffer if str(frames) == "-" else open(frames, "rb")
    stdout = sys.stdout.buffer
    pool = SolvePool(database, method=method, options=options, workers=workers, then=_answer, return_errors=True)
    n_workers = pool.workers  # default: the cores this process may use
    t0 = time.perf_counter()
    with stream, pool:
        if stream is sys.stdin.buffer or not stat.S_ISREG(os.fstat(stream.fileno()).st_mode):
            tally = _solve_stream(stream, pool, stdout, 1 if n_workers == 1 else PIPE_BLOCK * n_workers)
        else:  # a recording file: the workers read it in byte ranges themselves (SolvePool.map_file)
            tally = _Tally()
            for part in pool.map_file(frames, _fold_answers):
                stdout.write(part.text)
                tally.add(part)
                if part.error is not None:
                    offset, message = part.error
                    stdout.flush()
                    err_console.print(f"[red]line {_line_number(frames, offset)}:[/red] {message}")
                    raise typer.Exit(2)
            stdout.flush()
    wall = time.perf_counter() - t0
    n, solved = tally.n, tally.solved
    t = np.array(tally.times) if tally.times else np.zeros(1)
    why = ", ".join(f"{k} {v}" for k, v in tally.reasons.most_common())
    err_console.print(
        f"{solved}/{n} identified ({100 * solved / max(n, 1):.1f}%), "
        f"{tally.wrong} wrong of {tally.checked} with truth; "
        f"solve ms p50 {np.percentile(t, 50):.2f} p95 {np.percentile(t, 95):.2f} "
        f"p99 {np.percentile(t, 99):.2f}; "
        f"{n / max(wall, 1e-9):.0f} frames/s on {n_workers} worker(s)"
        + (f"; no_solution by reason: {why}" if why else "")
    )


@dataclass
class _Tally:
    """What the summary line counts: answers, identified, wrong and checked against a truth, the
    solve times (ms) and the no-solutions by reason; ``text`` and ``error`` are a range's own
    (:func:`_fold_answers`: its answers as JSON Lines, and the byte offset and message of the line
    it stopped at)."""

    n: int = 0
    solved: int = 0
    wrong: int = 0
    checked: int = 0
    times: list[float] = field(default_factory=list)
    reasons: Counter[str] = field(default_factory=Counter)
    text: bytes = b""
    error: tuple[int, str] | None = None

    def count(self, answer: tuple[bytes, bool, str | None, bool | None, float]) -> None:
        """One frame's :func:`_answer`."""
        _, ok, reason, correct, ms = answer
        self.n += 1
        self.solved += ok
        self.times.append(ms)
        if reason:
            self.reasons[reason] += 1
        if correct is not None:
            self.checked += 1
            self.wrong += not correct

    def add(self, other: _Tally) -> None:
        """Another tally's counts (a range's)."""
        self.n += other.n
        self.solved += other.solved
        self.wrong += other.wrong
        self.checked += other.checked
        self.times += other.times
        self.reasons.update(other.reasons)


def _fold_answers(pairs: Iterator[tuple[int, Any]]) -> _Tally:
    """In the worker: one byte range's answers as one tally, its JSON Lines joined, up to the
    first line it could not parse or solve (its offset and message kept; the rest not solved)."""
    from ..core.batch import FrameError

    tally, texts = _Tally(), []
    for offset, answer in pairs:
        if isinstance(answer, FrameError):
            tally.error = (offset, answer.message)
            break
        texts.append(answer[0])
        tally.count(answer)
    tally.text = b"".join(texts)
    return tally


def _line_number(path: Path, offset: int, block: int = 1 << 20) -> int:
    """The line (from 1) of ``path`` that starts at byte ``offset`` (read ``block`` bytes at a time:
    a bad line deep in a large recording costs no memory)."""
    newlines = 0
    with open(path, "rb") as f:
        while offset > 0:
            data = f.read(min(block, offset))
            if not data:
                break
            newlines += data.count(b"\n")
            offset -= len(data)
    return newlines + 1


def _solve_stream(stream: Any, pool: Any, stdout: Any, size: int) -> _Tally:
    """Standard input (or a pipe) block after block of ``size`` lines: a live feed's answers come
    out as each block is solved."""
    from ..core.batch import FrameError

    tally, lineno = _Tally(), 0
    while True:
        block = list(islice(stream, size))
        if not block:
            return tally
        numbered = [(lineno + i + 1, line) for i, line in enumerate(block) if line.strip()]
        lineno += len(block)
        results = pool.imap([line for _, line in numbered])
        out: list[bytes] = []
        for (num, _), res in zip(numbered, results, strict=True):
            if isinstance(res, FrameError):
                stdout.write(b"".join(out))
                results.close()  # cancels the frames not yet started
                err_console.print(f"[red]line {num}:[/red] {res.message}")
                raise typer.Exit(2)
            out.append(res[0])
            tally.count(res)
            if len(out) >= WRITE_EVERY:  # while the workers go on solving
                stdout.write(b"".join(out))
                out.clear()
        stdout.write(b"".join(out))
        stdout.flush()


def _answer(rec: dict[str, Any], sol: Any) -> tuple[bytes, bool, str | None, bool | None, float]:
    """In the worker: the frame's JSON answer (UTF-8, one line), whether it solved, why not, whether it matches
    the recording's truth (None without truth) and its solve time, ms."""
    from ..core.evaluate import correct_against_record

    correct = correct_against_record(rec, sol)
    reason = None if sol.reason is None else sol.reason.value
    text = orjson.dumps(sol.to_dict(rec.get("id")), option=orjson.OPT_APPEND_NEWLINE)
    return text, sol.solved, reason, correct, sol.timings_ms.get("total", 0.0)
