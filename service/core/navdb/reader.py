"""Open a navigation database memory-mapped and check it before use."""

from __future__ import annotations

import json
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ..catalog import StarTable
from ..errors import DatabaseCorruptError, DatabaseMissingError
from .format import (
    FORMAT_NAME,
    MANIFEST,
    SCHEMA_VERSION,
    SET_FORMAT_NAME,
    SHARED_GROUPS,
    STAR_ARRAYS,
    array_file,
    sha256_file,
)


@dataclass(frozen=True)
class NavDatabase:
    """An opened navigation database: read-only memory-mapped arrays plus the manifest.

    ``stars`` holds the navigation stars; ``shared[group]`` the arrays several methods read
    (``shared["pairs"]``: the star-pair table); ``tables[method]`` maps each method's array
    names to arrays: its own group, plus, under the shared arrays' names, its rows of every
    shared group it reads (``tables["pyramid"]["pairs"]`` is a slice of
    ``shared["pairs"]["pairs"]``, not a copy). Every array is a read-only memory-mapped view,
    so worker processes share pages.
    """

    path: Path
    manifest: dict[str, Any]
    stars: StarTable
    tables: dict[str, dict[str, np.ndarray]]
    shared: dict[str, dict[str, np.ndarray]] = field(default_factory=dict)

    @property
    def methods(self) -> list[str]:
        """Methods whose tables this database holds."""
        return list(self.manifest.get("methods", {}))

    def method_params(self, method: str) -> dict[str, Any]:
        """Build parameters the method's tables were made with."""
        return dict(self.manifest.get("methods", {}).get(method, {}))

    @property
    def epoch(self) -> float:
        return float(self.manifest["epoch"])

    @property
    def mag_limit(self) -> float:
        return float(self.manifest["mag_limit"])

    @property
    def max_fov_deg(self) -> float:
        return float(self.manifest["fov_max_deg"])


def _read_manifest(path: Path) -> dict[str, Any]:
    mpath = path / MANIFEST
    if not path.exists():
        raise DatabaseMissingError(f"no navigation database at {path}")
    if not mpath.is_file():
        raise DatabaseCorruptError(f"{mpath}: manifest missing (incomplete or foreign directory)")
    try:
        manifest = json.loads(mpath.read_text())
    except (OSError, ValueError) as exc:
        raise DatabaseCorruptError(f"{mpath}: unreadable manifest ({exc})") from exc
    if not isinstance(manifest, dict) or manifest.get("format") not in (FORMAT_NAME, SET_FORMAT_NAME):
        raise DatabaseCorruptError(f"{mpath}: not a {FORMAT_NAME} manifest")
    if manifest.get("schema_version") != SCHEMA_VERSION:
        raise DatabaseCorruptError(
            f"{mpath}: schema version {manifest.get('schema_version')!r}, this skyfix reads "
            f"{SCHEMA_VERSION}; rebuild it with `skyfix db build` (the default database is rebuilt "
            "on its next use)"
        )
    return manifest


def _open_array(path: Path, name: str, spec: dict[str, Any]) -> np.ndarray:
    fpath = path / spec["file"]
    if spec["file"] != array_file(name):
        raise DatabaseCorruptError(f"{path / MANIFEST}: array {name} names file {spec['file']!r}")
    if not fpath.is_file():
        raise DatabaseCorruptError(f"{fpath}: missing")
    try:
        with open(fpath, "rb") as fh:
            version = np.lib.format.read_magic(fh)
            reader = np.lib.format.read_array_header_1_0 if version == (1, 0) else np.lib.format.read_array_header_2_0
            shape, fortran, dtype = reader(fh)
            offset = fh.tell()
    except (OSError, ValueError) as exc:
        raise DatabaseCorruptError(f"{fpath}: not a valid .npy file ({exc})") from exc
    if dtype.hasobject:
        raise DatabaseCorruptError(f"{fpath}: object arrays are refused")
    if list(shape) != list(spec["shape"]) or dtype.str != np.dtype(spec["dtype"]).str or fortran:
        raise DatabaseCorruptError(
            f"{fpath}: shape {shape} dtype {dtype.str}, manifest says {tuple(spec['shape'])} {spec['dtype']}"
        )
    expected = offset + int(np.prod(shape, dtype=np.int64)) * dtype.itemsize
    size = os.path.getsize(fpath)
    if size != expected:
        raise DatabaseCorruptError(f"{fpath}: {size} bytes, expected {expected} (truncated or padded)")
    if expected == offset:
        return np.zeros(shape, dtype=dtype)
    # a plain ndarray view of the read-only map: np.memmap's Python-level __getitem__ costs
    # ~20 us a call, which on the solve path added up to a millisecond a frame
    return np.load(fpath, mmap_mode="r", allow_pickle=False).view(np.ndarray)


