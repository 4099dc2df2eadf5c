"""``skyfix solve-image IMAGE...``: detect and identify the stars of image files."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Annotated

import typer

from ._progress import err_console, resolve_db


def solve_image_files(
    images: Annotated[list[Path], typer.Argument(help="PNG, TIFF (8/16 bit), JPEG, FITS or .npy files.")],
    fov: Annotated[float | None, typer.Option(help="Horizontal field of view, deg (image size from the file).")] = None,
    camera: Annotated[str | None, typer.Option(help='Camera as JSON, e.g. \'{"width":1024,"height":768,"fov_deg":11.4}\'.')] = None,
    db: Annotated[Path | None, typer.Option(help="Database directory (default: the default one).")] = None,
    method: Annotated[str, typer.Option(help="Method name or 'auto'.")] = "auto",
    sigma: Annotated[float, typer.Option(help="Expected centroid error, px.")] = 1.0,
    threshold: Annotated[float, typer.Option(help="Detection threshold, local noise sigmas.")] = 5.0,
    fov_max_error: Annotated[float | None, typer.Option(
        min=0.0, max=30.0,
        help="How far the camera's horizontal field may be off, deg: a frame not identified with it is searched "
        "over the focal lengths this allows, and `fov_deg` reports the one fitted.")] = None,
) -> None:
    """Print one JSON result per image (the `skyfix solve` schema plus `wcs`)."""
    if fov_max_error is not None and not fov_max_error > 0:
        raise typer.BadParameter("must be more than 0 deg", param_hint="--fov-max-error")
    from ..core.camera import Camera
    from ..core.centroid import load_image
    from ..core.errors import SkyfixError
    from ..core.navdb import open_database
    from ..core.pipeline import SolveOptions, solve_image

    if (fov is None) == (camera is None):
        raise typer.BadParameter("give exactly one of --fov or --camera", param_hint="--fov")
    try:
        spec = json.loads(camera) if camera else None
    except ValueError as exc:
        raise typer.BadParameter(f"not JSON: {exc}", param_hint="--camera") from None
    database = open_database(resolve_db(db))
    failures = 0
    for path in images:
        try:
            img = load_image(path)
            cam = Camera.from_spec(spec) if spec else Camera.from_fov(fov, img.shape[1], img.shape[0])  # type: ignore[arg-type]
            sol = solve_image(img, cam, database, method=method, options=SolveOptions(centroid_sigma_px=sigma, fov_max_error_deg=fov_max_error),
                              detect={"sigma_threshold": threshold})
        except (OSError, SkyfixError) as exc:
            err_console.print(f"[red]{path}:[/red] {exc}")
            failures += 1
            continue
        typer.echo(json.dumps(sol.to_dict(str(path))))
    if failures:
        raise typer.Exit(2)
