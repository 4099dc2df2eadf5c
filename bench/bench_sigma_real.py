"""The real images: attitude error against the reference and the reported 1-sigma, per image set.

    python -m bench.bench_sigma_real [--loo] [--split SIGMA_PX,...]

Each image's centroid list (matches.json, as ``bench_sigma --real`` uses it) is solved by
``auto`` on the default database with ``centroid_sigma_px`` = 1, on a pinhole camera of the
reference's field. Per image set: stars, RMS residual, the RMS error about x / y / roll
against truth.json's quaternion and against the rigid reference (:mod:`bench.real_reference`:
the same boresight, the roll of the WCS's orthogonal factor), the mean reported sigma, the
standard deviation of error / sigma, and how many frames the residual-field test widened.

``--loo`` adds the distortion test on the eight tetra3 TIFFs: each frame solved with the
camera calibrated (``f_px``, ``k1``; principal point at the centre, as the reference's) on the
other seven, against the nominal 11.4-deg and the reference-field pinhole cameras.

``--split`` adds a test that needs no reference: each solved frame's paired centroids are split
in two (alternate stars by brightness), each half is solved on its own by ``auto``, and the
difference of the two attitudes is divided by ``sqrt(sigma_A^2 + sigma_B^2)``, each half's
reported 1-sigma. Its standard deviation over the frames is 1 when the reported sigma predicts
the error that the centroids' own scatter makes (not an error both halves share, such as an
unmodelled distortion), at each declared ``centroid_sigma_px`` listed.
"""

from __future__ import annotations

from . import common  # noqa: F401  (pins threads before numpy)

import argparse  # noqa: E402
import math  # noqa: E402
from collections.abc import Sequence  # noqa: E402
from dataclasses import dataclass  # noqa: E402

import numpy as np  # noqa: E402

from service.core.attitude import ARCSEC_PER_RAD, quat_to_matrix  # noqa: E402
from service.core.calibrate import calibrate  # noqa: E402
from service.core.camera import Camera  # noqa: E402
from service.core.geometry import radec_to_vector  # noqa: E402
from service.core.navdb import ensure_default_database, open_database  # noqa: E402
from service.core.pipeline import SolveOptions, solve  # noqa: E402
from service.core.residual_field import field_fit, field_inflation  # noqa: E402
from service.core.types import Centroids  # noqa: E402

from .bench_sigma import axis_errors_arcsec  # noqa: E402
from .real_reference import rigid_references  # noqa: E402

OPTIONS = SolveOptions(centroid_sigma_px=1.0)
SETS = ("tetra3", "cedar-solve 2019 (JPEG copies of tetra3)", "cedar-solve others", "openstartracker",
        "oresat")


def image_set(name: str) -> str:
    """The image set of a truth.json name (the 2019 cedar-solve JPEGs are the tetra3 frames)."""
    if name.startswith("cedar-solve/2019"):
        return SETS[1]
    if name.startswith("cedar-solve/"):
        return SETS[2]
    return name.split("/")[0]


@dataclass(frozen=True)
class Solved:
    """One solved real frame: stars, RMS residual (px), errors (arcsec, x / y / roll) against
    the quaternion and the rigid reference, the reported sigma (arcsec), whether the
    residual-field test widened it, and the 1-sigma (arcsec) of a reference made the way the
    reference was (rotation, linear map and quadratic terms: astrometry.net's CD matrix and
    order-2 SIP) from these stars with their scatter."""

    name: str
    stars: int
    rms_px: float
    err_quat: np.ndarray
    err_rigid: np.ndarray
    sigma: np.ndarray
    widened: bool
    ref_sigma: np.ndarray


