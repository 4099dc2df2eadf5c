"""Camera calibration from solved frames: a simulated round trip and the real tetra3 images."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from client.models import CameraSpec
from service.core.calibrate import PARAMS, calibrate, identify
from service.core.camera import Camera
from service.core.centroid import extract, load_image
from service.core.pipeline import SolveOptions
from service.core.sim import SimConfig, simulate_frames
from tests.conftest import ROOT

REAL = Path(os.environ.get("SKYFIX_REAL_DATA", ROOT.parent / "shared" / "data" / "real"))
TRUTH = Camera.from_focal(94.9489, 14.0, 1024, 1024, cx=517.0, cy=507.5, distortion=(-0.2, 0.5, 1e-4, -5e-5))
"""Seed 000's camera with a shifted principal point and ~8 px of distortion at the corners."""


def _truth_vector(cam: Camera) -> dict[str, float]:
    d = list(cam.distortion or ()) + [0.0] * 5
    return dict(zip(PARAMS, [cam.f_px, cam.cx, cam.cy, *d[:5]], strict=True))


def test_simulated_round_trip_recovers_the_camera_within_its_sigma(seed000_db) -> None:
    nominal = Camera.from_focal(94.9489 * 1.004, 14.0, 1024, 1024)  # focal 0.4% off, no distortion
    frames = simulate_frames(TRUTH, 30, SimConfig(mag_limit=6.5, centroid_noise_px=0.2), rng=3)
    cal = calibrate([f.centroids for f in frames], nominal, seed000_db, options=SolveOptions(centroid_sigma_px=1.0))
    truth = _truth_vector(TRUTH)
    fitted = _truth_vector(cal.camera)
    for name, sigma in cal.sigma.items():
        assert sigma > 0
        assert abs(fitted[name] - truth[name]) < 3 * sigma, (name, fitted[name], truth[name], sigma)
    assert cal.sigma["f_px"] < 2.0  # the focal length is well measured: 2 px of 6782
    assert abs(fitted["f_px"] - truth["f_px"]) < abs(nominal.f_px - truth["f_px"]) / 10
    # residuals fall from the distortion's pixels to the centroid noise (0.2 px per axis)
    assert cal.rms_px_nominal > 1.0
    assert cal.rms_px < 0.35
    assert cal.frames_solved >= 28


def test_a_nominal_focal_length_5_percent_off_is_found_with_fov_max_error(default_set_db) -> None:
    """A lens's nominal focal length is often a few percent off: as given almost no frame
    identifies, so there is little to fit; with ``fov_max_error_deg`` every frame is searched over focal
    lengths and the fit starts from theirs."""
    nominal = Camera.from_focal(94.9489 * 1.05, 14.0, 1024, 1024)
    frames = [f.centroids for f in simulate_frames(TRUTH, 20, SimConfig(mag_limit=6.5, centroid_noise_px=0.2), rng=3)]
    as_given = identify(frames, nominal, default_set_db, options=SolveOptions(centroid_sigma_px=1.0))
    assert sum(m is not None for m in as_given) <= 2
    cal = calibrate(frames, nominal, default_set_db, options=SolveOptions(centroid_sigma_px=1.0, fov_max_error_deg=1.0))
    assert cal.frames_solved >= 19
    assert abs(cal.camera.f_px - TRUTH.f_px) < 3 * cal.sigma["f_px"] < 3.0
    assert cal.rms_px < 0.35 < 5.0 < cal.rms_px_nominal


@pytest.mark.real
@pytest.mark.skipif(not (REAL / "truth.json").is_file(), reason="real images absent")
def test_real_tetra3_images_give_one_focal_length_and_smaller_residuals(default_set_db) -> None:
    """The eight 2019 tetra3 TIFFs (one camera, 1024x768, nominal 11.4 deg)."""
    paths = sorted((REAL / "tetra3").glob("*.tiff"))
    assert len(paths) == 8
    frames = [extract(load_image(p)).centroids for p in paths]
    nominal = Camera.from_fov(11.4, 1024, 768)
    cal = calibrate(frames, nominal, default_set_db, fit=("f_px", "k1"))
    assert cal.frames_solved == 8
    assert cal.rms_px < 0.5 * cal.rms_px_nominal
    truth = json.loads((REAL / "truth.json").read_text())["images"]
    ref_fov = np.mean([t["fov_deg"] for name, t in truth.items() if name.startswith("tetra3/")])
    assert abs(cal.camera.fov_deg - ref_fov) < 0.02
    # each image alone gives the same focal length to 0.05% (consistency across the sky)
    single = [calibrate([f], nominal, default_set_db, fit=("f_px",), iterations=1).camera.f_px for f in frames]
    assert np.ptp(single) < 5e-4 * np.mean(single)


def test_cli_writes_a_camera_the_api_accepts(tmp_path: Path, seed000_db) -> None:
    frames = simulate_frames(TRUTH, 12, SimConfig(mag_limit=6.5, centroid_noise_px=0.2), rng=4)
    nominal = {"width": 1024, "height": 1024, "focal_mm": 94.9489, "pixel_um": 14.0}
    rec = tmp_path / "frames.jsonl"
    rec.write_text("".join(json.dumps(f.to_record(i, TRUTH, camera_spec=nominal)) + "\n" for i, f in enumerate(frames)))
    out, report = tmp_path / "camera.json", tmp_path / "report.json"
    done = subprocess.run([sys.executable, "-c", "from service.cli import main; main()", "calibrate", str(rec), "--out", str(out),
                           "--db", str(seed000_db.path), "--fit", "f_px,k1,k2", "--report", str(report)],
                          capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    spec = json.loads(out.read_text())
    CameraSpec.model_validate(spec)  # what SKYFIX_CAMERAS and the SDK take
    cam = Camera.from_spec(spec)
    assert abs(cam.f_px - TRUTH.f_px) < 5 * json.loads(report.read_text())["parameters"]["f_px"]["sigma"]
    bad = subprocess.run([sys.executable, "-c", "from service.cli import main; main()", "calibrate", str(rec), "--out", str(out),
                          "--db", str(seed000_db.path), "--fit", "f_px,zoom"], capture_output=True, text=True, timeout=60)
    assert bad.returncode == 2 and "--fit" in bad.stderr and "Traceback" not in bad.stderr
