"""The fallback chain in the first pass's own compiled call gives the answers of the two calls,
frame for frame (:mod:`service.core.frame_chain`)."""

from __future__ import annotations

import time

import numpy as np
import pytest

from service.core import frame_chain, pipeline
from service.core.pipeline import SolveOptions, solve
from service.core.presets import PRESETS
from service.core.sim import SimConfig, random_points, simulate_frames
from tests.core.test_first_pass import _same_answer


def _same(a, b) -> None:
    _same_answer(a, b)
    assert (a.methods_tried, a.message) == (b.methods_tried, b.message)


def _counting(monkeypatch) -> list:
    """What the chain did in the first pass's call from now on, where the pipeline read it (a
    refusal, or a proof the call did not finish): one :class:`~service.core.fallback_pass.Chain`
    a frame."""
    seen = []
    unpack, refused = frame_chain.unpack_chain, frame_chain.refused_chain

    def counted_proof(*args):
        got = unpack(*args)
        seen.append(got.chain)
        return got

    def counted_refusal(*args):
        got = refused(*args)
        seen.append(got)
        return got

    monkeypatch.setattr(pipeline, "unpack_chain", counted_proof)
    monkeypatch.setattr(pipeline, "refused_chain", counted_refusal)
    return seen


def _both(monkeypatch, db, frames, camera, options) -> int:
    """Solve each frame both ways; returns how many answers of a fallback were finished in the
    first pass's call (:data:`~service.core.frame_chain.STAGE_SETTLED`: no observation made)."""
    settled = 0
    for centroids in frames:
        monkeypatch.setattr(pipeline, "FRAME_CHAIN_CALL", True)
        one = solve(centroids, camera, db, options=options)
        monkeypatch.setattr(pipeline, "FRAME_CHAIN_CALL", False)
        two = solve(centroids, camera, db, options=options)
        _same(one, two)
        settled += one.solved and one.method != "quad" and one.timings_ms["vectors"] == 0.0
    return settled


# seed 002: sparse then narrow (4096 px), most 5-7-star frames reach the chain; seed 000 and
# 001: mid first; 0 false stars: the first pass proves nearly all
@pytest.mark.parametrize(("preset", "noise", "false", "least", "proven"),
                         [("seed002", 0.5, 2, 60, 10), ("seed002", 1.0, 5, 60, 1), ("seed002", 2.0, 2, 40, 1),
                          ("seed002", 0.5, 0, 0, 0), ("seed000", 2.0, 5, 1, 0), ("seed001", 1.0, 5, 1, 0)])
def test_the_chain_in_the_first_pass_call_answers_as_two_calls(monkeypatch, default_set_db, preset, noise, false,
                                                               least, proven) -> None:
    p = PRESETS[preset]
    config = SimConfig(mag_limit=p.mag_limit, centroid_noise_px=noise, false_stars=false, mag_noise=0.3)
    seen = _counting(monkeypatch)
    frames = [f.centroids for f in simulate_frames(p.camera, 200, config, rng=51)]
    settled = _both(monkeypatch, default_set_db, frames, p.camera, SolveOptions(centroid_sigma_px=noise))
    assert len(seen) + settled >= least
    assert settled >= proven  # maxangle's proofs on the first member, finished in the same call


def test_random_points_are_refused_as_by_two_calls(monkeypatch, default_set_db) -> None:
    """Frames of 5-39 random points on seed 000's camera: every pass runs to its end (the many-star
    budget above ``QUERY_STARS``), and the refusal is made with no observation. Two frames of
    each size: a set-up makes the chain's arguments for a size after its first miss, so the
    first frame makes two calls, the second one."""
    p = PRESETS["seed000"]
    rng = np.random.default_rng(52)
    seen = _counting(monkeypatch)
    frames = [random_points(p.camera, int(n), rng) for n in (5, 6, 7, 9, 12, 20, 30, 39) for _ in range(2)]
    _both(monkeypatch, default_set_db, frames, p.camera, SolveOptions(centroid_sigma_px=1.0, timeout_ms=495.0))
    assert len(seen) == len(frames) // 2 and all(s.found is None for s in seen)


