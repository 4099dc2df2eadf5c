"""dmv's compiled vote (:mod:`service.core.methods._dmv_vote`): a candidate whose catalogue
neighbours are the observed ones turned about the star wins every vote under the right
alignment; neighbours out of reach are left out; an unrelated candidate gathers no vote."""

from __future__ import annotations

import math

import numpy as np

from service.core.methods._dmv_vote import vote


def _gaps(angles: np.ndarray) -> np.ndarray:
    """Sorted position angles as the table stores them: each one's CCW gap to the next."""
    return np.mod(np.roll(angles, -1) - angles, 2 * math.pi)


def test_the_turned_pattern_gets_every_vote_and_a_stranger_none() -> None:
    rng = np.random.default_rng(4)
    m = 6
    d_obs = np.sort(rng.uniform(0.01, 0.05, m))[::-1].copy()
    theta = np.sort(rng.uniform(0, 2 * math.pi, m))
    turn = 1.1
    cat_theta = np.mod(theta - turn, 2 * math.pi)
    order = np.argsort(cat_theta)
    own_dist = np.concatenate([d_obs[order], [0.2]])  # and one neighbour out of reach
    own_phi = np.concatenate([_gaps(cat_theta[order]), [0.3]])
    stranger_dist = rng.uniform(0.011, 0.049, 5)
    stranger_phi = _gaps(np.sort(rng.uniform(0, 2 * math.pi, 5)))
    dist = np.concatenate([stranger_dist, own_dist])
    phi = np.concatenate([stranger_phi, own_phi])
    lo = np.array([0, 5], np.int64)
    cnt = np.array([5, m + 1], np.int64)
    starts = np.argsort(-d_obs, kind="stable")[:4].astype(np.int64)
    flat, owner, oi, fj, a_ok, k_ok, f_ok, scores = vote(d_obs, theta, starts, lo, cnt, dist, phi, 0.1, 1e-5)
    assert 5 + m not in flat.tolist()  # the neighbour at 0.2 rad is beyond the reach
    best = int(np.argmax(scores))
    assert owner[fj[best]] == 1 and scores[best] == m
    assert all(scores[a] <= 1 for a in range(len(oi)) if owner[fj[a]] == 0)
    mine = a_ok == best
    assert sorted(k_ok[mine].tolist()) == list(range(m))
    assert np.allclose(dist[flat[f_ok[mine]]], d_obs[k_ok[mine]])
