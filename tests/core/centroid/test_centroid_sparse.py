"""Sparse mask pixels and labelling agree with OpenCV's full-frame versions."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from service.core.centroid import sparse
from service.core.centroid.background import tile_statistics
from service.core.centroid.sparse import label_pixels, mask_pixels, threshold_pixels


def same_partition(a: np.ndarray, b: np.ndarray) -> bool:
    """Two labelings of the same pixels describe the same components."""
    pairs = np.unique(np.stack([a, b]), axis=1)
    return len(np.unique(pairs[0])) == len(np.unique(pairs[1])) == pairs.shape[1]


@pytest.mark.parametrize("shape", [(1, 1), (3, 5), (17, 13), (64, 64), (101, 37)])
@pytest.mark.parametrize("density", [0.0, 0.05, 0.3, 0.7])
def test_labels_match_opencv(shape: tuple[int, int], density: float) -> None:
    rng = np.random.default_rng(hash((shape, density)) % 2**32)
    mask = np.where(rng.random(shape) < density, 255, 0).astype(np.uint8)
    lin = mask_pixels(mask)
    np.testing.assert_array_equal(lin, np.flatnonzero(mask))
    n, labels = label_pixels(lin, shape[1])
    n_cv, cv_labels = cv2.connectedComponents(mask, connectivity=8, ltype=cv2.CV_32S)
    assert n == n_cv - 1
    assert same_partition(labels, cv_labels.reshape(-1)[lin])
    if n:  # numbered in raster order of their first pixels
        first = np.unique(labels, return_index=True)[1]
        assert np.all(np.diff(first) > 0)


def test_row_ends_do_not_join_and_diagonals_do() -> None:
    mask = np.zeros((4, 6), np.uint8)
    mask[0, 5] = mask[1, 0] = 255  # consecutive in memory, not neighbours
    mask[2, 2] = mask[3, 3] = 255  # diagonal neighbours
    n, labels = label_pixels(mask_pixels(mask), 6)
    assert n == 3
    assert labels.tolist() == [0, 1, 2, 2]


@pytest.mark.parametrize("dtype", [np.uint8, np.uint16, np.float32])
@pytest.mark.parametrize("slope", [0.0, 0.02, 3.0])  # flat, gentle and steep background
@pytest.mark.parametrize("dense", [0.0, 1.0])  # always / never a full-resolution threshold map
def test_threshold_matches_a_full_resolution_map(dtype: type, slope: float, dense: float,
                                                  monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(sparse, "_DENSE_FRACTION", dense)
    rng = np.random.default_rng(5)
    height, width = 200, 300
    yy, xx = np.mgrid[0:height, 0:width]
    base = 30.0 + slope * (xx + 0.5 * yy) / 10.0
    noisy = base + rng.normal(0, 3.0, (height, width))
    if dtype is np.uint8:
        noisy = np.clip(noisy, 0, 255)
    det = np.ascontiguousarray(np.rint(noisy) if dtype is not np.float32 else noisy).astype(dtype)
    grid = tile_statistics(det, tile_px=32)
    thr = (grid.level + 3.0 * grid.sigma).astype(np.float32)
    shift = None if dtype is np.float32 else 0.5
    lin = threshold_pixels(det, grid, thr, shift=shift)
    t = grid.at(thr, xx.reshape(-1), yy.reshape(-1))
    if shift is not None:
        t = np.floor(t + shift)
    expected = np.flatnonzero(det.reshape(-1) > t)
    np.testing.assert_array_equal(lin, expected)
    assert 0 < lin.size < det.size
