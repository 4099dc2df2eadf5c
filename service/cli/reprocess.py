"""``skyfix reprocess RECORDING... --out DIR``: re-solve recordings on a Dask cluster."""

from __future__ import annotations

import glob
from pathlib import Path
from typing import Annotated

import typer

from ._progress import err_console


def reprocess_recordings(
    recordings: Annotated[list[str], typer.Argument(help="JSON Lines recordings (paths or globs).")],
    out: Annotated[Path, typer.Option(help="Output directory: one file per partition + manifest.json.")],
    cluster: Annotated[str | None, typer.Option(help="Dask scheduler address, e.g. tcp://host:8786.")] = None,
    local: Annotated[int | None, typer.Option(min=1, help="Start a LocalCluster of N worker processes here.")] = None,
    db: Annotated[Path | None, typer.Option(help="Database every worker can read (default: the default one).")] = None,
    method: Annotated[str, typer.Option(help="Method name or 'auto'.")] = "auto",
    sigma: Annotated[float, typer.Option(help="Expected centroid error, px.")] = 1.0,
    partition_frames: Annotated[int, typer.Option(min=1, help="Frames (lines) per partition at most.")] = 5000,
) -> None:
    """Solve every frame on the workers; a re-run skips the partitions already done and verified."""
    try:
        from service.cluster import reprocess
    except ImportError as exc:
        err_console.print(f"[red]error:[/red] skyfix reprocess needs the cluster extra: pip install 'skyfix[cluster]' ({exc})")
        raise typer.Exit(2) from None
    from rich.progress import BarColumn, Progress, TextColumn, TimeRemainingColumn

    if cluster and local:
        raise typer.BadParameter("give --cluster or --local, not both", param_hint="--cluster")
    paths: list[Path] = []
    for pattern in recordings:
        found = sorted(glob.glob(pattern)) if any(c in pattern for c in "*?[") else [pattern]
        if not found:
            raise typer.BadParameter(f"{pattern}: no file matches", param_hint="RECORDINGS")
        paths += [Path(p) for p in found]
    missing = [str(p) for p in paths if not p.is_file()]
    if missing:
        raise typer.BadParameter(f"no such file: {', '.join(missing)}", param_hint="RECORDINGS")
    if db is not None and not db.exists():
        raise typer.BadParameter(f"no database at {db}", param_hint="--db")
    with Progress(TextColumn("reprocess"), BarColumn(), TextColumn("{task.completed:.0f}/{task.total} frames"),
                  TextColumn("{task.fields[rate]:,.0f} frames/s"), TimeRemainingColumn(),
                  console=err_console, transient=False) as bar:
        task = None

        def tick(done: int, total: int, run_frames: int, elapsed: float) -> None:
            nonlocal task
            if task is None:  # partitions already done count from the start, not in the rate
                task = bar.add_task("reprocess", total=total, completed=done, rate=0.0)
            bar.update(task, completed=done, rate=run_frames / max(elapsed, 1e-9))

        try:
            summary = reprocess(paths, out, cluster=cluster, local=local, db=db, method=method, sigma=sigma,
                                partition_frames=partition_frames, progress=tick)
        except (OSError, ValueError, RuntimeError) as exc:
            err_console.print(f"[red]error:[/red] {exc}")
            raise typer.Exit(2) from None
    err_console.print(summary.line())
