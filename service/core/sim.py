"""Synthetic star-camera frames with known truth, from the same Hipparcos catalogue.

A frame is the list of centroids a camera at a known attitude would report: the catalogue
stars in its field (brighter than a limit), with centroid noise, magnitude noise, false stars,
missing stars and a brightest-N cap. Truth is the quaternion and, per centroid, the HIP of the
star (or ``None`` for a false star).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache
from typing import Any

import numpy as np

from .attitude import quat_to_matrix, random_rotations
from .camera import Camera
from .catalog import StarTable, load_hipparcos, select_stars
from .types import Centroids

BLEND_PX = 2.0
"""Stars closer than this many pixels land in one blob: the simulator reports them as one."""
BLEND_DEG = 0.03
"""... and never closer than this (degrees, above the databases' default merge radius of
0.02 deg), so that a blend the database merged is one centroid in the simulator too."""


@dataclass(frozen=True, slots=True)
class SimConfig:
    """Noise model of simulated frames.

    Attributes
    ----------
    mag_limit : float
        Faintest star the camera sees (approximate V).
    centroid_noise_px : float
        Standard deviation of Gaussian centroid noise per axis, px.
    mag_noise : float
        Standard deviation of magnitude noise (changes brightness order only), mag.
    false_stars : int
        False stars added at uniform random pixels, with random brightness.
    missing_prob : float
        Probability that a real star is dropped.
    max_stars : int or None
        Keep only the brightest N centroids.
    epoch : float
        Decimal year of the sky.
    """

    mag_limit: float = 6.5
    centroid_noise_px: float = 0.0
    mag_noise: float = 0.0
    false_stars: int = 0
    missing_prob: float = 0.0
    max_stars: int | None = None
    epoch: float = 2026.0


@dataclass(frozen=True, slots=True)
class SimFrame:
    """One simulated frame and its truth."""

    quaternion: np.ndarray  # (4,) ICRS -> camera, [w, x, y, z]
    centroids: Centroids
    hip: np.ndarray  # (N,) int64, -1 for a false star
    blends: dict[int, tuple[int, ...]]  # centroid index -> HIPs blended into it (when > 1)

    def to_record(self, frame_id: Any, camera: Camera, *, camera_spec: dict[str, Any] | None = None) -> dict[str, Any]:
        """The recorded-frame JSON object (one line of a recording)."""
        rows = np.column_stack([self.centroids.xy, self.centroids.flux])
        return {
            "id": frame_id,
            "camera": camera_spec if camera_spec is not None else camera.to_spec(),
            "centroids": [[round(float(v), 4) for v in r] for r in rows],
            "truth": {
                "quaternion": [float(v) for v in self.quaternion],
                "hip": [None if h < 0 else int(h) for h in self.hip],
                **({"blends": {str(k): list(v) for k, v in self.blends.items()}} if self.blends else {}),
            },
        }


@lru_cache(maxsize=8)
def sky_stars(mag_limit: float, epoch: float, blend_deg: float = 0.0) -> StarTable:
    """The simulator's sky: every Hipparcos star to ``mag_limit``, with stars closer than
    ``blend_deg`` merged as the camera would see them."""
    return select_stars(load_hipparcos(), epoch=epoch, mag_limit=mag_limit, double_star_sep_deg=blend_deg)


def simulate_frame(
    camera: Camera,
    quaternion: np.ndarray,
    config: SimConfig,
    rng: np.random.Generator,
    *,
    stars: StarTable | None = None,
) -> SimFrame:
    """One frame of ``camera`` at attitude ``quaternion`` (ICRS -> camera, [w, x, y, z])."""
    if stars is None:
        stars = sky_stars(config.mag_limit, config.epoch, max(BLEND_PX / camera.f_px * 180 / math.pi, BLEND_DEG))
    r = quat_to_matrix(quaternion)
    boresight = r[2]
    cos_lim = math.cos(math.radians(camera.diagonal_fov_deg / 2 + 0.5))
    near = np.flatnonzero(stars.vec @ boresight > cos_lim)
    xy, inside = camera.vector_to_pixel(stars.vec[near] @ r.T)
    idx = near[inside]
    xy = xy[inside]
    mag = stars.mag[idx].astype(np.float64)
    hip = stars.hip[idx].astype(np.int64)
    if config.missing_prob > 0:
        keep = rng.random(len(idx)) >= config.missing_prob
        xy, mag, hip = xy[keep], mag[keep], hip[keep]
    if config.centroid_noise_px > 0:
        xy = xy + rng.normal(0.0, config.centroid_noise_px, xy.shape)
    if config.mag_noise > 0:
        mag = mag + rng.normal(0.0, config.mag_noise, mag.shape)
    if config.false_stars > 0:
        fxy = np.column_stack([rng.uniform(-0.5, camera.width - 0.5, config.false_stars),
                               rng.uniform(-0.5, camera.height - 0.5, config.false_stars)])
        fmag = rng.uniform(min(1.0, config.mag_limit), config.mag_limit, config.false_stars)
        xy = np.vstack([xy, fxy])
        mag = np.concatenate([mag, fmag])
        hip = np.concatenate([hip, -np.ones(config.false_stars, dtype=np.int64)])
    inside = camera.contains(xy)
    xy, mag, hip = xy[inside], mag[inside], hip[inside]
    order = np.argsort(mag, kind="stable")
    if config.max_stars is not None:
        order = order[: config.max_stars]
    flux = 10.0 ** (-0.4 * (mag[order] - 6.0)) * 1000.0
    hip = hip[order]
    table = stars.blends or {}
    blends = {i: table[int(h)] for i, h in enumerate(hip) if int(h) in table}
    return SimFrame(np.asarray(quaternion, dtype=np.float64), Centroids(xy[order], flux), hip, blends)


def simulate_frames(
    camera: Camera,
    n: int,
    config: SimConfig,
    *,
    rng: np.random.Generator | int | None = None,
) -> list[SimFrame]:
    """``n`` frames at attitudes uniform on SO(3) (seeded by ``rng``)."""
    gen = np.random.default_rng(rng)
    quats = random_rotations(n, gen)
    return [simulate_frame(camera, q, config, gen) for q in quats]


def random_points(camera: Camera, n: int, rng: np.random.Generator | int | None = None) -> Centroids:
    """``n`` uniformly random centroids (no real stars): every method must refuse them."""
    gen = np.random.default_rng(rng)
    xy = np.column_stack([gen.uniform(0, camera.width - 1, n), gen.uniform(0, camera.height - 1, n)])
    return Centroids(xy, gen.uniform(1.0, 1000.0, n))