@dataclass(frozen=True)
class NavDatabaseSet:
    """Several databases, each serving a range of fields of view (a deep narrow-field member,
    a bright wide-field one, ...). ``for_camera`` picks the member for a camera; the pipeline
    does so on every solve, so a set can stand wherever a database can."""

    path: Path
    manifest: dict[str, Any]
    members: dict[str, NavDatabase]

    def for_camera(self, fov_deg: float, diagonal_fov_deg: float | None = None) -> list[NavDatabase]:
        """Members whose range holds a camera of horizontal field ``fov_deg`` and diagonal
        ``diagonal_fov_deg`` (degrees): side at least ``fov_min_deg``, diagonal at most
        ``fov_max_deg``; deepest (smallest ``fov_max_deg``) first. If none holds it, the one
        whose range is nearest."""
        diag = fov_deg if diagonal_fov_deg is None else diagonal_fov_deg
        ranges = self.__dict__.get("_ranges")
        if ranges is None:  # (member, fov_min_deg, fov_max_deg) by fov_max_deg, kept: every new camera asks
            ranges = self.__dict__["_ranges"] = sorted(
                ((m, float(m.manifest["fov_min_deg"]), float(m.manifest["fov_max_deg"]))
                 for m in self.members.values()), key=lambda r: r[2])
        fitting = [m for m, lo, hi in ranges if lo <= fov_deg and diag <= hi]
        if fitting:
            return fitting
        gaps = [max(lo - fov_deg, 0.0) + max(diag - hi, 0.0) for _, lo, hi in ranges]
        return [ranges[gaps.index(min(gaps))][0]]

    @property
    def methods(self) -> list[str]:
        """Methods every member holds."""
        sets = [set(m.methods) for m in self.members.values()]
        return sorted(set.intersection(*sets)) if sets else []

    @property
    def any_methods(self) -> list[str]:
        """Methods some member holds (a named method searches the members that fit the camera
        and hold it: the default set's ``sparse`` member alone holds ``triangle``)."""
        return sorted({name for m in self.members.values() for name in m.methods})

    @property
    def stars(self) -> StarTable:
        """The star table of the member with the most stars."""
        return max(self.members.values(), key=lambda m: len(m.stars)).stars

    @property
    def epoch(self) -> float:
        return min(m.epoch for m in self.members.values())


