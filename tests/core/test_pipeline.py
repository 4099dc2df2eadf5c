"""Acceptance: every method on seed 000's camera, scored against the simulator's truth."""

import numpy as np
import pytest

from service.core.camera import Camera
from service.core.errors import InvalidInputError, UnknownMethodError
from service.core.evaluate import score
from service.core.methods import maxangle, method_names
from service.core.pipeline import SolveOptions, solve
from service.core.presets import PRESETS
from service.core.sim import SimConfig, random_points, simulate_frames
from service.core.types import Centroids, NoSolutionReason
from tests.conftest import SEED000_CAMERA

SEED000_METHODS = ["maxangle", "pyramid"]


@pytest.fixture(scope="module")
def frames_1px_2false():
    """Five seeded sets of 500 frames (seeds 0-4, all kept): 1 px noise, 2 false stars."""
    config = SimConfig(mag_limit=6.5, centroid_noise_px=1.0, false_stars=2)
    return [simulate_frames(SEED000_CAMERA, 500, config, rng=seed) for seed in range(5)]


@pytest.mark.slow
@pytest.mark.parametrize("method", SEED000_METHODS)
def test_identifies_99_percent_with_no_wrong_answer(method: str, seed000_db, frames_1px_2false) -> None:
    """Seed 000's experiment: 1 px centroid noise, 2 false stars; >= 99% of frames identified,
    none wrong.

    The rate is measured on 2,500 frames (five seeded sets of 500) because one set of 500 is
    too small a sample for a 1% bar: the sets hold 2-8 frames with <= 5 real stars, and at this
    noise such a frame cannot be told from a coincidence at the verifier's 1e-5 bound (two
    extra stars each land near some predicted star for ~5e-4 of random points, times the
    hypotheses tried). Measured: maxangle 99.28%, pyramid 99.32% (the sets: 98.4-99.8%).
    Every frame with >= 6 real stars must be solved but one in 500, every set >= 98%.
    """
    solved = wrong = rich = rich_solved = total = 0
    for frames in frames_1px_2false:
        set_solved = 0
        for f in frames:
            sol = solve(f.centroids, SEED000_CAMERA, seed000_db, method=method)
            s = score(sol, f.quaternion, f.hip.tolist(), blends=f.blends)
            set_solved += s.solved
            wrong += s.solved and not s.correct
            n_real = int((f.hip >= 0).sum())
            rich += n_real >= 6
            rich_solved += n_real >= 6 and s.solved
            if s.solved:
                assert sol.method == method
                assert s.cross_boresight_arcsec < 150  # 1 px = 30 arcsec
        assert set_solved >= 0.98 * len(frames)
        solved += set_solved
        total += len(frames)
    assert wrong == 0
    assert rich_solved >= 0.998 * rich
    assert solved >= 0.99 * total


@pytest.mark.slow
@pytest.mark.parametrize("method", ["auto", *SEED000_METHODS])
def test_random_points_never_solve(method: str, seed000_db) -> None:
    for i in range(200):
        pts = random_points(SEED000_CAMERA, 5 + i % 25, rng=i)
        assert not solve(pts, SEED000_CAMERA, seed000_db, method=method).solved


def test_solution_fields(seed000_db) -> None:
    f = simulate_frames(SEED000_CAMERA, 1, SimConfig(centroid_noise_px=0.2), rng=42)[0]
    sol = solve(f.centroids, SEED000_CAMERA, seed000_db)
    assert sol.solved and sol.method in method_names()
    d = sol.to_dict("frame-1")
    assert d["id"] == "frame-1" and d["status"] == "solved"
    assert len(d["quaternion"]) == 4 and abs(np.linalg.norm(d["quaternion"]) - 1) < 1e-12
    assert 0 <= d["ra_deg"] < 360 and -90 <= d["dec_deg"] <= 90 and 0 <= d["roll_deg"] < 360
    assert d["false_match_probability"] < 1e-5
    assert d["rms_arcsec"] < 15
    assert set(d["timings_ms"]) >= {"vectors", "identify", "attitude", "total"}
    assert score(sol, f.quaternion, f.hip.tolist(), blends=f.blends).correct
    assert all(star["residual_arcsec"] < 30 for star in d["stars"])
    assert len(d["stars"]) >= 0.9 * (f.hip >= 0).sum()


