"""``skyfix calibrate INPUT... --out camera.json``: fit the camera from solved frames."""

from __future__ import annotations

import json
import os
import tempfile
from pathlib import Path
from typing import Annotated, Any

import typer

from ._progress import err_console, resolve_db

IMAGE_SUFFIXES = {".png", ".tif", ".tiff", ".jpg", ".jpeg", ".fits", ".fit", ".fts", ".npy"}


def _write_atomic(path: Path, data: dict[str, Any]) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    with os.fdopen(fd, "w") as fh:
        json.dump(data, fh, indent=2)
        fh.write("\n")
    os.replace(tmp, path)


def _load_frames(inputs: list[Path], nominal_spec: dict[str, Any] | None, threshold: float
                 ) -> tuple[list[Any], dict[str, Any]]:
    """Centroid lists of every frame (recordings' lines, or stars detected in images) and the
    nominal camera spec (``--camera``, else the first recorded frame's)."""
    from ..core.batch import frame_from_record
    from ..core.centroid import extract, load_image
    from ..core.errors import InvalidInputError

    frames, spec = [], nominal_spec
    for path in inputs:
        if path.suffix.lower() in IMAGE_SUFFIXES:
            if spec is None:
                raise InvalidInputError("--camera", f"{path}: images need the nominal camera (--camera or --fov)")
            frames.append(extract(load_image(path), sigma_threshold=threshold).centroids)
            continue
        with open(path) as fh:
            for lineno, line in enumerate(fh, 1):
                if not line.strip():
                    continue
                try:
                    rec = json.loads(line)
                except ValueError as exc:
                    raise InvalidInputError("frame", f"{path} line {lineno}: not JSON ({exc})") from None
                frame = frame_from_record(rec)
                if frame.is_rig:
                    raise InvalidInputError("cameras", f"{path} line {lineno}: calibrate one camera at a time")
                spec = spec or rec["camera"]
                frames.append(frame.views[0][0])
    if spec is None:
        raise InvalidInputError("input", "no frames")
    return frames, spec


def calibrate_camera(
    inputs: Annotated[list[Path], typer.Argument(help="Recordings (JSON Lines of centroid frames) and/or image files.")],
    out: Annotated[Path, typer.Option(help="Where to write the calibrated camera (JSON camera spec).")],
    camera: Annotated[str | None, typer.Option(help="Nominal camera as JSON (default: the recording's).")] = None,
    fov: Annotated[float | None, typer.Option(help="Nominal horizontal field, deg, for images (size from the file).")] = None,
    fit: Annotated[str, typer.Option(help="Parameters to fit, comma-separated, of f_px,cx,cy,k1,k2,p1,p2,k3.")]
        = "f_px,cx,cy,k1,k2,p1,p2",
    iterations: Annotated[int, typer.Option(min=1, max=20, help="Identify-then-fit rounds at most.")] = 4,
    db: Annotated[Path | None, typer.Option(help="Database directory (default: the default one).")] = None,
    method: Annotated[str, typer.Option(help="Method name or 'auto'.")] = "auto",
    sigma: Annotated[float, typer.Option(help="Expected centroid error of the nominal camera, px.")] = 1.0,
    threshold: Annotated[float, typer.Option(help="Detection threshold for images, local noise sigmas.")] = 5.0,
    report: Annotated[Path | None, typer.Option(help="Also write the fit's report (1-sigma, RMS, history).")] = None,
    fov_max_error: Annotated[float | None, typer.Option(
        min=0.0, max=30.0,
        help="How far the nominal horizontal field may be off, deg: frames are identified over the focal lengths "
        "this allows (a lens's nominal focal length is often 1-5% off).")] = None,
) -> None:
    """Fit focal length, principal point and distortion over many frames; write a camera that
    `skyfix solve`, `SKYFIX_CAMERAS` and the SDK accept."""
    from ..core.calibrate import PARAMS, calibrate
    from ..core.camera import Camera
    from ..core.centroid import load_image
    from ..core.errors import SkyfixError
    from ..core.navdb import open_database
    from ..core.pipeline import SolveOptions

    if fov_max_error is not None and not fov_max_error > 0:
        raise typer.BadParameter("must be more than 0 deg", param_hint="--fov-max-error")
    names = tuple(p.strip() for p in fit.split(",") if p.strip())
    if not names or set(names) - set(PARAMS):
        raise typer.BadParameter(f"choose from {','.join(PARAMS)}", param_hint="--fit")
    try:
        spec = json.loads(camera) if camera else None
    except ValueError as exc:
        raise typer.BadParameter(f"not JSON: {exc}", param_hint="--camera") from None
    try:
        if spec is None and fov is not None:
            first = next((p for p in inputs if p.suffix.lower() in IMAGE_SUFFIXES), None)
            if first is not None:
                h, w = load_image(first).shape[:2]
                spec = {"width": w, "height": h, "fov_deg": fov}
        frames, spec = _load_frames(inputs, spec, threshold)
        nominal = Camera.from_spec(spec)
        database = open_database(resolve_db(db))
        result = calibrate(frames, nominal, database, fit=names, iterations=iterations, method=method,
                           options=SolveOptions(centroid_sigma_px=sigma, fov_max_error_deg=fov_max_error),
                           progress=err_console.print)
    except (OSError, SkyfixError, ValueError) as exc:
        err_console.print(f"[red]error:[/red] {exc}")
        raise typer.Exit(2) from None
    _write_atomic(out, result.camera.to_spec())
    if report is not None:
        _write_atomic(report, result.report())
    params = result.report()["parameters"]
    sig = ", ".join(f"{p} {params[p]['value']:.6g} ± {s:.2g}" for p, s in result.sigma.items())
    err_console.print(
        f"{result.frames_solved}/{result.frames_total} frames, {result.stars} stars; RMS "
        f"{result.rms_px_nominal:.3f} px (nominal) -> {result.rms_px:.3f} px; {sig}; wrote {out}"
    )
