"""Calibration round trip on simulated distorted frames: fitted camera against the truth.

    python -m bench.bench_calibrate --frames 40 --noise 0.2

Seed 000's camera with a shifted principal point and Brown-Conrady distortion renders the
frames; the calibration starts from the nominal camera (focal length 0.4% off, centred, no
distortion) on the default database. Prints a markdown table: truth, fitted, 1-sigma and
(fitted - truth) / sigma per parameter, and the RMS residual before and after.
"""

from __future__ import annotations

from . import common  # noqa: F401  (pins threads before numpy)

import argparse  # noqa: E402
from collections.abc import Sequence  # noqa: E402

from service.core.calibrate import PARAMS, calibrate  # noqa: E402
from service.core.camera import Camera  # noqa: E402
from service.core.navdb import ensure_default_database, open_database  # noqa: E402
from service.core.pipeline import SolveOptions  # noqa: E402
from service.core.sim import SimConfig, simulate_frames  # noqa: E402

TRUTH = Camera.from_focal(94.9489, 14.0, 1024, 1024, cx=517.0, cy=507.5, distortion=(-0.2, 0.5, 1e-4, -5e-5))
NOMINAL = Camera.from_focal(94.9489 * 1.004, 14.0, 1024, 1024)


def _vector(cam: Camera) -> list[float]:
    d = list(cam.distortion or ()) + [0.0] * 5
    return [cam.f_px, cam.cx, cam.cy, *d[:5]]


def main(argv: Sequence[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=40)
    ap.add_argument("--noise", type=float, default=0.2)
    ap.add_argument("--seed", type=int, default=3)
    args = ap.parse_args(argv)
    db = open_database(ensure_default_database())
    frames = simulate_frames(TRUTH, args.frames, SimConfig(mag_limit=6.5, centroid_noise_px=args.noise), rng=args.seed)
    cal = calibrate([f.centroids for f in frames], NOMINAL, db, options=SolveOptions(centroid_sigma_px=1.0))
    truth, nominal, fitted = _vector(TRUTH), _vector(NOMINAL), _vector(cal.camera)
    print("| parameter | truth | nominal (start) | fitted | 1-sigma | (fitted - truth) / sigma |")
    print("|---|---|---|---|---|---|")
    for i, name in enumerate(PARAMS):
        if name in cal.sigma:
            s = cal.sigma[name]
            print(f"| {name} | {truth[i]:.6g} | {nominal[i]:.6g} | {fitted[i]:.6g} | {s:.2g} | {(fitted[i] - truth[i]) / s:+.2f} |")
    print(f"\n{cal.frames_solved}/{cal.frames_total} frames, {cal.stars} stars; RMS residual "
          f"{cal.rms_px_nominal:.3f} px (nominal camera) -> {cal.rms_px:.3f} px (calibrated)")


if __name__ == "__main__":
    main()
