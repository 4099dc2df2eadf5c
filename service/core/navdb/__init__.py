"""The navigation database: format, atomic builder, memory-mapped reader, default location."""

from .builder import BuildConfig, build_database, build_database_set, current_epoch
from .default import default_database_dir, default_database_ready, ensure_default_database
from .reader import NavDatabase, NavDatabaseSet, open_database

__all__ = [
    "BuildConfig",
    "NavDatabase",
    "NavDatabaseSet",
    "build_database",
    "build_database_set",
    "current_epoch",
    "default_database_dir",
    "default_database_ready",
    "ensure_default_database",
    "open_database",
]
