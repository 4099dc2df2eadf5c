"""Sparse mask handling: the pixels of a detection mask and their 8-connected components.

A star field's mask holds well under 1 % of the frame's pixels, so after one full-frame
comparison everything here works on the mask pixels only. :func:`threshold_pixels` compares
the frame with the *lowest* tile threshold (a superset of the mask: a bilinear threshold never
falls below its lowest tile) and applies the bilinear threshold at those pixels only, which
spares a full-resolution threshold map; :func:`mask_pixels` scans a mask eight bytes at a
time; :func:`label_pixels` joins horizontal runs of pixels that touch
runs of the row above (8-connectivity) and labels the runs with
``scipy.sparse.csgraph.connected_components``, instead of a labelling pass over the full frame.
"""

from __future__ import annotations

import math
from typing import Any

import cv2
import numpy as np
from numpy.typing import NDArray
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from .background import TileGrid

__all__ = ["label_pixels", "mask_pixels", "threshold_pixels"]

IntArray = NDArray[np.intp]

# Above this fraction of the frame over the lowest tile threshold (a steep background), a
# full-resolution threshold map is cheaper than thresholding the candidates one by one.
_DENSE_FRACTION = 0.02


def threshold_pixels(
    det: NDArray[Any], grid: TileGrid, thr: NDArray[np.floating[Any]], *, shift: float | None
) -> IntArray:
    """Linear indices (ascending) of the pixels of ``det`` above the threshold ``thr``.

    Parameters
    ----------
    det : (H, W) ndarray
        C-contiguous detection image (image units).
    grid : TileGrid
        Tiles on which ``thr`` is given; the threshold is bilinear between tile centres.
    thr : (ny, nx) float
        Threshold per tile (image units).
    shift : float or None
        ``None`` for a float ``det`` (``det > t``); for an integer one a pixel counts when
        ``det > floor(t + shift)``.
    """
    height, width = det.shape
    low = float(thr.min())
    floor = -math.inf
    if shift is not None:
        low = float(min(math.floor(low + shift), np.iinfo(det.dtype).max))
        floor = float(np.iinfo(det.dtype).min)
    # A scalar second operand is compared with every pixel (cv2's stubs only know arrays).
    mask = cv2.compare(det, low, cv2.CMP_GT) if low >= floor else None  # type: ignore[call-overload]
    if mask is None or cv2.countNonZero(mask) > _DENSE_FRACTION * det.size:
        full = grid.upsample(np.ascontiguousarray(thr, np.float32), (height, width))
        if shift is not None:
            info = np.iinfo(det.dtype)
            full = np.clip(np.floor(full + shift), info.min, info.max).astype(det.dtype)
        return mask_pixels(np.asarray(cv2.compare(det, full, cv2.CMP_GT), np.uint8))
    lin = mask_pixels(np.asarray(mask, np.uint8))
    value = det.reshape(-1)[lin]
    high = float(thr.max()) if shift is None else math.floor(float(thr.max()) + shift)
    near = np.flatnonzero(value <= high)  # only these can fall below the bilinear threshold
    ys = lin[near] // width
    t = grid.at(thr, lin[near] - ys * width, ys)
    if shift is not None:
        t = np.floor(t + shift)
    keep = np.ones(lin.size, bool)
    keep[near] = value[near] > t
    return lin[keep]


def mask_pixels(mask: NDArray[np.uint8]) -> IntArray:
    """Linear indices (row-major, ascending) of the non-zero pixels of a C-contiguous mask."""
    flat = mask.reshape(-1)
    n8 = flat.size // 8 * 8
    words = np.flatnonzero(flat[:n8].view(np.uint64) != 0)  # a bool pass is 3x faster
    row, col = np.nonzero(flat[:n8].reshape(-1, 8)[words])
    lin = words[row] * 8 + col
    if n8 < flat.size:
        lin = np.concatenate([lin, n8 + np.flatnonzero(flat[n8:])])
    return np.asarray(lin, dtype=np.intp)


def label_pixels(lin: IntArray, width: int) -> tuple[int, IntArray]:
    """8-connected components of the pixels ``lin`` (ascending linear indices, row-major).

    Returns
    -------
    n : int
        Number of components.
    labels : (M,) intp
        Component of each pixel, ``0 .. n-1``, numbered in raster order of first pixels.
    """
    if lin.size == 0:
        return 0, np.zeros(0, np.intp)
    ys = lin // width
    xs = lin - ys * width
    brk = np.flatnonzero((np.diff(lin) != 1) | (np.diff(ys) != 0)) + 1
    starts = np.r_[0, brk]
    lengths = np.diff(np.r_[starts, lin.size])
    # Runs sorted by (row, first column); key = row * (width + 2) + column keeps rows apart
    # even with the one-pixel margins of 8-connectivity.
    row_key = ys[starts] * (width + 2)
    first = row_key + xs[starts]
    last = row_key + xs[starts + lengths - 1]
    above = row_key - (width + 2)
    lo = np.searchsorted(last, above + xs[starts] - 1, "left")  # first run above reaching x0 - 1
    hi = np.searchsorted(first, above + xs[starts + lengths - 1] + 1, "right")  # past x1 + 1
    count = np.maximum(hi - lo, 0)
    total = int(count.sum())
    below = np.repeat(np.arange(starts.size), count)
    offset = np.arange(total) - np.repeat(np.cumsum(count) - count, count)
    upper = np.repeat(lo, count) + offset
    graph = coo_matrix((np.ones(total, np.int8), (upper, below)), shape=(starts.size, starts.size))
    n, run_label = connected_components(graph.tocsr(), directed=False)
    return int(n), np.repeat(run_label.astype(np.intp), lengths)
