"""``auto``'s compiled first pass gives the answer the general path gives, frame for frame."""

from __future__ import annotations

import math

import numpy as np
import pytest

from service.core import pipeline
from service.core.answer import recheck
from service.core.deeper import could_pair_more_deeper
from service.core.first_pass import deeper_arrays, first_pass
from service.core.pipeline import SolveOptions, _observation, solve
from service.core.plan import search_plan
from service.core.presets import PRESETS
from service.core.sim import SimConfig, simulate_frames
from service.core.types import Centroids
from service.core.verify import Verified, Verifier, camera_probes, marginal_choice


def _both(monkeypatch: pytest.MonkeyPatch, centroids: Centroids, camera, db, options: SolveOptions):
    monkeypatch.setattr(pipeline, "COMPILED_FIRST_PASS", True)
    fused = solve(centroids, camera, db, options=options)
    monkeypatch.setattr(pipeline, "COMPILED_FIRST_PASS", False)
    general = solve(centroids, camera, db, options=options)
    return fused, general


def _same_answer(fused, general) -> None:
    """The two paths' answers agree: status, stars, attitude, 1-sigma, residuals, bound."""
    assert (fused.status, fused.method, fused.reason) == (general.status, general.method, general.reason)
    assert [s[:2] for s in fused.stars] == [s[:2] for s in general.stars]
    if fused.solved:
        np.testing.assert_allclose(fused.quaternion, general.quaternion, atol=1e-12)
        np.testing.assert_allclose(fused.attitude_sigma_arcsec, general.attitude_sigma_arcsec, rtol=1e-9)
        np.testing.assert_allclose([s.residual_arcsec for s in fused.stars],
                                   [s.residual_arcsec for s in general.stars], atol=1e-3)
        assert fused.rms_arcsec == pytest.approx(general.rms_arcsec, rel=1e-9)
        assert fused.false_match_probability == pytest.approx(general.false_match_probability, rel=1e-9)


# seed 000 and 002: the first member is not the deepest (the answer is re-verified against it);
# seed 003: one member
@pytest.mark.parametrize(("preset", "noise"), [("seed000", 1.0), ("seed002", 0.5), ("seed003", 2.0)])
def test_the_compiled_first_pass_answers_as_the_general_path(monkeypatch, default_set_db, preset, noise) -> None:
    p = PRESETS[preset]
    config = SimConfig(mag_limit=p.mag_limit, centroid_noise_px=noise, false_stars=2, mag_noise=0.3)
    frames = simulate_frames(p.camera, 40, config, rng=31)
    options = SolveOptions(centroid_sigma_px=noise)
    plan, deepest = search_plan(default_set_db, [p.camera], "auto", noise)
    proved = 0
    for frame in frames:
        fused, general = _both(monkeypatch, frame.centroids, p.camera, default_set_db, options)
        _same_answer(fused, general)
        obs = _observation([(frame.centroids, p.camera, None)], [np.eye(3)])
        if len(obs) >= 5:
            proved += first_pass(obs, plan[0][0], deepest, noise, None, options.max_false_prob).solved
    assert proved >= 0.4 * len(frames)  # the compiled call answered many frames itself (seed 002: 18 of 40)


def test_a_frame_the_first_pass_cannot_prove_goes_on_without_searching_again(monkeypatch, default_set_db) -> None:
    # random points: quad proves nothing; the fallbacks run as on the general path and the
    # answer says so in the same words
    p = PRESETS["seed001"]
    rng = np.random.default_rng(4)
    for _ in range(5):
        xy = rng.uniform(0, p.camera.width - 1, (12, 2))
        cents = Centroids(xy, rng.uniform(1, 100, 12))
        fused, general = _both(monkeypatch, cents, p.camera, default_set_db, SolveOptions(centroid_sigma_px=1.0))
        assert not fused.solved and not general.solved
        assert fused.methods_tried == general.methods_tried
        assert fused.methods_tried[0] == "quad" and fused.methods_tried.count("quad") == general.methods_tried.count("quad")


def test_the_deeper_recheck_is_skipped_only_where_it_could_not_name_more_stars(default_set_db) -> None:
    # seed 000: the first member (V <= 6.5) is re-verified against the deepest (V <= 8); the
    # screen skips that recheck when no unpaired star lies near a deeper star
    p = PRESETS["seed000"]
    frames = simulate_frames(p.camera, 80, SimConfig(mag_limit=p.mag_limit, centroid_noise_px=1.0, false_stars=2),
                             rng=32)
    plan, deepest = search_plan(default_set_db, [p.camera], "auto", 1.0)
    member = plan[0][0]
    assert member is not deepest
    radius = 3.0
    skipped = named_more = 0
    for frame in frames:
        obs = _observation([(frame.centroids, p.camera, None)], [np.eye(3)])
        fp = first_pass(obs, member, member, 1.0, None, 1e-5)  # the member's own answer
        if not fp.solved:
            continue
        found = Verified(fp.obs_rows, fp.cat_rows, fp.matrix, fp.false_prob, fp.trials)
        rows = deeper_arrays(member, deepest).rows[found.cat]
        known = rows >= 0
        ok, m_obs, _, _, _ = recheck(obs, deepest, found.obs[known], rows[known], found.n_trials, radius)
        more = bool(ok) and len(m_obs) > len(found.obs)
        if could_pair_more_deeper(obs, deepest, found, radius):
            named_more += more
        else:
            skipped += 1
            assert not more
    assert skipped >= 10 and named_more >= 3


