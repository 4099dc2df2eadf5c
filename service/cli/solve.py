"""``skyfix solve FRAMES.jsonl``: identify recorded frames of centroids."""

from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import Annotated, Any

import numpy as np
import typer

from ._progress import err_console, resolve_db


def solve_frames(
    frames: Annotated[Path, typer.Argument(help="Recording: JSON Lines, one frame a line ('-' = stdin).")],
    db: Annotated[Path | None, typer.Option(help="Database directory (default: the default one).")] = None,
    method: Annotated[str, typer.Option(help="Method name or 'auto'.")] = "auto",
    sigma: Annotated[float, typer.Option(help="Expected centroid error, px.")] = 1.0,
) -> None:
    """Print one JSON result per frame on stdout, then a summary on stderr."""
    from ..core.batch import frame_from_record, solve_frame
    from ..core.errors import SkyfixError
    from ..core.evaluate import score
    from ..core.navdb import open_database
    from ..core.pipeline import SolveOptions

    database = open_database(resolve_db(db))
    options = SolveOptions(centroid_sigma_px=sigma)
    stream = sys.stdin if str(frames) == "-" else open(frames)
    times, n, solved, wrong, checked = [], 0, 0, 0, 0
    with stream:
        for lineno, line in enumerate(stream, 1):
            if not line.strip():
                continue
            n += 1
            try:
                rec: dict[str, Any] = json.loads(line)
                sol = solve_frame(frame_from_record(rec), database, method=method, options=options)
            except (SkyfixError, ValueError, KeyError, TypeError) as exc:
                err_console.print(f"[red]line {lineno}:[/red] {exc}")
                raise typer.Exit(2) from None
            out = sol.to_dict(rec.get("id"))
            typer.echo(json.dumps(out))
            times.append(sol.timings_ms.get("total", 0.0))
            solved += sol.solved
            truth = rec.get("truth") or {}
            if sol.solved and truth:
                blends = {int(k): v for k, v in (truth.get("blends") or {}).items()}
                # a rig's truth lists every camera's HIPs one camera after the other
                sizes = [len(c.get("centroids", [])) for c in rec["cameras"]] if rec.get("cameras") else [0]
                hips = truth.get("hip")
                correct = all(score(sol, truth.get("quaternion"), None if hips is None else hips[o:],
                                    camera=c, blends={k - o: v for k, v in blends.items() if k >= o}).correct
                              for c, o in enumerate(np.cumsum([0, *sizes[:-1]]).tolist()))
                checked += 1
                wrong += not correct
    t = np.array(times) if times else np.zeros(1)
    err_console.print(
        f"{solved}/{n} identified ({100 * solved / max(n, 1):.1f}%), {wrong} wrong of {checked} with truth; "
        f"solve ms p50 {np.percentile(t, 50):.2f} p95 {np.percentile(t, 95):.2f} p99 {np.percentile(t, 99):.2f}"
    )
