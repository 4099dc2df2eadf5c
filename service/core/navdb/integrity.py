"""Integrity checks of a navigation database beyond the reader's header, shape and size checks.

``sample_digest`` is a sha256 over a file's size, its first and last 64 KiB and 64 evenly
spaced 4 KiB blocks (every byte of a file under 384 KiB): the builder stores it beside each
array's full sha256, and ``check_at_start`` compares it for every array (a few MB read in all,
well under a second for the default database), so that bytes corrupted in place at a file's
ends, in its header or in a sampled block are refused before a server starts. Only the full
sha256 (``skyfix db verify``, ``skyfix serve --verify``) sees every byte.
"""

from __future__ import annotations

import hashlib
import os
from pathlib import Path
from typing import Any

from ..errors import DatabaseCorruptError
from .format import MANIFEST

EDGE_BYTES = 64 * 1024
BLOCK_BYTES = 4096
N_BLOCKS = 64


def sample_digest(path: str | os.PathLike[str]) -> str:
    """sha256 (hex) of the file's size, first and last ``EDGE_BYTES`` and ``N_BLOCKS`` evenly
    spaced blocks of ``BLOCK_BYTES`` (the whole file when it is smaller than all that)."""
    size = os.path.getsize(path)
    h = hashlib.sha256(size.to_bytes(8, "little"))
    with open(path, "rb") as fh:
        if size <= 2 * EDGE_BYTES + N_BLOCKS * BLOCK_BYTES:
            h.update(fh.read())
            return h.hexdigest()
        h.update(fh.read(EDGE_BYTES))
        span = size - 2 * EDGE_BYTES - BLOCK_BYTES
        for i in range(N_BLOCKS):
            fh.seek(EDGE_BYTES + span * i // (N_BLOCKS - 1))
            h.update(fh.read(BLOCK_BYTES))
        fh.seek(size - EDGE_BYTES)
        h.update(fh.read(EDGE_BYTES))
    return h.hexdigest()


def _members(db: Any) -> list[Any]:
    return list(db.members.values()) if hasattr(db, "members") else [db]


def check_samples(db: Any) -> int:
    """Compare every array's sampled digest with its manifest's (databases built before the
    digest existed have none: skipped). Returns the arrays checked; raises
    ``DatabaseCorruptError`` naming the file."""
    n = 0
    for member in _members(db):
        for spec in member.manifest.get("arrays", {}).values():
            want = spec.get("sample_sha256")
            if want is None:
                continue
            fpath = Path(member.path) / spec["file"]
            if sample_digest(fpath) != want:
                raise DatabaseCorruptError(
                    f"{fpath}: bytes differ from those the database was built with (sampled check); "
                    f"rebuild it, or see `skyfix db verify {member.path}`")
            n += 1
    return n


def check_at_start(path: str | os.PathLike[str], *, verify_hashes: bool = False) -> Any:
    """Open the database at ``path`` as a server does before it starts: the reader's checks
    (headers, shapes, sizes; stars present and finite unit vectors), the sampled digests, and
    with ``verify_hashes`` every byte's sha256. Returns the opened database."""
    from .reader import open_database

    db = open_database(path, verify_hashes=verify_hashes)
    check_samples(db)
    return db


__all__ = ["MANIFEST", "check_at_start", "check_samples", "sample_digest"]
