"""On-disk format of the navigation database (see db/README.md).

A database is a directory holding ``manifest.json`` and one ``.npy`` file per array. The
manifest lists, for every array, its file, dtype, shape and sha256, plus the build parameters.
Arrays are named ``<group>/<name>``: ``stars/hip``, ``stars/vec``, ``stars/mag`` and one group
per identification method (``pyramid/pairs`` ...). The file of ``a/b`` is ``a__b.npy``.

A database *set* is a directory whose ``manifest.json`` has format ``skyfix-navdb-set`` and
lists member databases (sub-directories, each a database as above) with the field-of-view range
each serves; the solver picks the member for each camera.
"""

from __future__ import annotations

import hashlib
from pathlib import Path

FORMAT_NAME = "skyfix-navdb"
SET_FORMAT_NAME = "skyfix-navdb-set"
SCHEMA_VERSION = 1
MANIFEST = "manifest.json"

STAR_ARRAYS = {
    "stars/hip": "<i4",  # (N,) Hipparcos number, rows brightest first
    "stars/vec": "<f8",  # (N, 3) ICRS unit vectors at the database epoch
    "stars/mag": "<f4",  # (N,) approximate Johnson V
}


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
