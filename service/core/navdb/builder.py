"""Build a navigation database atomically.

Arrays are written into a fresh hidden sibling directory, each file fsynced, the manifest
last; then a symlink is swapped into place with ``os.replace`` (atomic on POSIX). A build that
is killed half-way leaves the previous database untouched and only a stray ``.*.tmp-*``
directory, which the next build removes.
"""

from __future__ import annotations

import datetime as dt
import json
import os
import shutil
import threading
import time
from collections.abc import Callable, Iterator
from concurrent.futures import ThreadPoolExecutor
from contextlib import contextmanager
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from .._cores import usable_cores
from ..catalog import CATALOGUE_NAME, StarTable, load_hipparcos, select_stars
from ..errors import InvalidInputError
from .format import (
    FORMAT_NAME,
    MANIFEST,
    SCHEMA_VERSION,
    SET_FORMAT_NAME,
    SHARED_GROUPS,
    array_file,
    sha256_file,
)
from .integrity import sample_digest

if TYPE_CHECKING:  # the methods import the reader, which this package exports: import them lazily
    from ..methods._pairs import SharedPairs

Progress = Callable[[str, float], None]
"""Progress callback: ``(stage description, fraction done in [0, 1])``."""


def current_epoch() -> float:
    """Today's date as a decimal year."""
    now = dt.datetime.now(dt.UTC)
    start = dt.datetime(now.year, 1, 1, tzinfo=dt.UTC)
    return now.year + (now - start).total_seconds() / (365.25 * 86400)


@dataclass(frozen=True)
class BuildConfig:
    """What a navigation database is built for.

    Attributes
    ----------
    fov_max_deg : float
        Largest camera field served, degrees (the diagonal of the widest camera's image).
    fov_min_deg : float
        Smallest camera field served, degrees (the side of the narrowest camera).
    mag_limit : float
        Faintest star kept, approximate Johnson V.
    epoch : float
        Decimal year the positions are propagated to.
    double_star_sep_deg : float
        Stars closer than this are merged (degrees).
    density_cap : int or None
        At most this many brighter stars within ``density_radius_deg`` of a kept star.
    methods : tuple of str
        Methods whose tables to build (``"all"`` = every registered method).
    method_params : dict
        Per-method overrides of table parameters, ``{method: {param: value}}``.
    """

    fov_max_deg: float = 12.0
    fov_min_deg: float = 6.0
    mag_limit: float = 6.5
    epoch: float = field(default_factory=lambda: round(current_epoch(), 2))
    double_star_sep_deg: float = 0.02
    density_cap: int | None = None
    density_radius_deg: float = 5.0
    methods: tuple[str, ...] = ("pyramid", "maxangle")
    method_params: dict[str, dict[str, Any]] = field(default_factory=dict)


MIN_STARS = 4
"""Fewest navigation stars a database may hold (one four-star pattern)."""


def _noop(stage: str, frac: float) -> None:
    return None


def _write_array(directory: Path, name: str, arr: np.ndarray) -> dict[str, Any]:
    arr = np.ascontiguousarray(arr)
    fname = array_file(name)
    fpath = directory / fname
    with open(fpath, "wb") as fh:
        np.lib.format.write_array(fh, arr, allow_pickle=False)
        fh.flush()
        os.fsync(fh.fileno())
    return {"file": fname, "dtype": arr.dtype.str, "shape": list(arr.shape), "sha256": sha256_file(fpath),
            "sample_sha256": sample_digest(fpath)}


def build_database(out: str | os.PathLike[str], config: BuildConfig, *, progress: Progress = _noop) -> Path:
    """Build a database for ``config`` at ``out`` (replacing any database there atomically).

    Returns the path. ``out`` becomes a symlink to a versioned sibling directory
    ``.<name>.<timestamp>``; readers only ever see a complete database.
    """
    out = Path(out)
    with _staging(out) as tmp:
        _write_member(tmp, config, progress)
    progress("done", 1.0)
    return out


