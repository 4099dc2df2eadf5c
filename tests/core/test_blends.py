"""Close doubles: a blob dominated by one catalogue star is named as that star."""

from __future__ import annotations

import numpy as np

from service.core.blends import dominant_pairs
from service.core.evaluate import score
from service.core.pipeline import SolveOptions, solve
from service.core.presets import PRESETS
from service.core.sim import SimConfig, simulate_frames


def test_dominant_pairs_names_a_blob_with_a_much_fainter_companion() -> None:
    obs = np.array([[100.0, 100.0], [300.0, 300.0]])
    pred = np.array([[100.3, 100.1], [101.2, 100.4], [300.4, 299.8], [301.0, 300.9]])
    mag = np.array([4.0, 6.0, 5.0, 5.5])  # first blob: 2 mag apart; second: 0.5 mag apart
    o, p = dominant_pairs(obs, np.array([0, 1]), pred, mag, np.ones(4, bool), radius_px=2.5)
    assert o.tolist() == [0] and p.tolist() == [0]
    # the bright star already paired elsewhere, or another observed star as near it: no pair
    assert len(dominant_pairs(obs, np.array([0]), pred, mag, np.array([False, True, True, True]), 2.5)[0]) == 0
    crowded = np.array([[100.0, 100.0], [102.0, 100.5], [300.0, 300.0]])
    assert len(dominant_pairs(crowded, np.array([0]), pred, mag, np.ones(4, bool), 2.5)[0]) == 0


def test_dominant_pairs_leaves_a_blob_near_a_resolvable_companion() -> None:
    """A fainter star 3 px from the bright one is a blob of its own on the detector: a blob within
    reach of both may be that star's (the bright one's fallen past the border), so it is not
    named; at 1.9 px the two are one blob and it is."""
    obs = np.array([[100.0, 100.0]])
    for offset, named in ((3.0, False), (1.9, True)):
        pred = np.array([[100.5, 100.0], [100.5 - offset, 100.0]])
        o, _ = dominant_pairs(obs, np.array([0]), pred, np.array([4.0, 6.0]), np.ones(2, bool), radius_px=2.5)
        assert (len(o) == 1) == named, offset


def test_simulated_blob_of_a_close_double_is_named(default_set_db) -> None:
    """Seed 000's camera (30"/px): frame 162 of a seeded set holds HIP 110991 with HIP 110988
    blended into one blob; the verifier left it out (two candidates within its crowding radius),
    it is now named as the dominant star, and no answer of the set names a wrong star."""
    p = PRESETS["seed000"]
    frames = simulate_frames(p.camera, 400, SimConfig(mag_limit=p.mag_limit, centroid_noise_px=0.5, false_stars=2),
                             rng=9)
    f = frames[162]
    assert f.blends[4] == (110991, 110988)
    sol = solve(f.centroids, p.camera, default_set_db, options=SolveOptions(centroid_sigma_px=0.5))
    named = {s.centroid: s.hip for s in sol.stars}
    assert named.get(4) == 110991
    for f in frames[150:250]:
        sol = solve(f.centroids, p.camera, default_set_db, options=SolveOptions(centroid_sigma_px=0.5))
        s = score(sol, f.quaternion, f.hip.tolist(), blends=f.blends)
        assert not sol.solved or (s.correct and s.wrong_stars == 0)
