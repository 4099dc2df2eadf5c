"""``skyfix db build | info | verify``: the navigation database."""

from __future__ import annotations

import json
import time
from pathlib import Path
from typing import Annotated, Any

import typer

from ._progress import build_progress, err_console, peak_memory, resolve_db

app = typer.Typer(help="Build, inspect and verify navigation databases.", no_args_is_help=True)


@app.command()
def build(
    out: Annotated[Path, typer.Option("--out", "-o", help="Database directory to (re)build atomically.")],
    fov_max: Annotated[float, typer.Option(help="Largest field served: the widest camera's diagonal, deg.")] = 12.0,
    fov_min: Annotated[float, typer.Option(help="Smallest field served: the narrowest camera's side, deg.")] = 6.0,
    mag_limit: Annotated[float, typer.Option(help="Faintest star kept (approximate V).")] = 6.5,
    epoch: Annotated[float | None, typer.Option(help="Decimal year of the positions (default: now).")] = None,
    methods: Annotated[str, typer.Option(help="Comma-separated methods, or 'all'.")] = "pyramid,maxangle",
    double_star_sep: Annotated[float, typer.Option(help="Merge stars closer than this, deg.")] = 0.02,
    density_cap: Annotated[int | None, typer.Option(help="Max brighter stars within --density-radius.")] = None,
    density_radius: Annotated[float, typer.Option(help="Radius of the density cap, deg.")] = 5.0,
) -> None:
    """Build a database from the bundled Hipparcos catalogue."""
    from ..core.errors import SkyfixError
    from ..core.methods import AUTO_ORDER, get_method
    from ..core.methods.capability import build_warnings
    from ..core.navdb import BuildConfig, build_database, current_epoch, open_database

    names = tuple(m.strip() for m in methods.split(",") if m.strip())
    try:
        for m in names:
            if m != "all":
                get_method(m)
    except SkyfixError as exc:
        raise typer.BadParameter(str(exc), param_hint="--methods") from None
    if not (0 < fov_min <= fov_max < 90):
        raise typer.BadParameter("need 0 < --fov-min <= --fov-max < 90", param_hint="--fov-max")
    cfg = BuildConfig(
        fov_max_deg=fov_max, fov_min_deg=fov_min, mag_limit=mag_limit,
        epoch=round(current_epoch(), 2) if epoch is None else epoch,
        double_star_sep_deg=double_star_sep, density_cap=density_cap, density_radius_deg=density_radius,
        methods=names,
    )
    t0 = time.perf_counter()
    with build_progress(str(out)) as cb:
        build_database(out, cfg, progress=cb)
    err_console.print(f"built {out} in {time.perf_counter() - t0:.1f} s, peak memory {peak_memory()}")
    for line in build_warnings(open_database(out), AUTO_ORDER):  # methods that cannot serve its fields
        err_console.print(f"[yellow]warning:[/yellow] {line}", highlight=False)


@app.command()
def info(db: Annotated[Path | None, typer.Argument(help="Database directory (default: the default one).")] = None) -> None:
    """Print a database's manifest summary as JSON (a set: each member's)."""
    from ..core.navdb import open_database
    from ..core.navdb.reader import NavDatabaseSet

    t0 = time.perf_counter()
    d = open_database(resolve_db(db))
    ms = (time.perf_counter() - t0) * 1e3
    if isinstance(d, NavDatabaseSet):  # the default database is a set of members
        members = {name: _summary(m) for name, m in d.members.items()}
        summary: dict[str, Any] = {"format": "set", "schema_version": d.manifest.get("schema_version"),
                                   "methods": d.methods, "members": members}
        summary.update(path=str(d.path.resolve()), size_bytes=sum(m["size_bytes"] for m in members.values()))
    else:
        summary = _summary(d)
    summary["open_ms"] = round(ms, 2)
    typer.echo(json.dumps(summary, indent=1))


def _summary(d: Any) -> dict[str, Any]:
    """A single database's manifest summary, its path and its size on disk, bytes."""
    m = d.manifest
    size = sum((d.path / a["file"]).stat().st_size for a in m["arrays"].values())
    summary = {k: m.get(k) for k in ("schema_version", "catalogue", "epoch", "mag_limit", "fov_min_deg",
                                      "fov_max_deg", "n_stars", "built_utc", "build_seconds", "methods", "shared")}
    summary.update(path=str(d.path.resolve()), size_bytes=size)
    return summary


@app.command()
def verify(db: Annotated[Path | None, typer.Argument(help="Database directory (default: the default one).")] = None) -> None:
    """Check every array's header, shape, size and sha256 against the manifest."""
    from ..core.errors import DatabaseError
    from ..core.navdb import open_database

    path = resolve_db(db)
    try:
        open_database(path, verify_hashes=True)
    except DatabaseError as exc:
        err_console.print(f"[red]FAILED[/red] {exc}")
        raise typer.Exit(1) from None
    err_console.print(f"[green]OK[/green] {path}")