def build_database_set(
    out: str | os.PathLike[str], members: dict[str, BuildConfig], *, progress: Progress = _noop,
    manifest_extra: dict[str, Any] | None = None,
) -> Path:
    """Build a *set* of databases at ``out``: one member per field-of-view range (e.g. a deep
    narrow-field member and a bright wide-field one). ``open_database`` returns a
    ``NavDatabaseSet`` that picks the member for each camera. Atomic like ``build_database``.
    ``manifest_extra`` adds fields to the set's manifest (the default set's revision).
    """
    out = Path(out)
    if not members or not all(n.isidentifier() for n in members):
        raise ValueError("members need identifier names")
    share = dict.fromkeys(members, 0.0)  # each member's progress, 0-1
    lock = threading.Lock()

    def member_progress(name: str) -> Progress:
        def sub(stage: str, frac: float) -> None:
            with lock:  # one report at a time, the set's fraction the members' mean
                share[name] = frac
                progress(f"{name}: {stage}", sum(share.values()) / len(share))
        return sub

    with _staging(out) as tmp:
        for name in members:
            (tmp / name).mkdir()
        # the deepest member first (the narrow one: half the default set's time); the others
        # share the remaining threads. The build's kernels and numpy's sorts release the GIL.
        order = sorted(members, key=lambda n: -members[n].mag_limit)
        with ThreadPoolExecutor(max_workers=min(len(members), usable_cores())) as pool:
            jobs = {n: pool.submit(_write_member, tmp / n, members[n], member_progress(n)) for n in order}
            built = {n: jobs[n].result() for n in members}
        listing = {n: {"fov_min_deg": m["fov_min_deg"], "fov_max_deg": m["fov_max_deg"],
                       "mag_limit": m["mag_limit"], "n_stars": m["n_stars"]} for n, m in built.items()}
        _write_json(tmp / MANIFEST, {"format": SET_FORMAT_NAME, "schema_version": SCHEMA_VERSION,
                                     "built_utc": dt.datetime.now(dt.UTC).isoformat(timespec="seconds"),
                                     "members": listing, **(manifest_extra or {})})
    progress("done", 1.0)
    return out


@contextmanager
def _staging(out: Path) -> Iterator[Path]:
    """A fresh hidden directory beside ``out``; on success it is published at ``out``."""
    out.parent.mkdir(parents=True, exist_ok=True)
    for stale in out.parent.glob(f".{out.name}.tmp-*"):
        shutil.rmtree(stale, ignore_errors=True)
    stamp = dt.datetime.now(dt.UTC).strftime("%Y%m%dT%H%M%S%f")
    tmp = out.parent / f".{out.name}.tmp-{os.getpid()}-{stamp}"
    tmp.mkdir()
    try:
        yield tmp
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    final = out.parent / f".{out.name}.{stamp}"
    os.rename(tmp, final)
    _swap_symlink(out, final)
    _fsync_dir(out.parent)


def _write_json(path: Path, obj: Any) -> None:
    with open(path, "w") as fh:
        json.dump(obj, fh, indent=1)
        fh.flush()
        os.fsync(fh.fileno())


