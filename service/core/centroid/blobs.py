"""Blobs of the detection mask -> sources (peaks), reduced over the sparse mask pixels only.

A blob is a connected component of the thresholded, matched-filtered image. Every blob has a
primary source, its highest filtered pixel. Blobs are *deblended*: every other local maximum of
the filtered image becomes a source too when it stands out from the ridge that joins it to the
primary by at least ``prominence`` filtered-noise sigmas and reaches ``contrast`` times the
primary's height above background. Without this, two stars a few PSF widths apart merge into
one blob and one centroid between them. (A saturated core is a plateau of equal filtered
values, which yields a single maximum, so saturated blobs are deblended too.)
"""

from __future__ import annotations

from dataclasses import dataclass, fields
from typing import Any

import numpy as np
from numpy.typing import NDArray

from .background import TileGrid

__all__ = ["Sources", "find_sources"]

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.intp]

# 8-neighbour offsets (dy, dx) before and after a pixel in raster order: a local maximum is
# >= the ones before and > the ones after, so a flat plateau yields one maximum, not many.
_BEFORE = ((-1, -1), (-1, 0), (-1, 1), (0, -1))
_AFTER = ((0, 1), (1, -1), (1, 0), (1, 1))
_LINE_SAMPLES = 24


@dataclass(frozen=True, slots=True)
class Sources:
    """One row per source; blob-level values are repeated for every source of a blob.

    Attributes
    ----------
    x, y : (M,) intp
        Peak pixel of the filtered image.
    height : (M,) float64
        Filtered value at the peak above the filtered background.
    area : (M,) int64
        Pixels of the source's blob.
    n_peaks : (M,) int64
        Sources in the source's blob (1 = not blended).
    extent : (M,) int64
        Larger side of the blob's bounding box (px).
    raw_max : (M,) float64
        Highest raw pixel of the blob (image units).
    n_saturated : (M,) int64
        Pixels of the blob at or above the saturation level (0 without one).
    mask_flux : (M,) float64
        Sum of background-subtracted raw pixels over the blob.
    cog_x, cog_y : (M,) float64
        Intensity-weighted centre of the blob's raw pixels (clipped at 0 above background).
    """

    x: IntArray
    y: IntArray
    height: FloatArray
    area: NDArray[np.int64]
    n_peaks: NDArray[np.int64]
    extent: NDArray[np.int64]
    raw_max: FloatArray
    n_saturated: NDArray[np.int64]
    mask_flux: FloatArray
    cog_x: FloatArray
    cog_y: FloatArray

    def __len__(self) -> int:
        return int(self.x.shape[0])

    def take(self, idx: IntArray) -> Sources:
        return Sources(*(getattr(self, f.name)[idx] for f in fields(self)))


