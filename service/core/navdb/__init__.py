"""The navigation database: format, atomic builder, memory-mapped reader, default location."""

from .builder import BuildConfig, build_database, current_epoch
from .default import default_database_dir, ensure_default_database
from .reader import NavDatabase, open_database

__all__ = [
    "BuildConfig",
    "NavDatabase",
    "build_database",
    "current_epoch",
    "default_database_dir",
    "ensure_default_database",
    "open_database",
]
