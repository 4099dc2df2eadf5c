"""The maxangle build's memory is bounded by its tables (issue 12: a 20-28 deg build peaked
at 15.6 GB, six times its 2.4 GB of tables)."""

from __future__ import annotations

import tracemalloc

from service.core.catalog import load_hipparcos, select_stars
from service.core.methods.maxangle import MaxAngle
from service.core.navdb import BuildConfig

BYTES_PER_TRIANGLE_STORED = 28  # key float64, ids 3 x int32, c and theta float32


def test_build_peak_is_near_the_tables() -> None:
    config = BuildConfig(fov_max_deg=14.0, fov_min_deg=10.0, mag_limit=6.0, methods=("maxangle",), epoch=2026.0)
    stars = select_stars(load_hipparcos(), epoch=config.epoch, mag_limit=config.mag_limit,
                         double_star_sep_deg=config.double_star_sep_deg)
    tracemalloc.start()  # numpy reports its buffers to tracemalloc
    try:
        tables, meta = MaxAngle().build_tables(stars, config, {}, lambda stage, frac: None)
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    n = meta["n_triangles"]
    stored = sum(a.nbytes for a in tables.values())
    assert n > 500_000 and stored == n * BYTES_PER_TRIANGLE_STORED
    # the tables, 5 bytes a triangle for the in-place sort, the pair tables and a chunk
    # (1.7x at this small size, where those weigh most): it was 6.5x
    assert peak < 2.0 * stored, f"peak {peak / 1e6:.0f} MB for {stored / 1e6:.0f} MB of tables"
