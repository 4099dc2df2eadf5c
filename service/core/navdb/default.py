"""The default database: built on first use from the bundled catalogue."""

from __future__ import annotations

import fcntl
import json
import os
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from ..errors import DatabaseMissingError
from .builder import BuildConfig, Progress, _noop, build_database_set
from .format import MANIFEST, SCHEMA_VERSION

DEFAULT_NAME = "default"

DEFAULT_MEMBERS: dict[str, BuildConfig] = {
    "narrow": BuildConfig(
        fov_min_deg=3.5, fov_max_deg=16.5, mag_limit=8.0, double_star_sep_deg=0.01,
        density_cap=12, density_radius_deg=2.5, methods=("quad", "maxangle", "pyramid"),
        method_params={"maxangle": {"d_max_deg": 3.5}},
    ),
    "sparse": BuildConfig(
        fov_min_deg=3.5, fov_max_deg=9.0, mag_limit=7.0, double_star_sep_deg=0.01,
        methods=("quad", "maxangle", "pyramid", "triangle"),
        method_params={"maxangle": {"d_max_deg": 3.5}, "triangle": {"box_d_max_deg": 4.5}},
    ),
    "mid": BuildConfig(
        fov_min_deg=7.0, fov_max_deg=13.0, mag_limit=6.5, double_star_sep_deg=0.02,
        density_cap=12, density_radius_deg=4.0, methods=("quad", "maxangle", "pyramid"),
        method_params={"maxangle": {"d_max_deg": 13.0}},
    ),
    "wide": BuildConfig(
        fov_min_deg=9.0, fov_max_deg=32.0, mag_limit=6.5, double_star_sep_deg=0.02,
        density_cap=12, density_radius_deg=4.0, methods=("quad", "maxangle", "pyramid"),
    ),
    "rig": BuildConfig(
        fov_min_deg=7.0, fov_max_deg=13.0, mag_limit=6.5, double_star_sep_deg=0.02,
        density_cap=12, density_radius_deg=4.0, methods=("multifov",),
    ),
}
"""The default database set: a deep (V <= 8, density-capped) member for cameras of 3.5-16.5 deg
diagonal, a V <= 7 one for 3.5-9 deg, a bright one for 9-32 deg (the real test images, most star
trackers and wide-field cameras), and between them ``mid`` (V <= 6.5) for cameras of 7 deg side
to 13 deg diagonal (the seed-000 camera, 8.6 deg; seed 001's GF-7 camera, 8.9 deg), whose
``maxangle`` table holds every triangle up to 13 deg: the whole field of each camera it serves.
(The narrow and wide members' ``maxangle`` tables hold triangles up to their smallest camera's
side; the whole field of their largest at their density would cost about 500x and 150x as many
triangles.) ``mid`` costs ~15 s
and ~225 MB of the build (docs/benchmarks.md, Batch). Until revision 6 it stopped at 12.5 deg, and
seed 001's camera (12.56-deg diagonal) was served by ``narrow`` alone: bench_wrong's 99,960
frames name 165 more of seed 001's with ``mid`` (19,754 -> 19,919, 0 wrong), but 2% fewer of
its stars (333,857 -> 326,473), as on seed 000: stars past ``mid``'s density cap are named only
when the answer re-verified against ``narrow`` is strongly proven there
(``first_pass.settle_kernel``), which against V <= 8 takes more pairs.

``sparse`` is for narrow cameras that see only a few stars: against the deep member, a frame of
3-4 stars cannot be proven (its many faint stars make any small pattern ambiguous and any lone
extra match likely by chance); against V <= 7 it can, with the triangle method's
unique-triangle proof. The set tries the shallowest fitting member first. Its ``triangle`` keeps
a table of every triangle up to 4.5 deg (``box_d_max_deg``; 1.46 million, 39 MB, ~3 s of the
build) from which the proof reads its density boxes, and ``pyramid`` and ``triangle`` their
candidates, instead of joining pair windows (:mod:`service.core.methods._table_join`): 996 of
the 1,011 boxes of seed 002's 3-star frames fit in it. Measured with
``python -m bench.bench_default_db --frames 300 --camera seed002``: the 4-deg camera's frames
of 3 stars 0/37 -> 32/37, of 4 stars 1/44 -> 41/44 (a database built for the camera: 33/37,
44/44); the other paper cameras unchanged. It adds ~8 s to the build and 108 MB (the triangle
table 39 MB of them).

``rig`` serves rigs only (several cameras on one body, ``solve_rig``): ``multifov`` for cameras of
7 deg side to 13 deg diagonal at V <= 6.5 (the pair table and its index: ~1.5 s of the build and
6 MB). ``auto`` runs it on a rig after the first pass; for one camera it searches the other
members only (``plan.RIG_METHOD``). Without it, seed 001's rig (GF-7's two 8.9-deg cameras, whose 12.6-deg
diagonal only the deep ``narrow`` member served until revision 6) identified 93.3% of frames with 4 or more stars;
with it 99.7-99.8% (990-991 of 993 in repeated runs), 0 wrong (``python -m bench.bench_rig --frames 1000 --mag-limit 5.5 --noise 0.5``)."""


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


