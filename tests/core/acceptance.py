"""Shared loops of the acceptance tests: score simulated frames, refuse random points."""

from __future__ import annotations

from collections.abc import Sequence

from service.core.camera import Camera
from service.core.evaluate import score
from service.core.navdb import NavDatabase
from service.core.pipeline import DEFAULT_OPTIONS, SolveOptions, solve
from service.core.sim import SimFrame, random_points


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
                                 options: SolveOptions = DEFAULT_OPTIONS, n: int = 200) -> None:
    """``n`` frames of 3-30 uniform random points: every one must be ``no_solution``."""
    for i in range(n):
        pts = random_points(camera, 3 + i % 28, rng=seed + i)
        assert not solve(pts, camera, db, method=method, options=options).solved, f"random frame {i} solved"
