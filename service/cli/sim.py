"""``skyfix sim``: write simulated recordings (centroids with truth)."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Annotated

import typer

from ._progress import err_console


def sim(
    out: Annotated[Path, typer.Option("--out", "-o", help="Output .jsonl file, or a directory (frames.jsonl inside).")],
    n: Annotated[int, typer.Option(help="Number of frames.", min=1, max=1_000_000)] = 100,
    width: Annotated[int, typer.Option(help="Image width, px.", min=1)] = 1024,
    height: Annotated[int, typer.Option(help="Image height, px.", min=1)] = 1024,
    fov: Annotated[float | None, typer.Option(help="Horizontal field of view, deg.")] = None,
    focal_mm: Annotated[float | None, typer.Option(help="Focal length, mm (with --pixel-um).")] = 94.9489,
    pixel_um: Annotated[float | None, typer.Option(help="Pixel pitch, micrometres.")] = 14.0,
    mag_limit: Annotated[float, typer.Option(help="Faintest star seen (V).")] = 6.5,
    noise: Annotated[float, typer.Option(help="Centroid noise sigma, px.")] = 0.0,
    mag_noise: Annotated[float, typer.Option(help="Magnitude noise sigma.")] = 0.0,
    false_stars: Annotated[int, typer.Option(help="False stars per frame.", min=0)] = 0,
    missing: Annotated[float, typer.Option(help="Probability a star is missing.", min=0.0, max=1.0)] = 0.0,
    max_stars: Annotated[int | None, typer.Option(help="Keep the brightest N.")] = None,
    seed: Annotated[int, typer.Option(help="Random seed.")] = 0,
) -> None:
    """Simulate frames at attitudes uniform on SO(3); one JSON frame a line with its truth.

    Default camera: seed 000's (1024x1024, f 94.9489 mm, 14 um pixels, about 8.6 deg).
    """
    from ..core.camera import Camera
    from ..core.sim import SimConfig, simulate_frames

    camera = Camera.from_fov(fov, width, height) if fov else Camera.from_focal(focal_mm, pixel_um, width, height)
    spec = {"width": width, "height": height}
    spec.update({"fov_deg": fov} if fov else {"focal_mm": focal_mm, "pixel_um": pixel_um})
    cfg = SimConfig(mag_limit=mag_limit, centroid_noise_px=noise, mag_noise=mag_noise, false_stars=false_stars,
                    missing_prob=missing, max_stars=max_stars)
    path = out / "frames.jsonl" if out.suffix != ".jsonl" else out
    path.parent.mkdir(parents=True, exist_ok=True)
    frames = simulate_frames(camera, n, cfg, rng=seed)
    tmp = path.with_name(path.name + ".tmp")
    with open(tmp, "w") as fh:
        for i, f in enumerate(frames):
            fh.write(json.dumps(f.to_record(i, camera, camera_spec=spec)) + "\n")
    tmp.replace(path)
    err_console.print(f"wrote {n} frames to {path}")
