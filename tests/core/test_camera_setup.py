"""A camera's set-up kept with the database gives the answers solved without it
(:mod:`service.core.camera_setup`)."""

from __future__ import annotations

import dataclasses

import pytest

from service.core import camera_setup
from service.core.camera_setup import CameraSetup, keep_setup, kept_setup
from service.core.pipeline import SolveOptions, solve
from service.core.presets import PRESETS
from service.core.sim import SimConfig, random_points, simulate_frames
from service.core.types import Centroids, NoSolutionReason
from tests.core.test_first_pass import _same_answer


def _clear(db) -> None:
    db.__dict__.pop("_camera_setups", None)


@pytest.mark.parametrize(("preset", "noise", "false"), [("seed000", 1.0, 2), ("seed002", 0.5, 2), ("seed004", 2.0, 5)])
def test_frames_solved_with_the_kept_setup_answer_as_without(default_set_db, preset, noise, false) -> None:
    p = PRESETS[preset]
    config = SimConfig(mag_limit=p.mag_limit, centroid_noise_px=noise, false_stars=false, mag_noise=0.3)
    options = SolveOptions(centroid_sigma_px=noise)
    frames = [f.centroids for f in simulate_frames(p.camera, 30, config, rng=51)]
    frames.append(random_points(p.camera, 25, 52))
    _clear(default_set_db)
    solve(frames[0], p.camera, default_set_db, options=options)  # makes the setup
    setup = kept_setup(default_set_db, p.camera, "auto", options)
    assert setup is not None and setup.camera is p.camera and setup.options is options
    kept = [solve(c, p.camera, default_set_db, options=options) for c in frames]
    assert kept_setup(default_set_db, p.camera, "auto", options) is setup  # used, not remade
    fresh = []
    for c in frames:
        _clear(default_set_db)
        # an equal camera of another object is not the kept one's: the general set-up
        other = dataclasses.replace(p.camera)
        assert kept_setup(default_set_db, other, "auto", options) is None
        fresh.append(solve(c, other, default_set_db, options=options))
    for a, b in zip(kept, fresh, strict=True):
        _same_answer(a, b)
        assert a.methods_tried == b.methods_tried
    assert sum(s.solved for s in kept) >= 15
    # the kept camera's first pass ran from the centroids as given (frame_first_pass_kernel): its
    # proofs made no Observation, their vectors counted in identify; the fresh ones' did
    fused = [s for s in kept if s.solved and s.timings_ms["vectors"] == 0.0]
    assert len(fused) >= 10 and all(s.methods_tried == ("quad",) for s in fused)
    assert all(s.timings_ms["vectors"] > 0.0 for s in fresh if s.solved)
    # a frame the pass did not prove: its first pass is counted in identify, not in vectors
    refused = kept[-1]  # the random points
    assert not refused.solved and 0.0 < refused.timings_ms["vectors"] < refused.timings_ms["identify"] / 5


def test_the_setup_is_per_method_and_options_and_still_refuses_too_few_stars(default_set_db) -> None:
    p = PRESETS["seed000"]
    frame = simulate_frames(p.camera, 1, SimConfig(mag_limit=p.mag_limit, centroid_noise_px=0.5), rng=53)[0]
    options = SolveOptions(centroid_sigma_px=0.5)
    _clear(default_set_db)
    assert solve(frame.centroids, p.camera, default_set_db, options=options).solved
    assert kept_setup(default_set_db, p.camera, "auto", options) is not None
    assert kept_setup(default_set_db, p.camera, "maxangle", options) is None
    assert kept_setup(default_set_db, p.camera, "auto", SolveOptions(centroid_sigma_px=0.5)) is None
    two = Centroids(frame.centroids.xy[:2], frame.centroids.flux[:2])
    sol = solve(two, p.camera, default_set_db, options=options)
    assert not sol.solved and sol.reason == NoSolutionReason.TOO_FEW_STARS


def test_the_kept_setups_are_bounded(default_set_db, monkeypatch) -> None:
    monkeypatch.setattr(camera_setup, "SETUPS_KEPT", 3)
    _clear(default_set_db)
    cams = [dataclasses.replace(PRESETS["seed000"].camera) for _ in range(4)]
    options = SolveOptions()
    for cam in cams:
        keep_setup(default_set_db, CameraSetup(cam, options, "auto", [], default_set_db, (), None))
    assert len(default_set_db.__dict__["_camera_setups"]) == 1  # cleared when full, then the newest
    assert kept_setup(default_set_db, cams[-1], "auto", options) is not None
    assert kept_setup(default_set_db, cams[0], "auto", options) is None
    _clear(default_set_db)