def _rotation(axis: np.ndarray, angle: float) -> np.ndarray:
    a = axis / np.linalg.norm(axis)
    k = np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])
    return np.eye(3) + math.sin(angle) * k + (1 - math.cos(angle)) * k @ k


def test_the_compiled_choice_among_marginal_answers_is_the_verifiers(default_set_db) -> None:
    # the compiled choice (auto's first pass calls it on the search's arrays) and
    # Verifier.best_marginal on the same answers: the likeliest, unless a star is paired two ways
    # or an image corner moves too far
    p = PRESETS["seed000"]
    frame = simulate_frames(p.camera, 1, SimConfig(mag_limit=p.mag_limit), rng=5)[0]
    obs = _observation([(frame.centroids, p.camera, None)], [np.eye(3)])
    radius = 3.0
    limit = 3 * radius * obs.pixel_scale_rad
    r0 = _rotation(np.array([0.3, -0.5, 0.8]), 1.1)
    base = (np.arange(6), np.arange(100, 106))

    def answer(obs_rows, cat_rows, r, prob):
        return Verified(np.asarray(obs_rows, np.int64), np.asarray(cat_rows, np.int64), r, prob, 7)

    nudge = _rotation(np.array([1.0, 0.2, 0.1]), 0.5 * limit)  # moves a corner by about half the limit
    push = _rotation(np.array([1.0, 0.2, 0.1]), 3.0 * limit)
    cases = {
        "one": [answer(*base, r0, 1e-7)],
        "agree": [answer(*base, r0, 1e-7), answer(base[0][:5], base[1][:5], nudge @ r0, 1e-9)],
        "star paired two ways": [answer(*base, r0, 1e-9), answer([0, 7], [999, 107], r0, 1e-7)],
        "catalogue star paired two ways": [answer(*base, r0, 1e-9), answer([9], [100], r0, 1e-7)],
        "corner moved": [answer(*base, r0, 1e-9), answer(*base, push @ r0, 1e-7)],
        "tie: the first": [answer(*base, r0, 1e-8), answer(base[0][:4], base[1][:4], r0, 1e-8)],
    }
    results = {}
    for name, marginal in cases.items():
        verifier = Verifier(default_set_db.members["mid"], obs, match_radius_px=radius)
        verifier.marginal = list(marginal)
        want = verifier.best_marginal()
        off = np.cumsum([0] + [len(v.obs) for v in marginal])
        got = marginal_choice(np.stack([v.matrix for v in marginal]), np.array([v.false_prob for v in marginal]),
                            off.astype(np.int64), np.concatenate([v.obs for v in marginal]),
                            np.concatenate([v.cat for v in marginal]),
                            np.ascontiguousarray(camera_probes(p.camera, np.eye(3))), limit)
        assert (want is None and got == -1) or (want is marginal[got]), name
        results[name] = got
    assert results == {"one": 0, "agree": 1, "star paired two ways": -1, "catalogue star paired two ways": -1,
                       "corner moved": -1, "tie: the first": 0}


@pytest.mark.parametrize(("preset", "noise", "false", "method", "need"),
                         [("seed002", 0.5, 2, "auto", 10), ("seed002", 0.5, 0, "auto", 10),
                          ("seed000", 1.0, 5, "auto", 2), ("seed003", 1.0, 2, "maxangle", 60),
                          ("seed001", 1.0, 2, "pyramid", 60)])
def test_an_answer_another_method_proved_is_finished_as_the_general_path_does(monkeypatch, default_set_db, preset,
                                                                                noise, false, method, need) -> None:
    """``settle``: the first pass's compiled finish for answers of the fallbacks (maxangle,
    pyramid, triangle's 3-4-star proofs) and of a method asked for by name, against ``deeper.refine_deeper``
    and ``finish.solution``; seeds 000 and 002 re-verify against a deeper member, seeds 001 and
    003 have one."""
    p = PRESETS[preset]
    config = SimConfig(mag_limit=p.mag_limit, centroid_noise_px=noise, false_stars=false, mag_noise=0.3)
    frames = simulate_frames(p.camera, 120, config, rng=33)
    options = SolveOptions(centroid_sigma_px=noise)
    by_fallback = 0
    for frame in frames:
        monkeypatch.setattr(pipeline, "COMPILED_SETTLE", True)
        fused = solve(frame.centroids, p.camera, default_set_db, method=method, options=options)
        monkeypatch.setattr(pipeline, "COMPILED_SETTLE", False)
        general = solve(frame.centroids, p.camera, default_set_db, method=method, options=options)
        _same_answer(fused, general)
        by_fallback += fused.solved and fused.method != "quad"
    assert by_fallback >= need
