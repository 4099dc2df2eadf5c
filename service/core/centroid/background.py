"""Local background and noise on a coarse grid of tiles.

The image is cut into square tiles of ``tile_px``; each tile is summarised by a subsample of
at most 16 x 16 pixels (every ``s``-th pixel), which is plenty for a robust median and keeps the
cost far below one pass over a large frame. Per tile: the median (background level) and the
normalised median absolute deviation (noise sigma, ``1.4826 * MAD``). Both grids are then
median-filtered over 3 x 3 tiles so that a bright star, the Moon or a tree in one tile does not
leak into the threshold. Values at full resolution are bilinear between tile centres.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import cv2
import numpy as np
from numpy.typing import NDArray
from scipy import ndimage

__all__ = ["TileGrid", "tile_statistics"]

_SAMPLES_PER_SIDE = 16
_MAD_TO_SIGMA = 1.4826


@dataclass(frozen=True, slots=True)
class TileGrid:
    """Background level and noise sigma per tile.

    Attributes
    ----------
    level : (ny, nx) float32
        Median pixel value per tile (image units).
    sigma : (ny, nx) float32
        Robust noise sigma per tile (image units per pixel).
    tile_px : int
        Tile side in pixels; tile ``(j, i)`` covers rows ``j*tile_px ...`` and columns
        ``i*tile_px ...``, and its value sits at the tile's centre.
    """

    level: NDArray[np.float32]
    sigma: NDArray[np.float32]
    tile_px: int

    def at(
        self, grid: NDArray[Any], x: NDArray[Any], y: NDArray[Any]
    ) -> NDArray[np.float64]:
        """Bilinear value of ``grid`` (``level``, ``sigma`` or a combination of them) at pixel
        positions ``x``, ``y`` (same mapping as :meth:`upsample`, clamped at the edges)."""
        ny, nx = grid.shape
        u = np.clip((np.asarray(x, dtype=np.float64) + 0.5) / self.tile_px - 0.5, 0.0, nx - 1.0)
        v = np.clip((np.asarray(y, dtype=np.float64) + 0.5) / self.tile_px - 0.5, 0.0, ny - 1.0)
        i0 = np.minimum(u.astype(np.intp), max(nx - 2, 0))
        j0 = np.minimum(v.astype(np.intp), max(ny - 2, 0))
        i1 = np.minimum(i0 + 1, nx - 1)
        j1 = np.minimum(j0 + 1, ny - 1)
        fu, fv = u - i0, v - j0
        g = grid.astype(np.float64)
        top = g[j0, i0] * (1 - fu) + g[j0, i1] * fu
        bottom = g[j1, i0] * (1 - fu) + g[j1, i1] * fu
        return np.asarray(top * (1 - fv) + bottom * fv)

    def upsample(self, grid: NDArray[Any], shape: tuple[int, int]) -> NDArray[Any]:
        """Bilinear full-resolution map ``(H, W)`` of a tile grid, in the grid's dtype."""
        height, width = shape
        ny, nx = grid.shape
        full = cv2.resize(grid, (nx * self.tile_px, ny * self.tile_px), interpolation=cv2.INTER_LINEAR)
        return np.asarray(full[:height, :width])


def tile_statistics(image: NDArray[Any], *, tile_px: int, smooth: bool = True) -> TileGrid:
    """Median and robust sigma of ``image`` per tile.

    Parameters
    ----------
    image : (H, W) ndarray
        Any real dtype.
    tile_px : int
        Requested tile side in pixels; rounded down to a multiple of the subsampling step.
    smooth : bool, optional
        Median-filter both grids over 3 x 3 tiles (default).

    Returns
    -------
    TileGrid
    """
    height, width = image.shape
    step = max(1, tile_px // _SAMPLES_PER_SIDE)
    per_tile = max(1, tile_px // step)
    tile = per_tile * step
    ny, nx = -(-height // tile), -(-width // tile)
    # 8/16-bit pixels stay native: partitioning them is twice as fast as float32, and their
    # median and absolute deviations are exact integers anyway.
    native = image.dtype in (np.uint8, np.uint16)
    sub = np.asarray(image[step // 2 :: step, step // 2 :: step], dtype=None if native else np.float32)
    pad = ((0, ny * per_tile - sub.shape[0]), (0, nx * per_tile - sub.shape[1]))
    if pad[0][1] or pad[1][1]:
        sub = np.pad(sub, pad, mode="symmetric")
    blocks = sub.reshape(ny, per_tile, nx, per_tile).transpose(0, 2, 1, 3).reshape(ny, nx, -1)
    k = blocks.shape[-1] // 2
    level = np.partition(blocks, k, axis=-1)[..., k]
    centre = level[..., None]
    dev = np.maximum(blocks, centre) - np.minimum(blocks, centre)  # |x - median|, no sign
    sigma = _MAD_TO_SIGMA * np.partition(dev, k, axis=-1)[..., k].astype(np.float32)
    level = level.astype(np.float32)
    if smooth and (ny > 1 or nx > 1):
        level = ndimage.median_filter(level, size=3, mode="nearest")
        sigma = ndimage.median_filter(sigma, size=3, mode="nearest")
    return TileGrid(np.ascontiguousarray(level, np.float32), np.ascontiguousarray(sigma, np.float32), tile)