def solve_frame(frame: common.RealFrame, camera: Camera, db, rigid_q: Sequence[float]) -> Solved | None:
    """Solve one real frame's centroids on ``camera``; None when it does not solve."""
    sol = solve(frame.centroids, camera, db, options=OPTIONS)
    if not sol.solved or sol.attitude_sigma_arcsec is None:
        return None
    idx = [s.centroid for s in sol.stars]
    obs = camera.pixel_to_vector(np.asarray(frame.centroids.xy)[idx])
    ra, dec = np.radians([s.ra_deg for s in sol.stars]), np.radians([s.dec_deg for s in sol.stars])
    ref = radec_to_vector(ra, dec)
    r = quat_to_matrix(np.asarray(sol.quaternion, float))
    res = np.array([s.residual_arcsec for s in sol.stars]) / ARCSEC_PER_RAD
    sig_res = math.sqrt(float(res @ res) / max(2 * len(res) - 3, 1))  # as the solver's estimate has it
    gain = field_inflation(obs, ref, r, sig_res)
    ok, _, _, _, _, cov_j, _, _ = field_fit(obs, ref, r)
    ref_sigma = np.sqrt(np.diag(cov_j)[:3]) * sig_res * ARCSEC_PER_RAD if ok else np.full(3, np.nan)
    return Solved(frame.name, len(idx), sol.rms_arcsec / (ARCSEC_PER_RAD / camera.f_px),
                  axis_errors_arcsec(sol.quaternion, frame.quaternion),
                  axis_errors_arcsec(sol.quaternion, rigid_q),
                  np.asarray(sol.attitude_sigma_arcsec, float), bool(np.any(gain > 1.0)), ref_sigma)


def _trio(v: np.ndarray, nd: int = 1) -> str:
    return " / ".join(f"{x:.{nd}f}" for x in v)


def _joint_ratio(rows: Sequence[Solved]) -> np.ndarray:
    """std of error against the rigid reference over the combined 1-sigma of skyfix and of a
    reference fitted as astrometry.net's (frames too small for that fit left out)."""
    keep = [r for r in rows if np.all(np.isfinite(r.ref_sigma))]
    if not keep:
        return np.full(3, math.nan)
    return np.array([r.err_rigid / np.hypot(r.sigma, r.ref_sigma) for r in keep]).std(axis=0)


def table(rows: Sequence[Solved], totals: dict[str, int]) -> str:
    """Markdown table per image set and over all."""
    out = ["| image set | solved | stars (median) | RMS residual px (median) "
           "| RMS error vs quaternion x / y / roll (\") | RMS error vs rigid reference (\") "
           "| mean sigma (\") "
           "| std(error / sigma) vs quaternion | std(error / sigma) vs rigid reference | widened "
           "| std(error / sqrt(sigma^2 + reference sigma^2)) vs rigid reference |",
           "|---|---|---|---|---|---|---|---|---|---|---|"]
    groups = [(s, [r for r in rows if image_set(r.name) == s]) for s in SETS] + [("all", list(rows))]
    for label, rs in groups:
        if not rs:
            continue
        eq = np.array([r.err_quat for r in rs])
        er = np.array([r.err_rigid for r in rs])
        sg = np.array([r.sigma for r in rs])
        total = sum(totals.values()) if label == "all" else totals[label]
        out.append(f"| {label} | {len(rs)}/{total} | {np.median([r.stars for r in rs]):.0f} "
                   f"| {np.median([r.rms_px for r in rs]):.2f} | {_trio(np.sqrt((eq**2).mean(0)))} "
                   f"| {_trio(np.sqrt((er**2).mean(0)))} | {_trio(sg.mean(0))} "
                   f"| {_trio((eq / sg).std(0), 2)} | {_trio((er / sg).std(0), 2)} "
                   f"| {sum(r.widened for r in rs)} | {_trio(_joint_ratio(rs), 2)} |")
    return "\n".join(out)


