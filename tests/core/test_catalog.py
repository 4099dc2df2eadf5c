import math

import numpy as np
import pytest

from service.core.catalog import johnson_v, load_hipparcos, propagate, select_stars
from service.core.geometry import angle_between


def test_catalogue_is_the_whole_hipparcos() -> None:
    cat = load_hipparcos()
    assert len(cat.hip) == 117955
    assert cat.hip[0] == 1


def _row(cat, hip: int) -> int:
    return int(np.flatnonzero(cat.hip == hip)[0])


def test_vega_magnitude_and_position() -> None:
    cat = load_hipparcos()
    i = _row(cat, 91262)  # Vega, V = 0.03
    assert johnson_v(cat.hp_mag[i : i + 1], cat.b_v[i : i + 1])[0] == pytest.approx(0.03, abs=0.1)
    assert math.degrees(cat.ra_rad[i]) == pytest.approx(279.2347, abs=1e-3)


def test_barnards_star_moves_by_its_proper_motion() -> None:
    cat = load_hipparcos()
    i = _row(cat, 87937)  # Barnard's star, ~10.4 arcsec / yr
    v0, v1 = propagate(cat, 1991.25)[i], propagate(cat, 2026.25)[i]
    moved = math.degrees(float(angle_between(v0, v1))) * 3600
    assert moved == pytest.approx(10.39 * 35, rel=0.01)


def test_selection_threshold_doubles_and_density_cap() -> None:
    cat = load_hipparcos()
    base = select_stars(cat, epoch=2026.0, mag_limit=6.0)
    assert 4500 < len(base) < 5500
    assert np.all(np.diff(base.mag) >= 0) and base.mag.max() <= 6.0
    merged = select_stars(cat, epoch=2026.0, mag_limit=6.0, double_star_sep_deg=0.1)
    assert len(merged) != len(base)  # blends drop close companions and lift faint pairs over the limit
    # no two stars closer than the merge radius survive
    from scipy.spatial import cKDTree

    assert len(cKDTree(merged.vec).query_pairs(2 * math.sin(math.radians(0.1) / 2))) == 0
    capped = select_stars(cat, epoch=2026.0, mag_limit=6.0, density_cap=5, density_radius_deg=5.0)
    assert len(capped) < len(base)
    assert set(capped.hip[:50]) == set(base.hip[:50])  # the brightest are always kept