DEFAULT_REVISION = 6
"""The default set's contents, recorded in its manifest (``default_revision``): a default
database of an older revision is rebuilt on first use, like one of an older schema, while
databases a user built are left as they are. 2: ``maxangle`` tables in the ``cells`` layout
(:mod:`service.core.methods.maxangle_index`; the same records, read 3-8x faster). 3: the ``rig``
member (``multifov`` for rigs of 7-13 deg cameras). 4: ``quad`` tables with a spill list
(:data:`service.core.methods.quad_build.SPILL_OVER`; the same patterns, a third less time a
look-up on the narrow member). 5: the ``sparse`` member's ``triangle`` holds a table of
every triangle to 4.5 deg (``box_d_max_deg``; the same answers, seed 002's frames of 3-4 stars
~35% faster). 6: ``mid`` serves cameras to 13 deg diagonal (12.5 before), seed 001's GF-7 camera
(8.9 deg, 12.56-deg diagonal) among them."""


def _outdated(path: Path) -> str | None:
    """Why the default database at ``path`` is older than this skyfix builds (a readable
    manifest with a smaller integer ``schema_version``, or ``default_revision``), else None."""
    try:
        manifest = json.loads((path / MANIFEST).read_text())
        version = manifest.get("schema_version")
        revision = manifest.get("default_revision", 1)
    except (OSError, ValueError, AttributeError):
        return None  # missing or unreadable: opening reports it
    if isinstance(version, int) and version < SCHEMA_VERSION:
        return f"schema {version}"
    if version == SCHEMA_VERSION and isinstance(revision, int) and revision < DEFAULT_REVISION:
        return f"revision {revision}"
    return None


def default_database_ready() -> bool:
    """True if the default database exists and is of the current schema (nothing to build)."""
    path = default_database_dir() / DEFAULT_NAME
    return (path / MANIFEST).is_file() and _outdated(path) is None


def ensure_default_database(
    *, progress: Progress = _noop, build: bool = True, members: dict[str, BuildConfig] | None = None
) -> Path:
    """Path of the default database, building it first if it is missing or was built by an
    older skyfix (an older schema version or ``DEFAULT_REVISION``: it is replaced atomically;
    it is a cache of the bundled catalogue, so nothing is lost). ``members`` overrides ``DEFAULT_MEMBERS``.

    A manifest that is unreadable or of a *newer* schema is left alone: opening it names the
    problem. With ``build=False`` a missing or old database raises ``DatabaseMissingError``.
    """
    path = default_database_dir() / DEFAULT_NAME
    old = _outdated(path)
    if (path / MANIFEST).is_file() and old is None:
        return path
    if not build:
        why = "no default database" if old is None else f"the default database ({old}) is outdated"
        raise DatabaseMissingError(f"{why} at {path}; any `skyfix` command without a database argument "
                                   "(e.g. `skyfix db info`) rebuilds it")
    with _build_lock(path):  # two processes starting at once (server workers, test workers): one builds
        if (path / MANIFEST).is_file() and _outdated(path) is None:
            return path  # built by the process that held the lock
        return build_database_set(path, DEFAULT_MEMBERS if members is None else members, progress=progress,
                                  manifest_extra={"default_revision": DEFAULT_REVISION})


@contextmanager
def _build_lock(path: Path) -> Iterator[None]:
    """An exclusive lock on ``path``'s build (a lock file beside it, held until the build is
    published): a second builder would delete the first one's staging directory."""
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path.parent / f".{path.name}.lock", "a") as fh:
        fcntl.flock(fh, fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(fh, fcntl.LOCK_UN)
