"""``auto``'s fallbacks in one compiled call give the general loop's answer, frame for frame
(:mod:`service.core.fallback_pass`)."""

from __future__ import annotations

import time

import numpy as np
import pytest

from service.core import fallback_pass, pipeline
from service.core.fallback_pass import KIND_MAXANGLE, KIND_QUAD, fallback_passes, fallbacks
from service.core.pipeline import SolveOptions, _observation, solve
from service.core.plan import search_plan
from service.core.presets import PRESETS
from service.core.sim import SimConfig, simulate_frames
from tests.core.test_first_pass import _same_answer


def _same(a, b) -> None:
    _same_answer(a, b)
    assert a.methods_tried == b.methods_tried


def _counting(monkeypatch) -> list:
    """The pipeline's calls of :func:`fallbacks` from now on, with what each returned (the
    chain as its own call: ``pipeline.FRAME_CHAIN_CALL`` off; tests/core/test_frame_chain.py
    compares the chain in the first pass's call with this one)."""
    monkeypatch.setattr(pipeline, "FRAME_CHAIN_CALL", False)
    calls = []

    def counted(*args, **kwargs):
        got = fallbacks(*args, **kwargs)
        calls.append(got)
        return got

    monkeypatch.setattr(pipeline, "fallbacks", counted)
    return calls


def _compare(monkeypatch, db, preset: str, noise: float, false: int, n: int, rng: int) -> tuple[int, int]:
    """Solve ``n`` frames both ways; returns (frames the call took, frames it answered)."""
    p = PRESETS[preset]
    config = SimConfig(mag_limit=p.mag_limit, centroid_noise_px=noise, false_stars=false, mag_noise=0.3)
    options = SolveOptions(centroid_sigma_px=noise)
    calls = _counting(monkeypatch)
    for frame in simulate_frames(p.camera, n, config, rng=rng):
        monkeypatch.setattr(pipeline, "COMPILED_FALLBACKS", True)
        fused = solve(frame.centroids, p.camera, db, options=options)
        monkeypatch.setattr(pipeline, "COMPILED_FALLBACKS", False)
        general = solve(frame.centroids, p.camera, db, options=options)
        _same(fused, general)
    taken = [c for c in calls if c is not None]
    return len(taken), sum(c.found is not None for c in taken)


# seed 002 (sparse then narrow, 4096 px) and seed 000 (mid then narrow): two members, the
# passes alternate; seed 001: one member, one pass
@pytest.mark.parametrize(("preset", "noise", "false", "least"),
                         [("seed002", 0.5, 2, 60), ("seed002", 1.0, 5, 60), ("seed002", 2.0, 2, 40),
                          ("seed000", 2.0, 5, 1), ("seed001", 1.0, 5, 1)])
def test_the_compiled_fallbacks_answer_as_the_general_loop(monkeypatch, default_set_db, preset, noise, false,
                                                          least) -> None:
    taken, answered = _compare(monkeypatch, default_set_db, preset, noise, false, 200, 41)
    assert taken >= least
    if preset == "seed002":
        assert answered >= 10  # maxangle's proofs of frames whose bright detections are false


@pytest.mark.parametrize("budget", [None, 5])
def test_frames_of_more_stars_than_quad_looks_at_take_the_plans_order(monkeypatch, default_set_db, budget) -> None:
    """A frame of more than ``QUERY_STARS`` stars: every member's ``quad``, then the fallbacks,
    within ``MANY_STARS_MAX_TRIALS`` (random points: every pass runs to its end; with a budget of
    5 hypotheses, cut short), as the general loop runs them."""
    from service.core.sim import random_points

    if budget is not None:
        monkeypatch.setattr(pipeline, "MANY_STARS_MAX_TRIALS", budget)

    p = PRESETS["seed000"]
    options = SolveOptions(centroid_sigma_px=1.0)
    calls = _counting(monkeypatch)
    rng = np.random.default_rng(44)
    for n in (12, 20, 30, 39):
        points = random_points(p.camera, n, rng)
        monkeypatch.setattr(pipeline, "COMPILED_FALLBACKS", True)
        fused = solve(points, p.camera, default_set_db, options=options)
        monkeypatch.setattr(pipeline, "COMPILED_FALLBACKS", False)
        general = solve(points, p.camera, default_set_db, options=options)
        _same(fused, general)
        assert not fused.solved and fused.methods_tried == ("quad", "maxangle")
    assert len(calls) == 4 and all(c is not None for c in calls)
    if budget is None:
        assert all(c.tried == ["quad", "maxangle"] for c in calls)
    plan, _ = search_plan(default_set_db, [p.camera], "auto", 1.0)
    names = [(m.path.name, kind) for m, kind in fallback_passes(plan, small=False)]
    # narrow's maxangle (triangles to 3.5 deg) is left out: mid's sees the camera's whole field
    assert names == [("narrow", KIND_QUAD), ("mid", KIND_MAXANGLE)]
    assert [(m.path.name, kind) for m, kind in fallback_passes(plan)] == [("mid", KIND_MAXANGLE), ("narrow", KIND_QUAD)]