def find_sources(
    lin: IntArray,
    labels: IntArray,
    image: NDArray[Any],
    det: NDArray[Any],
    raw_grid: TileGrid,
    det_grid: TileGrid,
    det_sigma: NDArray[np.float32],
    *,
    saturation: float | None,
    prominence: float = 3.0,
    contrast: float = 0.005,
) -> Sources:
    """Sources of the blobs whose mask pixels are ``lin`` (ascending linear indices of the
    C-contiguous ``image`` and ``det``) with component ``labels`` (:mod:`.sparse`).

    ``det`` is the filtered image that was thresholded; ``det_sigma`` its noise grid on
    ``det_grid``'s tiles.
    """
    # Group the pixels by blob, raster order kept within each (a radix sort for 16-bit labels).
    keys = labels.astype(np.uint16) if labels.size and labels.max() < 65536 else labels
    order = np.argsort(keys, kind="stable")
    lin, lab = lin[order], keys[order]
    ys = lin // det.shape[1]
    xs = lin - ys * det.shape[1]
    starts = np.flatnonzero(np.r_[True, lab[1:] != lab[:-1]])
    ends = np.r_[starts[1:], lab.size]
    area = ends - starts
    blob_of = np.repeat(np.arange(starts.size), area)
    det_v = det.reshape(-1)[lin].astype(np.float64)
    raw_v = image.reshape(-1)[lin].astype(np.float64)

    # Highest filtered pixel per blob (the first one in raster order on a plateau).
    at_max = np.flatnonzero(det_v == np.maximum.reduceat(det_v, starts)[blob_of])
    peak_i = at_max[np.r_[True, blob_of[at_max[1:]] != blob_of[at_max[:-1]]]]
    # Background is smooth on the scale of a blob: one value per blob, at its peak.
    bkg = raw_grid.at(raw_grid.level, xs[peak_i], ys[peak_i])
    resid = raw_v - bkg[blob_of]
    w = np.clip(resid, 0.0, None)
    wsum = np.add.reduceat(w, starts)
    safe = np.where(wsum > 0, wsum, 1.0)
    cog_x = np.where(wsum > 0, np.add.reduceat(w * xs, starts) / safe, xs[peak_i])
    cog_y = np.where(wsum > 0, np.add.reduceat(w * ys, starts) / safe, ys[peak_i])
    raw_max = np.maximum.reduceat(raw_v, starts)
    extent = np.maximum(np.maximum.reduceat(xs, starts) - np.minimum.reduceat(xs, starts),
                        np.maximum.reduceat(ys, starts) - np.minimum.reduceat(ys, starts)) + 1

    # Secondary peaks: other local maxima of multi-pixel blobs, prominent over the ridge.
    is_max = _local_maxima(det, lin, xs, ys, det_v, area[blob_of] >= 2)
    is_max[peak_i] = False
    if saturation is not None:
        n_sat = np.add.reduceat((raw_v >= saturation).astype(np.int64), starts)
    else:
        n_sat = np.zeros(starts.size, np.int64)
    sec = np.flatnonzero(is_max)
    if sec.size:
        prim = peak_i[blob_of[sec]]
        lvl_sec = det_grid.at(det_grid.level, xs[sec], ys[sec])
        h_sec = det_v[sec] - lvl_sec
        h_prim = det_v[prim] - det_grid.at(det_grid.level, xs[prim], ys[prim])
        prom = det_v[sec] - _line_minimum(det, xs[sec], ys[sec], xs[prim], ys[prim])
        noise = det_grid.at(det_sigma, xs[sec], ys[sec])
        sec = sec[(prom >= prominence * noise) & (h_sec >= contrast * h_prim)]
    src = np.concatenate([peak_i, sec])
    blob = blob_of[src]
    n_peaks = np.bincount(blob, minlength=starts.size)
    return Sources(
        x=xs[src], y=ys[src],
        height=det_v[src] - det_grid.at(det_grid.level, xs[src], ys[src]),
        area=area[blob].astype(np.int64),
        n_peaks=n_peaks[blob].astype(np.int64),
        extent=extent[blob].astype(np.int64),
        raw_max=raw_max[blob],
        n_saturated=n_sat[blob],
        mask_flux=np.add.reduceat(resid, starts)[blob],
        cog_x=cog_x[blob].astype(np.float64),
        cog_y=cog_y[blob].astype(np.float64),
    )


def _local_maxima(det: NDArray[Any], lin: IntArray, xs: IntArray, ys: IntArray, centre: FloatArray,
                  consider: NDArray[np.bool_]) -> NDArray[np.bool_]:
    """Which of the pixels ``lin`` (at xs, ys) are 8-neighbour maxima of ``det`` (raster
    tie-break); only pixels flagged in ``consider`` are tested, the others come back False."""
    height, width = det.shape
    flat = det.reshape(-1)
    out = consider.copy()
    for offsets, strict in ((_AFTER, True), (_BEFORE, False)):
        for dy, dx in offsets:
            idx = np.flatnonzero(out)  # shrinks quickly: most pixels fail the first tests
            ny, nx = ys[idx] + dy, xs[idx] + dx
            inside = (ny >= 0) & (ny < height) & (nx >= 0) & (nx < width)
            nb = flat[np.where(inside, lin[idx] + (dy * width + dx), lin[idx])].astype(np.float64)
            ok = centre[idx] > nb if strict else centre[idx] >= nb
            out[idx[~(ok | ~inside)]] = False
    return out


def _line_minimum(
    det: NDArray[Any], x0: IntArray, y0: IntArray, x1: IntArray, y1: IntArray
) -> FloatArray:
    """Lowest ``det`` value (nearest pixel) along each straight segment (x0, y0) -> (x1, y1)."""
    t = np.linspace(0.0, 1.0, _LINE_SAMPLES)[None, :]
    px = np.rint(x0[:, None] + (x1 - x0)[:, None] * t).astype(np.intp)
    py = np.rint(y0[:, None] + (y1 - y0)[:, None] * t).astype(np.intp)
    return np.asarray(det[py, px].astype(np.float64).min(axis=1))