def test_hint_far_from_truth_refuses(seed000_db) -> None:
    f = simulate_frames(SEED000_CAMERA, 1, SimConfig(), rng=7)[0]
    far = (f.quaternion[1], -f.quaternion[0], f.quaternion[3], -f.quaternion[2])  # 180 deg away
    assert not solve(f.centroids, SEED000_CAMERA, seed000_db, hint=(far, 5.0)).solved
    assert solve(f.centroids, SEED000_CAMERA, seed000_db, hint=(f.quaternion, 5.0)).solved


def test_too_few_and_empty(seed000_db) -> None:
    assert not solve(Centroids.from_list([]), SEED000_CAMERA, seed000_db).solved
    assert not solve(Centroids.from_list([[1, 2], [3, 4]]), SEED000_CAMERA, seed000_db).solved


def test_misuse_raises(seed000_db) -> None:
    with pytest.raises(UnknownMethodError):
        solve(Centroids.from_list([[1, 2]]), SEED000_CAMERA, seed000_db, method="nope")
    with pytest.raises(InvalidInputError, match="centroids"):
        Centroids.from_list([[1, float("nan")]])


@pytest.mark.slow
@pytest.mark.parametrize("method", ["auto", *SEED000_METHODS])
def test_missing_stars_magnitude_noise_and_more_false_stars(method: str, seed000_db) -> None:
    """A harsher sky: 20% of stars missing, 0.5 mag brightness noise (order scrambled), 4 false
    stars, 1.5 px centroid noise. Fewer frames solve; none may be wrong."""
    from service.core.pipeline import SolveOptions

    cfg = SimConfig(mag_limit=6.5, centroid_noise_px=1.5, mag_noise=0.5, false_stars=4, missing_prob=0.2)
    frames = simulate_frames(SEED000_CAMERA, 150, cfg, rng=11)
    opts = SolveOptions(centroid_sigma_px=1.5)
    solved = 0
    for f in frames:
        sol = solve(f.centroids, SEED000_CAMERA, seed000_db, method=method, options=opts)
        s = score(sol, f.quaternion, f.hip.tolist(), blends=f.blends)
        assert not (s.solved and not s.correct), "wrong answer"
        solved += s.solved
    assert solved >= 0.9 * len(frames)


def test_no_solution_says_why_and_what_ran(seed000_db) -> None:
    """``reason``/``methods_tried``/``message`` (issue 12 item 6): a refused frame runs nothing,
    a searched one lists what ran, and ``method`` is never a method that did not run."""
    from service.core.navdb import open_database
    from service.core.pipeline import SolveOptions
    from service.core.types import NoSolutionReason

    fresh = open_database(seed000_db.path)  # not warmed: a refusal must not warm it
    few = solve(Centroids.from_list([[1, 2], [3, 4]]), SEED000_CAMERA, fresh)
    assert few.reason is NoSolutionReason.TOO_FEW_STARS and few.methods_tried == () and few.method == "auto"
    tiny = Camera.from_fov(1.5, 1024, 1024)  # the database serves 8.6-12.4 deg
    pts = random_points(tiny, 12, rng=1)
    out = solve(pts, tiny, fresh, method="maxangle")
    assert out.reason is NoSolutionReason.CAMERA_OUTSIDE_DATABASE and out.methods_tried == ()
    assert "skyfix db build" in out.message and "--fov-min 1.5" in out.message
    assert not fresh.__dict__.get("_warm"), "refused before warm-up"
    d = out.to_dict()
    assert d["reason"] == "camera_outside_database" and d["methods_tried"] == [] and d["message"] == out.message

    late = solve(random_points(SEED000_CAMERA, 20, rng=3), SEED000_CAMERA, seed000_db,
                 options=SolveOptions(timeout_ms=1e-6))
    assert late.reason is NoSolutionReason.TIME_LIMIT
    assert late.methods_tried == ("maxangle",) and late.method == "maxangle"  # was "pyramid"

    reasons = set()
    for i in range(20):
        sol = solve(random_points(SEED000_CAMERA, 5 + i, rng=i), SEED000_CAMERA, seed000_db)
        assert not sol.solved and sol.methods_tried == ("maxangle", "pyramid") and sol.method == "pyramid"
        reasons.add(sol.reason)
        assert sol.message and "maxangle, pyramid" in sol.message
    assert reasons <= {NoSolutionReason.NO_PATTERN_MATCH, NoSolutionReason.NOT_PROVEN} and reasons

    f = simulate_frames(SEED000_CAMERA, 1, SimConfig(centroid_noise_px=0.2), rng=42)[0]
    good = solve(f.centroids, SEED000_CAMERA, seed000_db)
    assert good.solved and good.reason is None and good.message is None
    assert good.methods_tried[-1] == good.method and good.to_dict()["reason"] is None


