"""maxangle's compiled query finds exactly the records a scan of the whole table finds, in both
layouts (service/core/methods/maxangle_index.py)."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from service.core.geometry import pairwise_angles
from service.core.methods import get_matcher
from service.core.methods.maxangle_index import THETA_LO, THETA_SPAN
from service.core.navdb import NavDatabase, build_database, open_database
from service.core.pipeline import _observation
from service.core.screen import triple_product
from service.core.sim import SimConfig, simulate_frames
from tests.conftest import SEED000_CAMERA, seed000_config


def _records(m):
    """Every record's ``b, c, theta`` (float64, as the query reads them) and, in the paper
    layout, its theta block."""
    key = np.asarray(m.key)
    c = np.asarray(m.c, np.float64)
    if m.layout == "cells":
        cell = np.floor(key)
        return np.asarray(m.b, np.float64), c, THETA_LO + (key - cell) * THETA_SPAN, None
    block = np.floor(key).astype(np.int64)
    return (key - block) * m.b_scale, c, np.asarray(m.theta, np.float64), block


def _brute_force(m, sides, theta, tol, eps, labels, obs_vec, cap):
    b_rec, c, th, block = _records(m)
    a_rec = np.sqrt(np.maximum(b_rec**2 + c**2 - 2 * b_rec * c * np.cos(th), 0.0))
    vec = np.asarray(m.vec)
    found = []
    for t in range(len(theta)):
        ok = ((np.abs(c - sides[t, 2]) <= eps) & (np.abs(th - theta[t]) <= tol[t])
              & (np.abs(a_rec - sides[t, 0]) <= eps))
        if block is None:
            ok &= np.abs(b_rec - sides[t, 1]) <= eps
        else:  # the paper's blocks covering theta +- tol, and b's slice of the key, as the query reads them
            lo = min(max(int(m.n_blocks * (theta[t] - tol[t] - THETA_LO) / THETA_SPAN), 0), m.n_blocks - 1)
            hi = min(max(int(m.n_blocks * (theta[t] + tol[t] - THETA_LO) / THETA_SPAN), 0), m.n_blocks - 1)
            key = np.asarray(m.key)
            ok &= ((block >= lo) & (block <= hi) & (key >= block + (sides[t, 1] - eps) / m.b_scale)
                   & (key <= block + (sides[t, 1] + eps) / m.b_scale))
        rows = np.flatnonzero(ok)
        h_obs = triple_product(obs_vec[labels[t, 0]], obs_vec[labels[t, 1]], obs_vec[labels[t, 2]]) > 0
        ids = np.asarray(m.ids)[rows]
        h_cat = np.einsum("ij,ij->i", vec[ids[:, 0]], np.cross(vec[ids[:, 1]], vec[ids[:, 2]])) > 0
        rows = rows[h_cat == h_obs]
        if cap and len(rows) > cap:
            continue
        found += [(int(r), t) for r in rows]
    return sorted(found)


@pytest.fixture(scope="module")
def paper_layout_db(tmp_path_factory: pytest.TempPathFactory) -> NavDatabase:
    """Seed 000's camera with the paper's layout (theta blocks), to V 6: a smaller table."""
    config = replace(seed000_config(), mag_limit=6.0, methods=("maxangle",),
                     method_params={"maxangle": {"layout": "paper"}})
    path = tmp_path_factory.mktemp("db") / "paper"
    build_database(path, config)
    return open_database(path)


@pytest.mark.parametrize("layout", ["cells", "paper"])
def test_query_equals_a_scan_of_the_whole_table(layout: str, request: pytest.FixtureRequest) -> None:
    db = request.getfixturevalue("seed000_db" if layout == "cells" else "paper_layout_db")
    m = get_matcher(db, "maxangle")
    assert m.layout == layout
    frames = simulate_frames(SEED000_CAMERA, 4, SimConfig(mag_limit=6.5, centroid_noise_px=1.0, false_stars=2), rng=2)
    checked = 0
    for frame in frames:
        obs = _observation([(frame.centroids, SEED000_CAMERA, None)], [np.eye(3)])
        v = obs.vec[:8]
        eps = (3 * math.sqrt(2) + 0.5) * obs.pixel_scale_rad
        labels, sides, theta, tol = m.observed_triangles(pairwise_angles(v), eps)
        labels, sides, theta, tol = labels[:12], sides[:12], theta[:12], tol[:12]
        for cap in (0, 3):
            rows, which = m.query_many(sides, theta, tol, eps, labels, v, cap)
            got = sorted(zip(rows.tolist(), which.tolist(), strict=True))
            assert got == _brute_force(m, sides, theta, tol, eps, labels, v, cap)
            checked += len(got)
    assert checked > 0
