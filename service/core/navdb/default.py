"""The default database: built on first use from the bundled catalogue."""

from __future__ import annotations

import os
from pathlib import Path

from ..errors import DatabaseMissingError
from .builder import BuildConfig, Progress, _noop, build_database_set

DEFAULT_NAME = "default"

DEFAULT_MEMBERS: dict[str, BuildConfig] = {
    "narrow": BuildConfig(
        fov_min_deg=3.5, fov_max_deg=16.5, mag_limit=8.0, double_star_sep_deg=0.01,
        density_cap=12, density_radius_deg=2.5, methods=("maxangle", "pyramid"),
        method_params={"maxangle": {"d_max_deg": 3.5}},
    ),
    "wide": BuildConfig(
        fov_min_deg=9.0, fov_max_deg=32.0, mag_limit=6.5, double_star_sep_deg=0.02,
        density_cap=12, density_radius_deg=4.0, methods=("maxangle", "pyramid"),
    ),
}
"""The default database set: a deep (V <= 8, density-capped) member for cameras of 3.5-16.5 deg
diagonal, and a bright one for 9-32 deg (the seed-000 camera, the real test images, most star
trackers and wide-field cameras)."""


def default_database_dir() -> Path:
    """Where the default database lives: ``$SKYFIX_DB_DIR`` if set; else ``db/`` of the source
    checkout this package runs from (``pip install -e .``); else ``$XDG_CACHE_HOME/skyfix/db``
    (``~/.cache/skyfix/db``) for a plain install, never inside site-packages."""
    env = os.environ.get("SKYFIX_DB_DIR")
    if env:
        return Path(env)
    root = Path(__file__).resolve().parents[3]
    if (root / "pyproject.toml").is_file() and (root / "service").is_dir():
        return root / "db"
    cache = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(cache) / "skyfix" / "db"


def ensure_default_database(*, progress: Progress = _noop, build: bool = True) -> Path:
    """Path of the default database, building it first if it is missing."""
    path = default_database_dir() / DEFAULT_NAME
    if (path / "manifest.json").is_file():
        return path
    if not build:
        raise DatabaseMissingError(f"no default database at {path}; run `skyfix db build`")
    return build_database_set(path, DEFAULT_MEMBERS, progress=progress)
