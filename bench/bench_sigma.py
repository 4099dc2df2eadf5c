"""Is the reported attitude 1-sigma honest? Error / reported sigma per camera axis.

For every solved frame the true attitude error is resolved about the camera's x, y (cross-
boresight) and z (roll) axes and divided by ``attitude_sigma_arcsec`` on that axis. An honest
sigma gives a standard deviation of that ratio of 1 on each axis.

    python -m bench.bench_sigma --frames 300 --noise 0.25,0.5,1,2 [--camera seed000,seed003] [--real]

Frames from the simulator at each centroid noise (no false stars), solved by ``auto`` on the
default database with ``centroid_sigma_px`` = the noise; ``--real`` adds the real images'
centroid lists against their reference solutions: truth.json's quaternion, and the rigid
reference (:mod:`bench.real_reference`: the same boresight, the roll of the reference WCS's
orthogonal factor rather than of its column axis). Besides the standard deviation of error /
sigma (as the issue states the goal), the RMS: a bias common to the frames (a mean error) is
missed by the one and counted by the other; an honest sigma gives 1 on both.
"""

from __future__ import annotations

from . import common  # noqa: F401  (pins threads before numpy)

import argparse  # noqa: E402
import math  # noqa: E402
from collections.abc import Sequence  # noqa: E402

import numpy as np  # noqa: E402

from service.core.attitude import ARCSEC_PER_RAD, quat_to_matrix  # noqa: E402
from service.core.navdb import ensure_default_database, open_database  # noqa: E402
from service.core.pipeline import SolveOptions, solve  # noqa: E402
from service.core.presets import PRESETS  # noqa: E402
from service.core.sim import SimConfig, simulate_frames  # noqa: E402

from .real_reference import rigid_references  # noqa: E402


def axis_errors_arcsec(q_est: Sequence[float], q_true: Sequence[float]) -> np.ndarray:
    """Small-angle error rotation ``R_est R_true^T`` as a vector about camera x, y, z (arcsec)."""
    e = quat_to_matrix(np.asarray(q_est, float)) @ quat_to_matrix(np.asarray(q_true, float)).T
    return np.array([e[2, 1] - e[1, 2], e[0, 2] - e[2, 0], e[1, 0] - e[0, 1]]) / 2 * ARCSEC_PER_RAD


def ratios(solutions: Sequence[tuple[Sequence[float], Sequence[float], Sequence[float]]]) -> np.ndarray:
    """``(n, 3)`` error / reported sigma for ``(q_est, q_true, sigma_arcsec)`` triples."""
    rows = [axis_errors_arcsec(q, t) / np.asarray(s, float) for q, t, s in solutions]
    return np.array(rows).reshape(-1, 3)


def _row(label: str, r: np.ndarray, n_frames: int) -> str:
    std = r.std(axis=0) if len(r) else np.full(3, math.nan)
    rms = np.sqrt((r**2).mean(axis=0)) if len(r) else np.full(3, math.nan)
    return (f"| {label} | {len(r)}/{n_frames} | {std[0]:.2f} | {std[1]:.2f} | {std[2]:.2f} "
            f"| {rms[0]:.2f} / {rms[1]:.2f} / {rms[2]:.2f} |")


def main(argv: Sequence[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=300)
    ap.add_argument("--noise", default="0.25,0.5,1,2")
    ap.add_argument("--camera", default="seed000,seed003")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--real", action="store_true")
    args = ap.parse_args(argv)
    db = open_database(ensure_default_database())
    print("| camera, noise | solved | std x | std y | std roll | RMS x / y / roll |")
    print("|---|---|---|---|---|---|")
    for key in args.camera.split(","):
        preset = PRESETS[key]
        for noise in (float(v) for v in args.noise.split(",")):
            config = SimConfig(mag_limit=preset.mag_limit, centroid_noise_px=noise, false_stars=0)
            frames = simulate_frames(preset.camera, args.frames, config, rng=args.seed)
            opts = SolveOptions(centroid_sigma_px=noise)
            got = []
            for f in frames:
                sol = solve(f.centroids, preset.camera, db, options=opts)
                if sol.solved and sol.attitude_sigma_arcsec is not None:
                    got.append((sol.quaternion, f.quaternion, sol.attitude_sigma_arcsec))
            print(_row(f"{key}, {noise:g} px", ratios(got), len(frames)))
    if args.real:
        real = common.real_frames()
        rigid = rigid_references(common.REAL_DIR)
        got, got_rigid = [], []
        for rf in real:
            sol = solve(rf.centroids, rf.camera, db, options=SolveOptions(centroid_sigma_px=1.0))
            if sol.solved and sol.attitude_sigma_arcsec is not None:
                got.append((sol.quaternion, rf.quaternion, sol.attitude_sigma_arcsec))
                got_rigid.append((sol.quaternion, rigid[rf.name].quaternion, sol.attitude_sigma_arcsec))
        print(_row("real images (reference solutions)", ratios(got), len(real)))
        print(_row("real images (rigid reference)", ratios(got_rigid), len(real)))


if __name__ == "__main__":
    main()
