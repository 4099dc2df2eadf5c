"""The answer's star list (service.core.types.MatchedStars): columns made tuples when read."""

import dataclasses
import pickle

import numpy as np
import pytest

from service.core.types import (
    MatchedStars,
    NoSolutionReason,
    Solution,
    SolveStatus,
    StarMatch,
    refused_solution_of,
    solved_solution_of,
)


def _columns() -> tuple:
    return (np.array([4, 0, 7]), np.array([32349, 30438, 24436]), np.array([101.28, 95.98, 78.63]),
            np.array([-16.71, -52.69, -8.2]), np.array([-1.46, -0.74, 0.13]), np.array([0.5, 1.25, 2.0]),
            [0, 0, 0])


def test_reads_as_the_tuple_of_star_matches() -> None:
    stars = MatchedStars(*_columns())
    want = tuple(StarMatch(*row) for row in zip(*[c.tolist() if isinstance(c, np.ndarray) else c for c in _columns()]))
    assert len(stars) == 3
    assert stars == want and want == stars and stars == MatchedStars(*_columns())
    assert stars != want[:2]
    assert stars[1].hip == 30438 and isinstance(stars[1].hip, int) and isinstance(stars[1].ra_deg, float)
    assert stars[1:] == want[1:]
    assert [s.centroid for s in stars] == [4, 0, 7]
    assert hash(stars) == hash(want)
    assert repr(stars) == repr(want)


def test_a_solution_with_it_compares_and_pickles_as_with_the_tuple() -> None:
    stars = MatchedStars(*_columns())
    sol = Solution(SolveStatus.SOLVED, "quad", quaternion=(1.0, 0.0, 0.0, 0.0), stars=stars)
    plain = Solution(SolveStatus.SOLVED, "quad", quaternion=(1.0, 0.0, 0.0, 0.0), stars=tuple(stars))
    assert sol == plain
    back = pickle.loads(pickle.dumps(sol))
    assert back == plain and isinstance(back.stars, tuple)
    assert sol.to_dict()["stars"][2] == {"centroid": 7, "camera": 0, "hip": 24436, "ra_deg": 78.63,
                                         "dec_deg": -8.2, "mag": 0.13, "residual_arcsec": 2.0}


def test_the_wire_format_is_the_same_before_and_after_the_tuples_are_made() -> None:
    stars = MatchedStars(*_columns())
    sol = Solution(SolveStatus.SOLVED, "quad", stars=stars)
    before = sol.to_dict()["stars"]
    assert len(stars[:]) == 3  # makes the tuples
    assert sol.to_dict()["stars"] == before == Solution(SolveStatus.SOLVED, "quad", stars=tuple(stars)).to_dict()["stars"]
    assert before[0] == {"centroid": 4, "camera": 0, "hip": 32349, "ra_deg": 101.28, "dec_deg": -16.71, "mag": -1.46,
                         "residual_arcsec": 0.5}


def test_a_column_reads_the_same_before_and_after_the_tuples_are_made() -> None:
    stars = MatchedStars(*_columns())
    before = {name: stars.column(name) for name in StarMatch._fields}
    assert before["hip"] == [32349, 30438, 24436] and isinstance(before["hip"][0], int)
    assert before["camera"] == [0, 0, 0]
    assert len(stars[:]) == 3  # makes the tuples
    assert {name: stars.column(name) for name in StarMatch._fields} == before


def test_the_slot_made_solution_is_the_dataclass_s_own() -> None:
    """``solved_solution_of`` sets every field (a field added to Solution and forgotten there
    would be unset: comparing would raise), equal to the dataclass's ``__init__``, still frozen."""
    stars = MatchedStars([3, 1], [11767, 424], [37.95, 2.5], [89.26, 1.0], [2.0, 4.1], [0.5, 1.5], [0, 0])
    args = dict(quaternion=(0.5, 0.5, 0.5, 0.5), ra_deg=37.9, dec_deg=89.2, roll_deg=12.0, stars=stars,
                rms_arcsec=1.2, false_match_probability=1e-12, attitude_sigma_arcsec=(1.0, 2.0, 3.0))
    fast = solved_solution_of("quad", **args)
    slow = Solution(SolveStatus.SOLVED, "quad", **args)
    for f in dataclasses.fields(Solution):
        assert getattr(fast, f.name) == getattr(slow, f.name), f.name
    assert fast == slow and fast.solved
    assert fast.timings_ms is not solved_solution_of("quad", **args).timings_ms  # a dict of its own
    with pytest.raises(dataclasses.FrozenInstanceError):
        fast.method = "other"  # type: ignore[misc]
    assert fast.to_dict() == slow.to_dict()


def test_the_slot_made_refusal_is_the_dataclass_s_own() -> None:
    """``refused_solution_of`` sets every field, equal to the dataclass's ``__init__``, still frozen."""
    args = dict(reason=NoSolutionReason.NOT_PROVEN, methods_tried=("quad", "maxangle"),
                message="12 candidate attitude(s) checked, none proven", timings_ms={"total": 0.05})
    fast = refused_solution_of("maxangle", **args)
    slow = Solution(SolveStatus.NO_SOLUTION, "maxangle", **args)
    for f in dataclasses.fields(Solution):
        assert getattr(fast, f.name) == getattr(slow, f.name), f.name
    assert fast == slow and not fast.solved
    with pytest.raises(dataclasses.FrozenInstanceError):
        fast.method = "other"  # type: ignore[misc]
    assert fast.to_dict() == slow.to_dict()
