"""Shared loops of the acceptance tests: score simulated frames, refuse random points, build a
preset's database and frames."""

from __future__ import annotations

from collections.abc import Sequence

import pytest

from service.core.camera import Camera
from service.core.evaluate import score
from service.core.navdb import NavDatabase, build_database, open_database
from service.core.pipeline import DEFAULT_OPTIONS, SolveOptions, solve
from service.core.presets import Preset
from service.core.sim import SimConfig, SimFrame, random_points, simulate_frames


def tally(frames: Sequence[SimFrame], camera: Camera, db: NavDatabase, method: str,
          options: SolveOptions = DEFAULT_OPTIONS) -> tuple[int, int]:
    """(solved, wrong) over ``frames``, scored against their truth (blends included)."""
    solved = wrong = 0
    for f in frames:
        s = score(solve(f.centroids, camera, db, method=method, options=options), f.quaternion,
                  f.hip.tolist(), blends=f.blends)
        solved += s.solved
        wrong += s.solved and not s.correct
    return solved, wrong


def assert_refuses_random_points(camera: Camera, db: NavDatabase, method: str, *, seed: int,
                                 options: SolveOptions = DEFAULT_OPTIONS, n: int = 56) -> None:
    """``n`` frames of 3-30 uniform random points (each count twice; five times until session 25
    and three until session 36, when CI's ten minutes ran short): every one must be
    ``no_solution``. ``bench.bench_wrong`` counts wrong answers at scale."""
    for i in range(n):
        pts = random_points(camera, 3 + i % 28, rng=seed + i)
        assert not solve(pts, camera, db, method=method, options=options).solved, f"random frame {i} solved"


def assert_identifies(frames: Sequence[SimFrame], camera: Camera, db: NavDatabase, method: str, *,
                      rate: float = 0.99, options: SolveOptions = DEFAULT_OPTIONS) -> None:
    """At least ``rate`` of ``frames`` identified and not one wrong answer."""
    solved, wrong = tally(frames, camera, db, method, options)
    assert wrong == 0, f"{wrong} wrong answers ({solved} solved of {len(frames)})"
    assert solved >= rate * len(frames), f"{solved} of {len(frames)} frames identified"


def preset_database(tmp_path_factory: pytest.TempPathFactory, preset: Preset,
                    methods: tuple[str, ...]) -> NavDatabase:
    """A database of ``methods`` for ``preset`` (its magnitude limit), in a fresh temporary folder."""
    path = tmp_path_factory.mktemp(preset.name) / preset.name
    build_database(path, preset.build_config(methods))
    return open_database(path)


def preset_frames(preset: Preset, n: int, *, rng: int, noise_px: float = 0.5) -> list[SimFrame]:
    """``n`` simulated frames of ``preset``'s camera to its magnitude limit, ``noise_px`` (px, per
    axis) centroid noise."""
    config = SimConfig(mag_limit=preset.mag_limit, centroid_noise_px=noise_px)
    return simulate_frames(preset.camera, n, config, rng=rng)