def test_a_spent_budget_is_counted_as_the_general_loop_counts_it(monkeypatch, default_set_db) -> None:
    # a budget of 5 hypotheses: passes are cut short or not started, on both paths alike
    monkeypatch.setattr(pipeline, "FEW_STARS_MAX_TRIALS", 5)
    taken, _ = _compare(monkeypatch, default_set_db, "seed002", 1.0, 5, 120, 42)
    assert taken >= 30


def test_the_passes_follow_the_general_loops_order(default_set_db) -> None:
    plan, _ = search_plan(default_set_db, [PRESETS["seed002"].camera], "auto", 0.5)
    names = [(m.path.name, kind) for m, kind in fallback_passes(plan)]
    assert names == [("sparse", KIND_MAXANGLE), ("narrow", KIND_QUAD), ("narrow", KIND_MAXANGLE)]
    plan, _ = search_plan(default_set_db, [PRESETS["seed001"].camera], "auto", 0.5)  # as seed 000's (mid first)
    assert [(m.path.name, kind) for m, kind in fallback_passes(plan)] == [("mid", KIND_MAXANGLE), ("narrow", KIND_QUAD)]
    plan, _ = search_plan(default_set_db, [PRESETS["seed002"].camera], "pyramid", 0.5)
    assert fallback_passes(plan) is None  # not auto's shape: the general loop


def test_a_quad_pass_short_of_its_patterns_hands_the_frame_back(monkeypatch, default_set_db) -> None:
    """With no hash probe allowed, the second member's ``quad`` cannot look up every pattern:
    the call returns None and the general loop (with its own bounds) answers the frame."""
    p = PRESETS["seed002"]
    frames = simulate_frames(p.camera, 300, SimConfig(mag_limit=p.mag_limit, centroid_noise_px=0.5, false_stars=2),
                             rng=43)
    frame = next(f for f in frames if len(f.centroids) == 6)
    obs = _observation([(frame.centroids, p.camera, None)], [np.eye(3)])
    plan, _ = search_plan(default_set_db, [p.camera], "auto", 0.5)
    args = (obs, plan, 0, 1000, 0.5, None, 1e-5, 8, time.perf_counter() + 1.0)
    assert fallbacks(*args) is not None
    monkeypatch.setattr(fallback_pass, "MAX_PROBES", -1)
    assert fallbacks(*args) is None
    assert fallbacks(*args[:-1], time.perf_counter()) is None  # no time left: the loop, which checks the clock


def test_a_frame_of_at_most_6_stars_runs_quad_on_the_first_member_only(default_set_db) -> None:
    """``pipeline.FIRST_QUAD_ONLY_STARS``: the later members' ``quad`` passes drop out of the
    chain; their fallbacks stay."""
    plan, _ = search_plan(default_set_db, [PRESETS["seed002"].camera], "auto", 0.5)
    names = [(m.path.name, kind) for m, kind in fallback_passes(plan, first_quad_only=True)]
    assert names == [("sparse", KIND_MAXANGLE), ("narrow", KIND_MAXANGLE)]
    plan, _ = search_plan(default_set_db, [PRESETS["seed001"].camera], "auto", 0.5)
    names = [(m.path.name, kind) for m, kind in fallback_passes(plan, first_quad_only=True)]
    assert names == [("mid", KIND_MAXANGLE)]


@pytest.mark.parametrize("compiled", [True, False])
def test_5_6_star_frames_answer_as_with_every_members_quad(default_set_db, monkeypatch, compiled) -> None:
    """Seed 002's 5-6-star frames (1 px, 1-2 false stars, magnitude noise): the same answers
    with the later members' ``quad`` passes (``FIRST_QUAD_ONLY_STARS = 4``, as before session 27)
    and without them, in the compiled chain and in the general loop (47,952 frames of
    bench_wrong's grid, seeds 3, 7 and 11: the same stars and attitudes)."""
    p = PRESETS["seed002"]
    monkeypatch.setattr(pipeline, "COMPILED_FALLBACKS", compiled)
    options = SolveOptions(centroid_sigma_px=1.0)
    frames = [f for false in (1, 2) for f in simulate_frames(
        p.camera, 60, SimConfig(mag_limit=p.mag_limit, centroid_noise_px=1.0, false_stars=false,
                                mag_noise=0.3), rng=70 + false) if 5 <= len(f.centroids) <= 6]
    assert len(frames) >= 20
    answers, chains = {}, {}
    for flag in (4, 6):
        monkeypatch.setattr(pipeline, "FIRST_QUAD_ONLY_STARS", flag)
        chains[flag] = _counting(monkeypatch)
        answers[flag] = [solve(f.centroids, p.camera, default_set_db, options=options) for f in frames]
    if compiled:  # narrow's quad ran in the chain before, and no longer
        assert any("quad" in c.tried for c in chains[4] if c is not None)
        assert not any("quad" in c.tried for c in chains[6] if c is not None)
    for before, after in zip(answers[4], answers[6], strict=True):
        assert before.solved == after.solved
        assert [s.hip for s in before.stars] == [s.hip for s in after.stars]
        assert before.quaternion == after.quaternion
    assert any("quad" in s.methods_tried and "maxangle" in s.methods_tried for s in answers[6])
    assert sum(s.solved for s in answers[6]) >= 3