def _write_member(directory: Path, config: BuildConfig, progress: Progress) -> dict[str, Any]:
    """Write one database (arrays, then the manifest) into ``directory``; return the manifest."""
    from ..methods import get_method, method_names
    from ..methods.base import PairMethod

    t0 = time.perf_counter()
    progress("reading the Hipparcos catalogue", 0.0)
    cat = load_hipparcos()
    stars: StarTable = select_stars(
        cat,
        epoch=config.epoch,
        mag_limit=config.mag_limit,
        double_star_sep_deg=config.double_star_sep_deg,
        density_cap=config.density_cap,
        density_radius_deg=config.density_radius_deg,
    )
    if len(stars) < MIN_STARS:
        raise InvalidInputError("mag_limit", f"{len(stars)} stars at V <= {config.mag_limit:g}: a database "
                                             f"needs at least {MIN_STARS} (a fainter --mag-limit)")
    arrays_meta: dict[str, Any] = {}
    assert stars.pm is not None
    for name, arr in (("stars/hip", stars.hip), ("stars/vec", stars.vec), ("stars/mag", stars.mag),
                      ("stars/pm", stars.pm)):
        arrays_meta[name] = _write_array(directory, name, arr)
    progress(f"{len(stars)} navigation stars selected", 0.1)

    names = method_names() if "all" in config.methods else list(config.methods)
    clash = sorted(set(names) & {"stars", *SHARED_GROUPS})
    if clash:
        raise ValueError(f"method names {clash} clash with database array groups")
    shared, shared_meta = _write_shared_pairs(directory, stars, config, names, arrays_meta)
    if shared is not None:
        progress(f"{len(shared.angles)} star pairs (shared)", 0.2)
    methods_meta: dict[str, Any] = {}
    for i, mname in enumerate(names):
        method = get_method(mname)
        lo, hi = 0.2 + 0.75 * i / len(names), 0.2 + 0.75 * (i + 1) / len(names)

        def sub(stage: str, frac: float, lo: float = lo, hi: float = hi, m: str = mname) -> None:
            progress(f"{m}: {stage}", lo + (hi - lo) * frac)

        params_in = config.method_params.get(mname, {})
        if isinstance(method, PairMethod) and shared is not None:
            tables, params = method.build_tables(stars, config, params_in, sub, shared=shared)
        else:  # the original interface: methods with no shared table (maxangle, radial ...)
            tables, params = method.build_tables(stars, config, params_in, sub)
        for key, arr in tables.items():
            arrays_meta[f"{mname}/{key}"] = _write_array(directory, f"{mname}/{key}", arr)
        methods_meta[mname] = params

    manifest = {
        "format": FORMAT_NAME,
        "schema_version": SCHEMA_VERSION,
        "catalogue": {"name": CATALOGUE_NAME, "sha256": cat.sha256},
        "built_utc": dt.datetime.now(dt.UTC).isoformat(timespec="seconds"),
        "build_seconds": round(time.perf_counter() - t0, 3),
        "epoch": config.epoch,
        "mag_limit": config.mag_limit,
        "fov_min_deg": config.fov_min_deg,
        "fov_max_deg": config.fov_max_deg,
        "n_stars": len(stars),
        "config": asdict(config),
        "methods": methods_meta,
        "shared": shared_meta,
        "arrays": arrays_meta,
    }
    _write_json(directory / MANIFEST, manifest)
    return manifest


def _write_shared_pairs(
    directory: Path, stars: StarTable, config: BuildConfig, names: list[str], arrays_meta: dict[str, Any]
) -> tuple[SharedPairs | None, dict[str, Any]]:
    """Build and write the ``pairs/`` group once for every method in ``names`` that reads it.

    Returns the table (None if no method reads it) and the manifest's ``shared`` section:
    the table's limits (degrees), its length, and each user's row range ``[start, end)``.
    """
    from ..methods import get_method
    from ..methods._pairs import build_shared_pairs
    from ..methods.base import PairMethod

    limits = {}
    for m in names:
        method = get_method(m)
        if isinstance(method, PairMethod):
            limits[m] = method.pair_limits(config, config.method_params.get(m, {}))
    if not limits:
        return None, {}
    shared = build_shared_pairs(stars.vec, limits.values())
    for key, arr in (("pairs", shared.pairs), ("angles", shared.angles)):
        arrays_meta[f"pairs/{key}"] = _write_array(directory, f"pairs/{key}", arr)
    meta = {"max_angle_deg": shared.limits.max_angle_deg, "min_angle_deg": shared.limits.min_angle_deg,
            "n_pairs": int(len(shared.angles)),
            "rows": {m: list(shared.rows(lim)) for m, lim in limits.items()}}
    return shared, {"pairs": meta}


def _swap_symlink(out: Path, target: Path) -> None:
    """Point ``out`` at ``target`` atomically and remove what it pointed at before."""
    old: Path | None = None
    if out.is_symlink():
        old = out.parent / os.readlink(out)
    elif out.exists():
        # a plain directory from elsewhere: move it aside first (not atomic, but never lost)
        aside = out.parent / f".{out.name}.replaced-{os.getpid()}"
        os.rename(out, aside)
        old = aside
    link_tmp = out.parent / f".{out.name}.link-{os.getpid()}"
    if link_tmp.is_symlink():
        link_tmp.unlink()
    os.symlink(target.name, link_tmp)
    os.replace(link_tmp, out)
    if old is not None and old.resolve() != target.resolve():
        shutil.rmtree(old, ignore_errors=True)


def _fsync_dir(path: Path) -> None:
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)
