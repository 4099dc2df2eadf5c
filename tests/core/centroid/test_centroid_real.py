"""Detection on the real star-camera images of ../shared/data/real (skipped when absent).

``matches.json`` lists, per image, Hipparcos stars with centroids measured by cedar-solve's
extractor (pixel centres at +0.5 there; we subtract 0.5). Found = a detection within 2 px.
Set ``SKYFIX_REAL_DATA`` to the directory holding ``matches.json`` to use another copy.
"""

from __future__ import annotations

import json
import os
from functools import lru_cache
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from scipy.spatial import cKDTree

from service.core.centroid import decode_image, extract

pytestmark = pytest.mark.real


def real_data_dir() -> Path:
    env = os.environ.get("SKYFIX_REAL_DATA")
    if env:
        return Path(env)
    return Path(__file__).resolve().parents[3] / ".." / "shared" / "data" / "real"


@lru_cache(maxsize=1)
def load_matches() -> dict[str, Any]:
    path = real_data_dir() / "matches.json"
    if not path.is_file():
        return {}
    images: dict[str, Any] = json.loads(path.read_text())["images"]
    return images


def image_names() -> list[str]:
    return sorted(load_matches()) or ["<no real data>"]


# Least fraction of the listed stars each group's images must recover (measured: tetra3 1.00
# each; cedar-solve >= 0.86 (orion_trees, branches over stars); oresat >= 0.98;
# openstartracker >= 0.67 per image, 0.89 over the group). See docs/centroiding.md.
MIN_FRACTION = {"tetra3": 0.95, "cedar-solve": 0.8, "oresat": 0.95, "openstartracker": 0.6}


def found_distances(name: str, **kwargs: Any) -> tuple[np.ndarray, int]:
    entry = load_matches()[name]
    img = decode_image((real_data_dir() / name).read_bytes())
    det = extract(img, **kwargs)
    truth = np.array([[m["x"] - 0.5, m["y"] - 0.5] for m in entry["matches"]])
    if len(det) == 0:
        return np.full(len(truth), np.inf), 0
    dist, _ = cKDTree(det.centroids.xy).query(truth)
    return dist, len(det)


@pytest.mark.parametrize("name", image_names())
def test_listed_stars_are_found(name: str) -> None:
    if not load_matches():
        pytest.skip(f"no real data at {real_data_dir()}")
    dist, n_det = found_distances(name, max_stars=None)
    found = dist <= 2.0
    group = name.split("/")[0]
    assert found.mean() >= MIN_FRACTION[group], f"{name}: {found.sum()}/{len(dist)} found, {n_det} detections"
    assert np.median(dist[found]) < 0.5  # agrees with cedar-solve's centroids


def test_faint_openstartracker_stars_rank_among_the_brightest() -> None:
    """The faint, noisy UB Nanosat frames: plain thresholding finds mostly noise there; the
    matched filter and windowed fluxes put most catalogue stars among the 30 brightest."""
    names = [n for n in load_matches() if n.startswith("openstartracker/")]
    if not names:
        pytest.skip(f"no real data at {real_data_dir()}")
    found = total = 0
    for name in names:
        dist, _ = found_distances(name, max_stars=30)
        found += int((dist <= 2.0).sum())
        total += len(dist)
    assert found / total >= 0.7, f"{found}/{total}"  # measured 69/92


def test_tree_branches_do_not_outrank_the_stars() -> None:
    """cedar-solve/tree.jpg: lit foliage covers a third of the frame. Without the point-source
    test 3 of the 8 brightest detections are listed stars (of 150 detections); with it 4 (of 90),
    and the rest of the eight includes one more catalogue star that matches.json leaves out."""
    name = "cedar-solve/tree.jpg"
    if name not in load_matches():
        pytest.skip(f"no real data at {real_data_dir()}")
    img = decode_image((real_data_dir() / name).read_bytes())
    truth = np.array([[m["x"] - 0.5, m["y"] - 0.5] for m in load_matches()[name]["matches"]])
    det = extract(img)
    dist, rank = cKDTree(det.centroids.xy).query(truth)
    assert int(((dist <= 2.0) & (rank < 8)).sum()) >= 4
    assert len(det) <= 100
