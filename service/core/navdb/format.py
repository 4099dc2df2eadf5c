"""On-disk format of the navigation database (see db/README.md).

A database is a directory holding ``manifest.json`` and one ``.npy`` file per array. The
manifest lists, for every array, its file, dtype, shape and sha256, plus the build parameters.
Arrays are named ``<group>/<name>``: ``stars/hip``, ``stars/vec``, ``stars/mag``, the *shared*
groups that several methods read (``pairs/pairs``, ``pairs/angles``: the star-pair table of
pyramid, triangle and multifov, stored once), and one group per identification method for what
is its own (``maxangle/ids``, ``triangle/kvector`` ...). The file of ``a/b`` is ``a__b.npy``.

The manifest's ``shared`` section describes each shared group: its build limits and, for every
method that reads it, the row range ``[start, end)`` that method uses (its own limits on the
common table). Schema version 1 stored the pair table once per method and is refused.

A database *set* is a directory whose ``manifest.json`` has format ``skyfix-navdb-set`` and
lists member databases (sub-directories, each a database as above) with the field-of-view range
each serves; the solver picks the member for each camera.
"""

from __future__ import annotations

import hashlib
from pathlib import Path

FORMAT_NAME = "skyfix-navdb"
SET_FORMAT_NAME = "skyfix-navdb-set"
SCHEMA_VERSION = 4
"""2: the star-pair table is one shared group (``pairs/``) instead of one copy per method.
3: ``stars/pm``, the proper motions, so a frame's epoch can be applied per request.
4: the ``quad`` pattern table in every member of the default database (auto's first pass)."""
MANIFEST = "manifest.json"

STAR_ARRAYS = {
    "stars/hip": "<i4",  # (N,) Hipparcos number, rows brightest first
    "stars/vec": "<f8",  # (N, 3) ICRS unit vectors at the database epoch
    "stars/mag": "<f4",  # (N,) approximate Johnson V
    "stars/pm": "<f4",  # (N, 2) proper motion (mu_alpha*, mu_delta), mas/yr
}

PAIR_ARRAYS = {
    "pairs/pairs": "<i4",  # (M, 2) star pairs (row indices into stars/, smaller first)
    "pairs/angles": "<f8",  # (M,) their separations, radians, ascending
}
SHARED_GROUPS = ("pairs",)
"""Array groups several methods read; no method may be named like one."""


def array_file(name: str) -> str:
    """File name of array ``group/name``."""
    if not name.replace("/", "").replace("_", "").isalnum() or name.count("/") != 1:
        raise ValueError(f"bad array name {name!r}")
    return name.replace("/", "__") + ".npy"


def sha256_file(path: Path, chunk: int = 1 << 20) -> str:
    """Hex sha256 of a file's bytes."""
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        while block := fh.read(chunk):
            h.update(block)
    return h.hexdigest()