def leave_one_out(frames: Sequence[common.RealFrame], db, refs) -> str:
    """The tetra3 frames solved with three cameras: the reference field's pinhole, the nominal
    11.4 deg pinhole, and the camera calibrated on the other seven frames."""
    tetra = [f for f in frames if f.name.startswith("tetra3/")]
    nominal = Camera.from_fov(11.4, 1024, 768)
    lines = ["| camera | solved | RMS residual px (median) | RMS error vs rigid reference x / y / roll (\") "
             "| mean sigma (\") | std(error / sigma) |", "|---|---|---|---|---|---|"]
    results: dict[str, list[Solved]] = {"reference-field pinhole": [], "nominal 11.4 deg pinhole": [],
                                        "calibrated on the other 7 (f, k1)": []}
    for i, f in enumerate(tetra):
        others = [g.centroids for j, g in enumerate(tetra) if j != i]
        cal = calibrate(others, nominal, db, fit=("f_px", "k1"), options=OPTIONS).camera
        for label, cam in zip(results, (f.camera, nominal, cal), strict=True):
            got = solve_frame(f, cam, db, refs[f.name].quaternion)
            if got is not None:
                results[label].append(got)
    for label, rs in results.items():
        er = np.array([r.err_rigid for r in rs]).reshape(-1, 3)
        sg = np.array([r.sigma for r in rs]).reshape(-1, 3)
        lines.append(f"| {label} | {len(rs)}/{len(tetra)} | {np.median([r.rms_px for r in rs]):.2f} "
                     f"| {_trio(np.sqrt((er**2).mean(0)))} | {_trio(sg.mean(0))} "
                     f"| {_trio((er / sg).std(0), 2)} |")
    return "\n".join(lines)


def split_halves(frames: Sequence[common.RealFrame], db, sigma_px: float) -> tuple[np.ndarray, int]:
    """Per frame whose two halves both solve, naming the stars as the whole frame did: the two
    halves' attitude difference over their combined 1-sigma (x / y / roll), and the number of
    frames the whole solved."""
    options = SolveOptions(centroid_sigma_px=sigma_px)
    z, solved = [], 0
    for f in frames:
        whole = solve(f.centroids, f.camera, db, options=options)
        if not whole.solved:
            continue
        solved += 1
        hip = {s.centroid: s.hip for s in whole.stars}
        rows = sorted(hip)
        halves = []
        xy, flux = np.asarray(f.centroids.xy), np.asarray(f.centroids.flux)
        for part in (rows[0::2], rows[1::2]):
            sol = solve(Centroids(xy[part], flux[part]), f.camera, db, options=options)
            named = sol.solved and all(s.hip == hip[part[s.centroid]] for s in sol.stars)
            if named and sol.attitude_sigma_arcsec:
                halves.append(sol)
        if len(halves) == 2:
            d = axis_errors_arcsec(halves[0].quaternion, halves[1].quaternion)
            z.append(d / np.hypot(halves[0].attitude_sigma_arcsec, halves[1].attitude_sigma_arcsec))
    return np.array(z).reshape(-1, 3), solved


def split_table(frames: Sequence[common.RealFrame], db, sigmas: Sequence[float]) -> str:
    """The split-half test at each declared centroid sigma, as markdown."""
    lines = ["| declared centroid_sigma_px | frames with both halves solved "
             "| std(difference / combined sigma) x / y / roll |", "|---|---|---|"]
    for sigma in sigmas:
        z, solved = split_halves(frames, db, sigma)
        lines.append(f"| {sigma:g} | {len(z)}/{solved} | {_trio(z.std(0), 2)} |")
    return "\n".join(lines)


def run(loo: bool = False, split: Sequence[float] = ()) -> str:
    """The tables as markdown."""
    db = open_database(ensure_default_database())
    frames = common.real_frames()
    refs = rigid_references(common.REAL_DIR)
    totals = {s: sum(image_set(f.name) == s for f in frames) for s in SETS}
    rows = [r for f in frames if (r := solve_frame(f, f.camera, db, refs[f.name].quaternion)) is not None]
    text = table(rows, totals)
    skew = np.array([abs(refs[f.name].skew_arcsec) for f in frames])
    centre = np.array([math.hypot(*refs[f.name].centre_px) for f in frames])
    text += (f"\n\nreference WCS skew |col - row|: median {np.median(skew):.0f}\", max {skew.max():.0f}\"; "
             f"boresight offset from (W/2, H/2): median {np.median(centre):.3f} px")
    if loo:
        text += "\n\n" + leave_one_out(frames, db, refs)
    if split:
        text += "\n\n" + split_table(frames, db, split)
    return text


def main(argv: Sequence[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--loo", action="store_true",
                    help="add the leave-one-out calibration test on the tetra3 frames")
    ap.add_argument("--split", default="",
                    help="declared centroid sigmas (px, comma-separated) for the split-half test")
    args = ap.parse_args(argv)
    print(run(args.loo, [float(v) for v in args.split.split(",") if v]))


if __name__ == "__main__":
    main()