def open_database(path: str | os.PathLike[str], *, verify_hashes: bool = False) -> NavDatabase | NavDatabaseSet:
    """Open the database (or database set) at ``path`` memory-mapped.

    Checks the manifest's format and schema version, and every array's presence, header,
    dtype, shape and file size; ``verify_hashes`` also checks sha256 (what ``skyfix db verify``
    does). Raises ``DatabaseMissingError`` or ``DatabaseCorruptError`` naming the file.
    """
    p = Path(path)
    manifest = _read_manifest(p)
    if manifest["format"] == SET_FORMAT_NAME:
        members = manifest.get("members")
        if not isinstance(members, dict) or not members:
            raise DatabaseCorruptError(f"{p / MANIFEST}: a database set with no members")
        opened = {}
        for name in members:
            if not str(name).isidentifier():
                raise DatabaseCorruptError(f"{p / MANIFEST}: bad member name {name!r}")
            member = open_database(p / name, verify_hashes=verify_hashes)
            if not isinstance(member, NavDatabase):
                raise DatabaseCorruptError(f"{p / name}: nested database sets are not supported")
            opened[name] = member
        together = tuple(opened.values())
        for member in together:  # the stars a member left out and another holds (service.core.hidden)
            member.__dict__["_set_members"] = together
        return NavDatabaseSet(p, manifest, opened)
    arrays: dict[str, np.ndarray] = {}
    specs = manifest.get("arrays", {})
    for name in STAR_ARRAYS:
        if name not in specs:
            raise DatabaseCorruptError(f"{p / MANIFEST}: array {name} missing from the manifest")
    for name, spec in specs.items():
        arrays[name] = _open_array(p, name, spec)
        if verify_hashes and sha256_file(p / spec["file"]) != spec["sha256"]:
            raise DatabaseCorruptError(f"{p / spec['file']}: sha256 does not match the manifest")
    _check_stars(p, specs, arrays)
    stars = StarTable(arrays["stars/hip"], arrays["stars/vec"], arrays["stars/mag"], pm=arrays["stars/pm"])
    tables: dict[str, dict[str, np.ndarray]] = {m: {} for m in manifest.get("methods", {})}
    shared: dict[str, dict[str, np.ndarray]] = {}
    for name, arr in arrays.items():
        group, key = name.split("/", 1)
        if group in SHARED_GROUPS:
            shared.setdefault(group, {})[key] = arr
        elif group != "stars":
            tables.setdefault(group, {})[key] = arr
    _attach_shared(p / MANIFEST, manifest.get("shared", {}), shared, tables)
    return NavDatabase(p, manifest, stars, tables, shared)


def _check_stars(p: Path, specs: dict[str, Any], arrays: dict[str, np.ndarray]) -> None:
    """Refuse a database without stars, or whose star vectors are not finite unit vectors
    (corrupt bytes, or a broken build), naming the file (a few ms for 25,000 stars)."""
    vec = arrays["stars/vec"]
    if len(vec) == 0:
        raise DatabaseCorruptError(f"{p}: no navigation stars (built with too bright a --mag-limit?)")
    norm = np.einsum("ij,ij->i", vec, vec) if vec.ndim == 2 and vec.shape[1] == 3 else None
    if norm is None or not np.all(np.abs(norm - 1.0) < 1e-6):  # False for NaN and inf
        bad = len(vec) if norm is None else int(np.count_nonzero(~(np.abs(norm - 1.0) < 1e-6)))
        raise DatabaseCorruptError(f"{p / specs['stars/vec']['file']}: {bad} of {len(vec)} star vectors are "
                                   "not finite unit vectors (NaN or corrupt)")


def _attach_shared(mpath: Path, spec: Any, shared: dict[str, dict[str, np.ndarray]],
                   tables: dict[str, dict[str, np.ndarray]]) -> None:
    """Hand every method its rows of each shared group it reads (manifest ``shared[group]
    ["rows"][method] = [start, end)``), as views under the shared arrays' names."""
    if not isinstance(spec, dict) or set(spec) - set(SHARED_GROUPS) or set(shared) - set(spec):
        raise DatabaseCorruptError(f"{mpath}: shared groups {sorted(shared)} do not match the manifest's")
    for group, info in spec.items():
        arrays = shared.get(group)
        rows = info.get("rows") if isinstance(info, dict) else None
        if not arrays or not isinstance(rows, dict):
            raise DatabaseCorruptError(f"{mpath}: shared group {group} has no arrays or no rows")
        n = {len(a) for a in arrays.values()}
        if len(n) != 1:
            raise DatabaseCorruptError(f"{mpath}: arrays of shared group {group} differ in length")
        length = n.pop()
        for method, rng in rows.items():
            ok = isinstance(rng, list) and len(rng) == 2 and all(isinstance(x, int) for x in rng)
            if not ok or not 0 <= rng[0] <= rng[1] <= length or method not in tables:
                raise DatabaseCorruptError(f"{mpath}: bad rows {rng!r} of {group} for {method!r}")
            own = tables[method]
            if set(own) & set(arrays):
                raise DatabaseCorruptError(f"{mpath}: {method} has its own {sorted(set(own) & set(arrays))}")
            own.update({key: arr[rng[0]:rng[1]] for key, arr in arrays.items()})
