"""Scoring against truth (service.core.evaluate): the attitude error and wrong stars."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from service.core.attitude import ARCSEC_PER_RAD
from service.core.evaluate import attitude_error, correct_against_record, score
from service.core.types import MatchedStars, Solution, SolveStatus, StarMatch


def _q(rot: Rotation) -> list[float]:
    x, y, z, w = rot.as_quat()  # scipy: scalar last
    return [w, x, y, z]


@pytest.mark.parametrize(("axis", "arcsec"), [("x", 0.01), ("y", 7.5), ("x", 3600.0), ("z", 12.0), ("z", 500.0)])
def test_attitude_error_splits_cross_boresight_from_roll(axis: str, arcsec: float) -> None:
    """A rotation about a camera axis: about +z (the boresight) it is all roll, about x or y
    all cross-boresight, to 1e-6" even for hundredths of an arcsecond."""
    rng = np.random.default_rng(3)
    truth = Rotation.random(random_state=rng)  # ICRS -> camera
    err = Rotation.from_euler(axis, arcsec / ARCSEC_PER_RAD)
    cross, roll = attitude_error(_q(err * truth), _q(truth))
    want_cross, want_roll = (0.0, arcsec) if axis == "z" else (arcsec, 0.0)
    assert cross == pytest.approx(want_cross, abs=1e-6)
    assert roll == pytest.approx(want_roll, abs=1e-6)


def test_attitude_error_is_blind_to_the_quaternion_sign_and_scale() -> None:
    rng = np.random.default_rng(4)
    for _ in range(200):
        truth, est = Rotation.random(random_state=rng), Rotation.random(random_state=rng)
        q_est = np.array(_q(est)) * rng.choice([-1.0, 1.0]) * rng.uniform(0.5, 2.0)
        cross, roll = attitude_error(q_est, _q(truth))
        e = (est * truth.inv()).as_matrix()  # independent: scipy's matrices
        assert cross == pytest.approx(np.degrees(np.arccos(np.clip(e[2, 2], -1, 1))) * 3600, abs=1e-3)
        assert roll == pytest.approx(abs(np.degrees(np.arctan2(e[1, 0] - e[0, 1], e[0, 0] + e[1, 1]))) * 3600,
                                     abs=1e-3)


def _solution(hips: list[int], cameras: list[int] | None = None, *, as_columns: bool = True) -> Solution:
    n = len(hips)
    cols = (list(range(n)), hips, [0.0] * n, [0.0] * n, [5.0] * n, [1.0] * n, cameras or [0] * n)
    stars = MatchedStars(*cols) if as_columns else tuple(StarMatch(*row) for row in zip(*cols))
    return Solution(SolveStatus.SOLVED, "quad", quaternion=(1.0, 0.0, 0.0, 0.0), stars=stars)


@pytest.mark.parametrize("as_columns", [True, False])
def test_score_counts_wrong_stars_and_accepts_a_blend(as_columns: bool) -> None:
    truth_q = [1.0, 0.0, 0.0, 0.0]
    assert score(_solution([10, 11, 12], as_columns=as_columns), truth_q, [10, 11, 12]).correct
    bad = score(_solution([10, 99, 12], as_columns=as_columns), truth_q, [10, 11, 12])
    assert not bad.correct and bad.wrong_stars == 1
    false_star = score(_solution([10, 11, 12], as_columns=as_columns), truth_q, [10, None, 12])
    assert false_star.wrong_stars == 1, "a false star named after any star is wrong"
    blend = score(_solution([10, 99, 12], as_columns=as_columns), truth_q, [10, 11, 12], blends={1: [11, 99]})
    assert blend.correct


def test_correct_against_record_splits_a_rigs_truth_by_camera() -> None:
    # each camera's centroids are numbered from 0 within it
    sol = Solution(SolveStatus.SOLVED, "multifov", quaternion=(1.0, 0.0, 0.0, 0.0),
                   stars=MatchedStars([0, 1, 0, 1], [10, 11, 20, 21], *[[0.0] * 4] * 4, [0, 0, 1, 1]))
    rec = {"cameras": [{"centroids": [[1, 2], [3, 4]]}, {"centroids": [[5, 6], [7, 8]]}],
           "truth": {"quaternion": [1, 0, 0, 0], "hip": [10, 11, 20, 21]}}
    assert correct_against_record(rec, sol) is True
    rec["truth"]["hip"] = [10, 11, 21, 20]
    assert correct_against_record(rec, sol) is False
    assert correct_against_record({"truth": {}}, sol) is None
