"""The cameras of the source papers, as used by the acceptance tests and the benchmarks.

Where a paper's numbers disagree with each other the docstring of the preset says which we
kept. Each preset names the magnitude limit its paper used and the database configuration
that serves it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

from .camera import Camera
from .navdb.builder import BuildConfig
from .sim import BLEND_DEG


@dataclass(frozen=True)
class Preset:
    """A paper's camera, its star magnitude limit and a database configuration for it.

    Attributes
    ----------
    name : str
        Key in ``PRESETS`` (``<key>deep`` for an acceptance camera, see ``acceptance``).
    camera : Camera
        The paper's camera.
    mag_limit : float
        Faintest star the camera sees (approximate V) in the benchmarks and in its study.
    paper : str
        What the paper says about the camera, and which of its numbers we kept.
    acceptance_mag_limit : float or None
        Faintest star (approximate V) of the camera the method's acceptance test uses, when it
        differs from ``mag_limit`` (see ``acceptance``); ``None``: the same.
    """

    name: str
    camera: Camera
    mag_limit: float
    paper: str
    acceptance_mag_limit: float | None = None

    def acceptance(self) -> Preset:
        """The camera of the acceptance test: this preset at ``acceptance_mag_limit``, named
        ``<name>deep`` (itself when there is no separate limit).

        Kept out of ``PRESETS`` so that the benchmarks' ``--camera all`` runs the papers'
        cameras only.
        """
        if self.acceptance_mag_limit is None:
            return self
        return replace(self, name=f"{self.name}deep", mag_limit=self.acceptance_mag_limit,
                       paper=f"{self.paper}; acceptance camera at {self.acceptance_mag_limit:g} Mv",
                       acceptance_mag_limit=None)

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
    # 7.0 Mv is the sparse-field study (tests/core/test_sparse.py, the benchmarks): one frame
    # in five holds 3 stars or fewer. The acceptance camera goes to 8.0 Mv, the shallowest
    # half magnitude at which >= 99.5% of frames hold >= 4 stars (99.91% of 20,000; 7.5 Mv:
    # 96.6%) and about where Hipparcos stops being complete (docs/methods.md, radial).
    "seed002": Preset(
        "seed002", Camera.from_focal(_focal_for(4.0, 4096, 9.0), 9.0, 4096, 4096), 7.0,
        "002 radial: 4x4 deg, 4096x4096, 9 um; deeper limit (7.0 Mv: the median frame holds ~5 stars)",
        acceptance_mag_limit=8.0,
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
