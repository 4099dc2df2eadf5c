"""The cameras of the source papers, as used by the acceptance tests and the benchmarks.

Where a paper's numbers disagree with each other the docstring of the preset says which we
kept. Each preset names the magnitude limit its paper used and the database configuration
that serves it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from .camera import Camera
from .navdb.builder import BuildConfig
from .sim import BLEND_DEG


@dataclass(frozen=True)
class Preset:
    """A paper's camera, its star magnitude limit and a database configuration for it."""

    name: str
    camera: Camera
    mag_limit: float
    paper: str

    def build_config(self, methods: tuple[str, ...], *, epoch: float = 2026.0) -> BuildConfig:
        """A database for this camera: pairs up to the image diagonal, triangles up to the side."""
        return BuildConfig(
            fov_max_deg=self.camera.diagonal_fov_deg + 0.2,
            fov_min_deg=min(self.camera.fov_deg, self.camera.fov_y_deg),
            mag_limit=self.mag_limit,
            epoch=epoch,
            methods=methods,
            # merge doubles as the simulator blends them (service.core.sim.BLEND_DEG), or a
            # fine-pixel camera sees one centroid where the database keeps two stars
            double_star_sep_deg=BLEND_DEG,
        )


def _focal_for(fov_deg: float, width: int, pixel_um: float) -> float:
    return width * pixel_um / 1000 / 2 / math.tan(math.radians(fov_deg) / 2)


PRESETS: dict[str, Preset] = {
    "seed000": Preset(
        "seed000", Camera.from_focal(94.9489, 14.0, 1024, 1024), 6.5,
        "000 maxangle: 8x8 deg nominal (8.6 deg from f 94.9489 mm and 14 um), 1024x1024, 6.5 Mv",
    ),
    "seed001": Preset(
        "seed001", Camera.from_fov(8.9, 2048, 2048), 6.5,
        "001 multifov: each camera 8.9x8.9 deg, 2048x2048, 6.5 Mv (two cameras; rig in the tests)",
    ),
    "seed002": Preset(
        "seed002", Camera.from_focal(_focal_for(4.0, 4096, 9.0), 9.0, 4096, 4096), 7.0,
        "002 radial: 4x4 deg, 4096x4096, 9 um; deeper limit (7.0 Mv: the median frame holds ~5 stars)",
    ),
    "seed003": Preset(
        "seed003", Camera.from_focal(50.0, 13.0, 1024, 1024), 6.0,
        "003 dmv: f 50 mm, 13 um, 1024x1024 (15.2 deg from those, the paper says 12x12), 6.0 Mv",
    ),
    "seed004": Preset(
        "seed004", Camera.from_focal(_focal_for(20.0, 1024, 15.0), 15.0, 1024, 1024), 6.5,
        "004 pso: 20x20 deg, 1024x1024, 15 um, 6.5 Mv",
    ),
}