def test_a_spent_budget_is_counted_as_by_two_calls(monkeypatch, default_set_db) -> None:
    # a budget of 5 hypotheses: passes cut short or not started, in both ways alike (a set-up of
    # its own: the budget is part of the chain's arguments kept on it)
    monkeypatch.setattr(pipeline, "FEW_STARS_MAX_TRIALS", 5)
    p = PRESETS["seed002"]
    config = SimConfig(mag_limit=p.mag_limit, centroid_noise_px=1.0, false_stars=5)
    seen = _counting(monkeypatch)
    frames = [f.centroids for f in simulate_frames(p.camera, 120, config, rng=53)]
    _both(monkeypatch, default_set_db, frames, p.camera, SolveOptions(centroid_sigma_px=1.0, timeout_ms=499.0))
    assert len(seen) >= 30


def test_a_chain_that_hands_the_frame_back_leaves_it_to_the_general_loop(monkeypatch, default_set_db) -> None:
    """With no hash probe allowed, the second member's ``quad`` cannot look up every pattern:
    the chain hands the frame back, and the general loop answers it as after two calls."""
    from service.core import fallback_pass

    monkeypatch.setattr(fallback_pass, "MAX_PROBES", -1)  # (fallback_pass.chain_bounds: both paths)
    p = PRESETS["seed002"]
    config = SimConfig(mag_limit=p.mag_limit, centroid_noise_px=0.5, false_stars=2)
    frames = [f.centroids for f in simulate_frames(p.camera, 300, config, rng=54) if len(f.centroids) >= 7][:30]
    seen = _counting(monkeypatch)
    _both(monkeypatch, default_set_db, frames, p.camera, SolveOptions(centroid_sigma_px=0.5, timeout_ms=498.0))
    assert len(seen) < len(frames)  # (7-10-star frames run narrow's quad in the chain: handed back)


def test_a_frame_near_its_time_limit_makes_two_calls(default_set_db) -> None:
    """The chain does not look at the clock: a frame whose limit leaves less than
    ``MIN_CLOCK_S + FIRST_PASS_CLOCK_S`` does not take it in the first pass's call."""
    from service.core.camera_setup import kept_setup

    p = PRESETS["seed002"]
    options = SolveOptions(centroid_sigma_px=1.0, timeout_ms=60.0)
    frame = simulate_frames(p.camera, 1, SimConfig(mag_limit=p.mag_limit), rng=55)[0].centroids
    solve(frame, p.camera, default_set_db, options=options)
    setup = kept_setup(default_set_db, p.camera, "auto", options)
    assert setup is not None
    assert pipeline._frame_chain(setup, 6, "auto", options, time.perf_counter()) is None
    fresh = SolveOptions(centroid_sigma_px=1.0, timeout_ms=497.0)
    solve(frame, p.camera, default_set_db, options=fresh)
    setup = kept_setup(default_set_db, p.camera, "auto", fresh)
    assert pipeline._frame_chain(setup, 6, "auto", fresh, time.perf_counter()) is None  # not made before a miss
    assert pipeline._frame_chain(setup, 6, "auto", fresh, None, build=True) is not None  # made (after a miss)
    assert pipeline._frame_chain(setup, 6, "auto", fresh, time.perf_counter()) is not None  # then kept


def test_a_new_cameras_first_frames_make_the_chains_arguments_only_after_a_miss(default_set_db) -> None:
    """A camera's frame that the first pass proves costs no chain set-up (each real image is a
    camera of its own); after a miss, the camera's later frames of that size take the one call."""
    from service.core.camera_setup import kept_setup

    p = PRESETS["seed002"]
    options = SolveOptions(centroid_sigma_px=1.0, timeout_ms=496.0)
    frames = simulate_frames(p.camera, 200, SimConfig(mag_limit=p.mag_limit, centroid_noise_px=1.0, false_stars=0),
                             rng=56)
    proven = next(f.centroids for f in frames if len(f.centroids) >= 9)
    assert solve(proven, p.camera, default_set_db, options=options).solved
    setup = kept_setup(default_set_db, p.camera, "auto", options)
    assert not setup.chains
    points = random_points(p.camera, 8, np.random.default_rng(57))
    first = solve(points, p.camera, default_set_db, options=options)
    assert len(setup.chains) == 1 and first.timings_ms["vectors"] > 0.0  # two calls, then made
    again = solve(points, p.camera, default_set_db, options=options)
    assert again.timings_ms["vectors"] == 0.0  # one call: no observation
    _same(first, again)
