"""The default database: built on first use from the bundled catalogue."""

from __future__ import annotations

import os
from pathlib import Path

from ..errors import DatabaseMissingError
from .builder import BuildConfig, Progress, _noop, build_database

DEFAULT_NAME = "default"

DEFAULT_CONFIG = BuildConfig(
    fov_max_deg=30.0,
    fov_min_deg=5.0,
    mag_limit=6.5,
    double_star_sep_deg=0.02,
    density_cap=12,
    density_radius_deg=4.0,
    methods=("pyramid", "maxangle"),
)
"""Serves cameras from about 5 to 25 degrees (the seed-000 camera and the real test images)."""


def default_database_dir() -> Path:
    """``$SKYFIX_DB_DIR`` if set, else ``db/`` at the project root (beside ``service/``)."""
    env = os.environ.get("SKYFIX_DB_DIR")
    if env:
        return Path(env)
    return Path(__file__).resolve().parents[3] / "db"


def ensure_default_database(*, progress: Progress = _noop, build: bool = True) -> Path:
    """Path of the default database, building it first if it is missing."""
    path = default_database_dir() / DEFAULT_NAME
    if (path / "manifest.json").is_file():
        return path
    if not build:
        raise DatabaseMissingError(f"no default database at {path}; run `skyfix db build`")
    return build_database(path, DEFAULT_CONFIG, progress=progress)
