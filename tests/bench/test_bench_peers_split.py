"""``bench_peers``' split of the same frames by outcome (skyfix against each peer)."""

from __future__ import annotations

from typing import Any

import pytest

from bench.bench_peers import per_frame, run_frames, split_by_peer, split_table
from bench.common import Answer, Judged


def _j(solved: bool, ms: float, wrong: bool = False) -> Judged:
    return Judged(solved, wrong, wrong, False, 1.0 if solved else None, 1.0 if solved else None, ms, 4 if solved else 0)


def test_split_counts_frames_both_solve_and_frames_only_skyfix_solves() -> None:
    judged = {
        "skyfix auto": [_j(True, 1.0), _j(True, 3.0), _j(True, 10.0), _j(False, 5.0), _j(True, 2.0, wrong=True)],
        "tetra3rs": [_j(True, 2.0), _j(True, 4.0), _j(False, 0.1), _j(True, 1.0), _j(True, 1.0)],
    }
    got = split_by_peer(judged)["tetra3rs"]
    assert got["both"] == 2 and got["only_skyfix"] == 1  # a wrong answer is no solve of skyfix's
    assert got["both_skyfix_ms_mean"] == pytest.approx(2.0) and got["both_peer_ms_mean"] == pytest.approx(3.0)
    assert got["both_skyfix_ms_median"] == pytest.approx(2.0) and got["both_peer_ms_median"] == pytest.approx(3.0)
    assert got["only_skyfix_ms_mean"] == pytest.approx(10.0) and got["only_skyfix_peer_ms_mean"] == pytest.approx(0.1)
    table = "\n".join(split_table([{"value": 1.0, "split": {"tetra3rs": got}}], ["skyfix auto"]))
    assert "| 1 | 2 / 2.00 vs 3.00 / 2.00 vs 3.00; 1 / 10.00 |" in table


def test_no_skyfix_entry_no_split() -> None:
    assert split_by_peer({"tetra3rs": [_j(True, 1.0)]}) == {}


class _Recorder:
    """A solver that records the order it is called in (the schedule is under test, not a solver)."""

    def __init__(self, name: str, log: list[tuple[str, int]]) -> None:
        self.name, self.log = name, log

    def solve(self, centroids: Any, camera: Any, noise_px: float) -> Answer:
        self.log.append((self.name, centroids))
        return Answer(False, 0.1, status="no_solution")


@pytest.mark.parametrize("order", ["rotating", "blocked"])
def test_run_frames_orders(order: str) -> None:
    log: list[tuple[str, int]] = []
    solvers = [_Recorder("a", log), _Recorder("b", log)]
    frames = [(i, None, None, None, None) for i in range(3)]
    judged = run_frames(solvers, frames, 0.5, order)
    assert {n: len(js) for n, js in judged.items()} == {"a": 3, "b": 3}
    if order == "blocked":  # each solver over every frame, one after the other
        assert log == [("a", 0), ("a", 1), ("a", 2), ("b", 0), ("b", 1), ("b", 2)]
    else:  # every solver on each frame, the first one rotating
        assert log == [("a", 0), ("b", 0), ("b", 1), ("a", 1), ("a", 2), ("b", 2)]


def test_run_frames_refuses_an_unknown_order() -> None:
    with pytest.raises(ValueError, match="order"):
        run_frames([], [], 0.5, "shuffled")


def test_per_frame_keeps_every_frame_in_order() -> None:
    judged = {"skyfix auto": [_j(True, 1.23456), _j(False, 0.5), _j(True, 2.0, wrong=True)],
              "tetra3rs": [_j(False, 0.01), _j(True, 0.2), _j(True, 0.3)]}
    got = per_frame(judged)
    assert got["skyfix auto"] == {"ms": [1.2346, 0.5, 2.0], "outcome": ["right", "none", "wrong"]}
    assert got["tetra3rs"]["outcome"] == ["none", "right", "right"]
