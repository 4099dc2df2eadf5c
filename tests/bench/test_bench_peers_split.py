"""``bench_peers``' split of the same frames by outcome (skyfix against each peer)."""

from __future__ import annotations

import pytest

from bench.bench_peers import split_by_peer, split_table
from bench.common import Judged


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