def test_a_named_method_searches_the_members_that_hold_it(default_set_db) -> None:
    """The default set's `sparse` member alone holds `triangle`: `--method triangle` on a 4-deg
    camera searches it; on a camera no member holding it serves, the error names what can."""
    preset = PRESETS["seed002"]
    config = SimConfig(mag_limit=preset.mag_limit, centroid_noise_px=0.5)
    frames = [f for f in simulate_frames(preset.camera, 40, config, rng=3) if len(f.centroids) >= 6][:5]
    solved = [solve(f.centroids, preset.camera, default_set_db, method="triangle",
                    options=SolveOptions(centroid_sigma_px=0.5)) for f in frames]
    assert all(s.method == "triangle" for s in solved) and sum(s.solved for s in solved) >= 4
    wide = PRESETS["seed004"]
    with pytest.raises(UnknownMethodError) as err:
        solve(frames[0].centroids, wide.camera, default_set_db, method="triangle")
    assert "triangle" not in err.value.known and "quad" in err.value.known


def test_a_frame_no_answer_could_pass_skips_the_triangle_fallbacks(seed000_db, monkeypatch) -> None:
    """``maxangle`` and ``pyramid`` prove a triangle by the stars beyond it; a 4-star frame of
    this 1024-px camera could not pass the bound even with every star paired
    (``Verifier.could_prove``), so neither runs. Five stars can, and both run."""
    import service.core.pipeline as pipeline

    four = solve(random_points(SEED000_CAMERA, 4, rng=5), SEED000_CAMERA, seed000_db)
    assert not four.solved and not set(four.methods_tried) & pipeline.TRIANGLE_PROOF_METHODS
    # nothing else could run: the answer says the frame has too few stars, and what was not run
    assert four.methods_tried == () and four.reason is NoSolutionReason.TOO_FEW_STARS and four.method == "auto"
    assert "not run: maxangle, pyramid" in four.message and "4 stars" in four.message
    five = solve(random_points(SEED000_CAMERA, 5, rng=5), SEED000_CAMERA, seed000_db)
    assert not five.solved and five.methods_tried == ("maxangle", "pyramid")
    monkeypatch.setattr(pipeline, "TRIANGLE_PROOF_METHODS", frozenset())
    four = solve(random_points(SEED000_CAMERA, 4, rng=5), SEED000_CAMERA, seed000_db)
    assert four.methods_tried == ("maxangle", "pyramid")


