"""The compiled answer checks (one camera) give what the pipeline's Python checks give, and an
answer whose fit left stars out is paired again from it."""

from __future__ import annotations

import numpy as np
import pytest

from service.core.answer import compiled_checks, recheck, repaired
from service.core.finish import checked_pairs
from service.core.navdb import NavDatabase
from service.core.pipeline import _observation
from service.core.sim import SimConfig, simulate_frames
from service.core.verify import Verified, Verifier
from tests.conftest import SEED000_CAMERA


def test_compiled_checks_give_the_python_answer(seed000_db: NavDatabase) -> None:
    # stars deeper than the database (faint neighbours), close doubles, false stars and magnitude
    # noise exercise the blend and plausibility checks; each answer starts from the true pairs of
    # the four brightest real stars, proven by the verifier as the pipeline would
    config = SimConfig(mag_limit=7.0, centroid_noise_px=0.7, false_stars=4, mag_noise=0.3)
    frames = simulate_frames(SEED000_CAMERA, 60, config, rng=8)
    row_of = {int(h): i for i, h in enumerate(np.asarray(seed000_db.stars.hip))}
    changed = compared = 0
    for frame in frames:
        obs = _observation([(frame.centroids, SEED000_CAMERA, None)], [np.eye(3)])  # brightest first
        hip = frame.hip[obs.index]
        known = [(i, row_of[int(h)]) for i, h in enumerate(hip) if h >= 0 and int(h) in row_of][:4]
        if len(known) < 4:
            continue
        v = Verifier(seed000_db, obs, match_radius_px=3.0).check(*map(np.array, zip(*known, strict=True)))
        if v is None:
            continue
        if compared % 2:  # every other answer: its brightest pair re-paired with a faint star (by position
            cat = v.cat.copy()  # alone a false detection can pair so; the field's own stars are all taken)
            mag = np.asarray(seed000_db.stars.mag)
            cat[np.argmin(mag[v.cat])] = np.setdiff1d(np.flatnonzero(mag >= mag.max() - 0.05), v.cat)[0]
            v = Verified(v.obs, cat, v.matrix, v.false_prob, v.n_trials)
        python, moved = checked_pairs(obs, seed000_db, v, 3.0)
        o, c, moved_c = compiled_checks(obs, seed000_db, v.obs, v.cat, v.matrix, 3.0)
        assert moved_c == moved
        assert sorted(zip(o.tolist(), c.tolist())) == sorted(zip(python.obs.tolist(), python.cat.tolist()))
        compared += 1
        changed += moved
    assert compared >= 40 and changed >= 3  # the checks did change some answers


def test_compiled_recheck_gives_the_verifiers_answer(seed000_db: NavDatabase) -> None:
    """deeper.refine_deeper's compiled check agrees with Verifier.check: pairs, bound and attitude."""
    config = SimConfig(mag_limit=6.5, centroid_noise_px=1.0, false_stars=3)
    frames = simulate_frames(SEED000_CAMERA, 30, config, rng=4)
    row_of = {int(h): i for i, h in enumerate(np.asarray(seed000_db.stars.hip))}
    proven = refused = 0
    for n, frame in enumerate(frames):
        obs = _observation([(frame.centroids, SEED000_CAMERA, None)], [np.eye(3)])
        hip = frame.hip[obs.index]
        known = [(i, row_of[int(h)]) for i, h in enumerate(hip) if h >= 0 and int(h) in row_of][:5]
        if len(known) < 4:
            continue
        o, c = (np.array(x) for x in zip(*known, strict=True))
        if n % 3 == 0:  # a wrong hypothesis: two catalogue stars swapped
            c[[0, 1]] = c[[1, 0]]
        v = Verifier(seed000_db, obs, match_radius_px=3.0, max_false_prob=1.0, strong_false_prob=1.0)
        python = v.check(o, c, n_trials=50)
        ok, m_obs, m_cat, r, prob = recheck(obs, seed000_db, o, c, 50, 3.0)
        assert ok == (python is not None)
        if ok:
            assert sorted(zip(m_obs.tolist(), m_cat.tolist())) == sorted(zip(python.obs.tolist(), python.cat.tolist()))
            assert prob == pytest.approx(python.false_prob, rel=1e-8, abs=1e-300)
            np.testing.assert_allclose(r, python.matrix, atol=1e-9)
        proven += ok
        refused += not ok
    assert proven >= 10 and refused >= 3


def test_repaired_pairs_again_the_stars_a_pulled_fit_left_out(seed000_db: NavDatabase) -> None:
    """From half an answer's pairs under an attitude pulled 3 px at the image's corners (a roll
    about the boresight), the pairing is grown again past the half, every star right, to 90% or
    more of the checked answer's stars on average; an answer that pairs every star it can is left
    as it is (None)."""
    config = SimConfig(mag_limit=6.5, centroid_noise_px=0.5, false_stars=2)
    frames = simulate_frames(SEED000_CAMERA, 20, config, rng=11)
    corner_px = float(np.hypot(SEED000_CAMERA.width, SEED000_CAMERA.height)) / 2
    a = 3.0 / corner_px  # radians: 3 px at the corners
    roll = np.array([[np.cos(a), -np.sin(a), 0.0], [np.sin(a), np.cos(a), 0.0], [0.0, 0.0, 1.0]])
    row_of = {int(h): i for i, h in enumerate(np.asarray(seed000_db.stars.hip))}
    kept: list[float] = []
    for frame in frames:
        obs = _observation([(frame.centroids, SEED000_CAMERA, None)], [np.eye(3)])
        hip = frame.hip[obs.index]
        known = [(i, row_of[int(h)]) for i, h in enumerate(hip) if h >= 0 and int(h) in row_of][:4]
        if len(known) < 4:
            continue
        v = Verifier(seed000_db, obs, match_radius_px=3.0).check(*map(np.array, zip(*known, strict=True)))
        if v is None or len(v.obs) < 10:
            continue
        assert repaired(obs, seed000_db, v.obs, v.cat, v.matrix, 3.0) is None
        half = len(v.obs) // 2
        again = repaired(obs, seed000_db, v.obs[:half], v.cat[:half], roll @ v.matrix, 3.0)
        assert again is not None
        o, c = again
        checked, _, _ = compiled_checks(obs, seed000_db, v.obs, v.cat, v.matrix, 3.0)  # what the answer keeps
        assert len(o) > half
        assert all(int(seed000_db.stars.hip[ci]) == int(hip[oi]) for oi, ci in zip(o.tolist(), c.tolist()))
        kept.append(len(o) / len(checked))
    assert len(kept) >= 5 and np.mean(kept) >= 0.9
