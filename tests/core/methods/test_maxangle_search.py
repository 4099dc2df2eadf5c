"""maxangle's compiled search (service/core/methods/maxangle_search.py) does what the Python loop
does: the same answer, the same marginal answers kept, the same hypotheses counted."""

from __future__ import annotations

import math

import numpy as np
import pytest

from service.core.methods import get_matcher, maxangle
from service.core.methods.base import SolveContext
from service.core.methods.maxangle_search import TRIANGLES_PER_CALL, calls, chunk_bounds
from service.core.pipeline import _observation
from service.core.presets import PRESETS
from service.core.sim import SimConfig, simulate_frames
from service.core.verify import Verifier
from tests.conftest import SEED000_CAMERA
from tests.core.methods.test_maxangle import paper_layout_db  # noqa: F401 (a fixture)


def test_chunks_grow_to_16_and_calls_hold_whole_chunks() -> None:
    assert np.diff(chunk_bounds(50)).tolist() == [2, 4, 8, 16, 16, 4]
    assert chunk_bounds(0).tolist() == [0] and chunk_bounds(1).tolist() == [0, 1]
    for total in (1, 7, 30, 64, 65, 400):
        bounds = chunk_bounds(total)
        groups = calls(bounds)
        assert groups[0][0] == 0 and groups[-1][1] == len(bounds) - 1
        assert all(a[1] == b[0] for a, b in zip(groups, groups[1:], strict=False))  # contiguous, in order
        assert all(bounds[c1] - bounds[c0] <= TRIANGLES_PER_CALL or c1 == c0 + 1 for c0, c1 in groups)
    assert len(calls(chunk_bounds(60))) == 1  # a 7-star frame's triangles: one call


def _identify(monkeypatch, db, frame, camera, noise, compiled, trials=0, trial_limit=None):
    monkeypatch.setattr(maxangle, "COMPILED_SEARCH", compiled)
    obs = _observation([(frame.centroids, camera, None)], [np.eye(3)])
    radius = max(2.5, 3.0 * noise)
    ver = Verifier(db, obs, match_radius_px=radius, trials=trials, trial_limit=trial_limit)
    tol = (3.0 * math.sqrt(2.0) * noise + 0.5) * obs.pixel_scale_rad
    found = get_matcher(db, "maxangle").identify(SolveContext(obs, ver, tol, math.inf, 12))
    return found, ver


def _same(a, b) -> None:
    assert (a is None) == (b is None)
    if a is not None:
        assert a.obs.tolist() == b.obs.tolist() and a.cat.tolist() == b.cat.tolist()
        np.testing.assert_allclose(a.matrix, b.matrix, atol=1e-12)
        assert a.false_prob == pytest.approx(b.false_prob, rel=1e-9, abs=1e-300) and a.n_trials == b.n_trials


def _compare(monkeypatch, db, camera, frames, noise, **kw) -> dict[str, int]:
    seen = {"found": 0, "marginal": 0, "none": 0}
    for frame in frames:
        fast, v_fast = _identify(monkeypatch, db, frame, camera, noise, True, **kw)
        slow, v_slow = _identify(monkeypatch, db, frame, camera, noise, False, **kw)
        _same(fast, slow)
        assert (v_fast.trials, v_fast.patterns, v_fast._first_marginal_at) == \
            (v_slow.trials, v_slow.patterns, v_slow._first_marginal_at)
        assert len(v_fast.marginal) == len(v_slow.marginal)
        for a, b in zip(v_fast.marginal, v_slow.marginal, strict=True):
            _same(a, b)
        seen["found" if fast else "marginal" if v_fast.marginal else "none"] += 1
    return seen


def test_the_compiled_search_counts_and_answers_as_the_python_loop_on_seed002(monkeypatch, default_set_db) -> None:
    # seed 002's 4096-px camera on the default set's first member: 5-9 stars with 2 false are
    # proven strongly, marginally, or not at all
    p = PRESETS["seed002"]
    member = default_set_db.members["sparse"]
    frames = [f for f in simulate_frames(p.camera, 200, SimConfig(mag_limit=p.mag_limit, centroid_noise_px=1.0,
                                                                   false_stars=2), rng=41)
              if 5 <= len(f.centroids) <= 9][:60]
    seen = _compare(monkeypatch, member, p.camera, frames, 1.0)
    assert seen["found"] >= 10 and seen["marginal"] >= 3 and seen["none"] >= 10, seen


@pytest.mark.parametrize("trial_limit", [1, 5, 40])
def test_the_compiled_search_stops_at_the_trial_limit_as_the_python_loop(monkeypatch, default_set_db,
                                                                          trial_limit) -> None:
    p = PRESETS["seed002"]
    member = default_set_db.members["sparse"]
    frames = [f for f in simulate_frames(p.camera, 120, SimConfig(mag_limit=p.mag_limit, centroid_noise_px=2.0,
                                                                   false_stars=3), rng=42)
              if 5 <= len(f.centroids) <= 12][:25]
    _compare(monkeypatch, member, p.camera, frames, 2.0, trials=3, trial_limit=3 + trial_limit)


@pytest.mark.parametrize("layout", ["cells", "paper"])
def test_the_compiled_search_answers_as_the_python_loop_in_both_layouts(monkeypatch, request, layout) -> None:
    # seed 000's camera: many stars, many chunks and calls (the clock is checked between them)
    db = request.getfixturevalue("seed000_db" if layout == "cells" else "paper_layout_db")
    frames = simulate_frames(SEED000_CAMERA, 30, SimConfig(mag_limit=6.5, centroid_noise_px=2.0, false_stars=5),
                             rng=43)
    seen = _compare(monkeypatch, db, SEED000_CAMERA, frames, 2.0)
    assert seen["found"] >= 5 and seen["marginal"] + seen["none"] >= 3, seen
