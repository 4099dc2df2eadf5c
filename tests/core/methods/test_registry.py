"""The method registry: ``auto``'s order per field width and declared centroid error."""

from __future__ import annotations

import pytest

from service.core.errors import UnknownMethodError
from service.core.methods import AUTO_ORDER, WIDE_AUTO_ORDER, WIDE_FIELD_DEG, WIDE_NOISY_PX, resolve
from service.core.navdb import BuildConfig, NavDatabase, build_database, open_database


@pytest.fixture(scope="module")
def wide_db(tmp_path_factory: pytest.TempPathFactory) -> NavDatabase:
    """A small wide-field database (bright stars only) with three methods."""
    path = tmp_path_factory.mktemp("registry") / "wide"
    build_database(path, BuildConfig(fov_min_deg=15.0, fov_max_deg=29.0, mag_limit=4.0,
                                     methods=("maxangle", "pso", "pyramid")))
    return open_database(path)


def test_auto_keeps_maxangle_first_on_narrow_fields(wide_db: NavDatabase) -> None:
    order = resolve(wide_db, "auto", fov_deg=8.0, sigma_px=2.0)
    assert order[:2] == [m for m in AUTO_ORDER if m in wide_db.tables][:2] == ["maxangle", "pyramid"]


def test_auto_puts_pso_first_on_wide_noisy_fields_only(wide_db: NavDatabase) -> None:
    wide = WIDE_FIELD_DEG + 5
    assert resolve(wide_db, "auto", fov_deg=wide, sigma_px=WIDE_NOISY_PX)[0] == "pso"
    assert resolve(wide_db, "auto", fov_deg=wide, sigma_px=None)[0] == [m for m in WIDE_AUTO_ORDER if m in wide_db.tables][0]
    assert resolve(wide_db, "auto", fov_deg=wide, sigma_px=0.5)[0] == "maxangle"
    assert sorted(resolve(wide_db, "auto", fov_deg=wide, sigma_px=0.5)) == sorted(wide_db.methods)


def test_a_named_method_must_be_in_the_database(wide_db: NavDatabase) -> None:
    assert resolve(wide_db, "pso", fov_deg=20.0, sigma_px=0.5) == ["pso"]
    with pytest.raises(UnknownMethodError):
        resolve(wide_db, "dmv")