def test_few_star_frames_searched_in_full_get_a_budget_of_hypotheses(default_set_db, monkeypatch) -> None:
    """A frame of 5-7 stars that quad searched in full on every member gets the first fallback
    for ``FEW_STARS_MAX_TRIALS`` more hypotheses over all members (a count, not the clock: the
    same frame gets the same answer on a loaded machine); with none it does not start."""
    import service.core.pipeline as pipeline

    p = PRESETS["seed000"]
    frame = random_points(p.camera, 6, rng=11)
    opts = SolveOptions(centroid_sigma_px=1.0)
    full = solve(frame, p.camera, default_set_db, options=opts)
    assert full.methods_tried == ("quad", "maxangle")
    monkeypatch.setattr(pipeline, "FEW_STARS_MAX_TRIALS", 0)
    assert solve(frame, p.camera, default_set_db, options=opts).methods_tried == ("quad",)
    monkeypatch.setattr(pipeline, "FEW_STARS_MAX_TRIALS", 1)  # one screen's worth, then no further check
    compiled = solve(frame, p.camera, default_set_db, options=opts)  # maxangle_search counts as the loop does
    monkeypatch.setattr(maxangle, "COMPILED_SEARCH", False)  # the Python loop, whose checks can be seen
    monkeypatch.setattr(pipeline, "COMPILED_FALLBACKS", False)
    seen: list[int] = []
    real = pipeline.Verifier.check

    def check(self, obs_idx, cat_idx, **kw):
        seen.append(self.trials)
        return real(self, obs_idx, cat_idx, **kw)

    monkeypatch.setattr(pipeline.Verifier, "check", check)
    looped = solve(frame, p.camera, default_set_db, options=opts)
    assert not looped.solved and not compiled.solved
    assert seen == []  # the first screen used up the budget before any check
    assert compiled.message == looped.message  # the same count of hypotheses


def test_many_star_frames_searched_in_full_get_a_budget_of_hypotheses(default_set_db, monkeypatch) -> None:
    """A frame of more than quad.QUERY_STARS stars that quad searched in full gets the first
    fallback for ``MANY_STARS_MAX_TRIALS`` more hypotheses over all members, a count and not the
    clock: with none it does not start, with a few it stops there, and the same frame gives the
    same count whatever the machine's load."""
    import service.core.pipeline as pipeline

    p = PRESETS["seed000"]
    frame = random_points(p.camera, 25, rng=7)
    opts = SolveOptions(centroid_sigma_px=1.0)
    full = solve(frame, p.camera, default_set_db, options=opts)
    assert not full.solved and full.methods_tried == ("quad", "maxangle")
    assert solve(frame, p.camera, default_set_db, options=opts).message == full.message
    monkeypatch.setattr(pipeline, "MANY_STARS_MAX_TRIALS", 0)
    assert solve(frame, p.camera, default_set_db, options=opts).methods_tried == ("quad",)
    monkeypatch.setattr(pipeline, "MANY_STARS_MAX_TRIALS", 1)
    capped = solve(frame, p.camera, default_set_db, options=opts)
    assert capped.methods_tried == ("quad", "maxangle")
    checked = int(full.message.split()[0])  # "591 candidate attitude(s) checked, none proven ..."
    assert int(capped.message.split()[0]) < checked


def test_an_8_star_frame_whose_bright_detections_are_false_gets_the_fallback(default_set_db) -> None:
    """An 8-star seed 002 frame with 3 false stars that ``quad`` searched in full without a
    proof (its true stars are fainter than the pattern stars of its region) is not refused: the
    first fallback proves it, and every answer is right. Until session 16 such frames were
    refused without the fallback (seed 002 at 0.5 px, 3 false stars: 96 -> 118 of 200 named)."""
    p = PRESETS["seed002"]
    opts = SolveOptions(centroid_sigma_px=0.5)
    frames = [f for f in simulate_frames(p.camera, 400, SimConfig(mag_limit=p.mag_limit, centroid_noise_px=0.5,
                                                                   false_stars=3), rng=21)
              if len(f.centroids) == 8]
    sols = [solve(f.centroids, p.camera, default_set_db, options=opts) for f in frames]
    by_fallback = [(f, s) for f, s in zip(frames, sols, strict=True)
                   if s.solved and s.methods_tried == ("quad", "maxangle")]
    assert len(by_fallback) >= 3
    for f, s in zip(frames, sols, strict=True):
        if s.solved:
            assert score(s, f.quaternion, f.hip.tolist(), blends=f.blends).correct


def test_a_small_frame_gets_the_first_members_fallback_before_the_next_members_quad(default_set_db,
                                                                                   monkeypatch) -> None:
    """SMALL_FRAME_FALLBACK_FIRST: a 7-star seed 002 frame with 2 false stars, which quad cannot
    prove (4 + 1 stars do not pass the bound at 4096 px), is proven by the first member's maxangle
    without the second member's quad; the answer is the one the plan's own order gives."""
    import service.core.pipeline as pipeline
    from service.core.methods.quad import QuadMatcher

    p = PRESETS["seed002"]
    opts = SolveOptions(centroid_sigma_px=1.0)
    frames = [f for f in simulate_frames(p.camera, 300, SimConfig(mag_limit=p.mag_limit, centroid_noise_px=1.0,
                                                                   false_stars=2), rng=12)
              if len(f.centroids) == 7][:12]
    searched: list[str] = []
    real = QuadMatcher.search

    def search(self, obs, v, tol_rad):
        searched.append(self.db.path.name)
        return real(self, obs, v, tol_rad)

    monkeypatch.setattr(QuadMatcher, "search", search)
    runs = {}
    for first in (True, False):
        monkeypatch.setattr(pipeline, "SMALL_FRAME_FALLBACK_FIRST", first)
        searched.clear()
        runs[first] = [solve(f.centroids, p.camera, default_set_db, options=opts) for f in frames]
        runs[first, "quad"] = list(searched)
    proven = sum(s.solved for s in runs[True])
    assert proven >= 8
    assert len(runs[True, "quad"]) <= len(frames) - proven < len(runs[False, "quad"])
    for a, b in zip(runs[True], runs[False], strict=True):
        assert (a.solved, [s[:2] for s in a.stars]) == (b.solved, [s[:2] for s in b.stars])


def test_a_4_star_frame_is_not_given_to_quad_and_says_why_on_the_default_database(default_set_db) -> None:
    # seed 000's 1024-px camera: quad needs 5 stars and the triangle fallbacks cannot pass the
    # bound, so nothing runs; seed 002's 4096-px camera can prove 4 stars, so its fallbacks run
    p = PRESETS["seed000"]
    frame = simulate_frames(p.camera, 1, SimConfig(mag_limit=p.mag_limit, centroid_noise_px=1.0), rng=3)[0]
    four = solve(Centroids(frame.centroids.xy[:4], frame.centroids.flux[:4]), p.camera, default_set_db,
                 options=SolveOptions(centroid_sigma_px=1.0))
    assert four.reason is NoSolutionReason.TOO_FEW_STARS and four.methods_tried == ()
    assert "not run: maxangle, pyramid" in four.message
    p = PRESETS["seed002"]
    frame = simulate_frames(p.camera, 1, SimConfig(mag_limit=p.mag_limit, centroid_noise_px=1.0), rng=3)[0]
    four = solve(Centroids(frame.centroids.xy[:4], frame.centroids.flux[:4]), p.camera, default_set_db,
                 options=SolveOptions(centroid_sigma_px=1.0))
    assert "quad" not in four.methods_tried and "maxangle" in four.methods_tried
    assert four.solved or four.reason is not NoSolutionReason.TOO_FEW_STARS


def test_a_3_4_star_frame_runs_the_fallbacks_of_one_member(default_set_db, monkeypatch) -> None:
    """Seed 002's camera on the default set: a 4-star frame that ``sparse``'s fallbacks leave is
    not searched again by ``narrow``'s (SPARSE_FRAME_ONE_MEMBER), as it was without the flag."""
    import service.core.pipeline as pipeline

    camera = PRESETS["seed002"].camera
    four = random_points(camera, 4, rng=7)
    solve(four, camera, default_set_db)  # (a first solve warms the set up: its own solves aside)
    calls: list[tuple[str, tuple[str, ...]]] = []
    identify = pipeline._identify

    def spy(obs, db, methods, *args, **kw):  # type: ignore[no-untyped-def]
        calls.append((db.path.name, tuple(methods)))
        return identify(obs, db, methods, *args, **kw)

    monkeypatch.setattr(pipeline, "_identify", spy)
    fallbacks = lambda: {m for m, methods in calls if "quad" not in methods}  # noqa: E731
    assert not solve(four, camera, default_set_db).solved
    assert fallbacks() == {"sparse"}
    calls.clear()
    monkeypatch.setattr(pipeline, "SPARSE_FRAME_ONE_MEMBER", False)
    assert not solve(four, camera, default_set_db).solved
    assert fallbacks() == {"sparse", "narrow"}
