"""Rig simulation: one body attitude, every camera through its mounting, truth per camera."""

from __future__ import annotations

import math

import numpy as np
import pytest

from service.core.attitude import quat_to_matrix
from service.core.camera import Camera
from service.core.catalog import load_hipparcos, propagate
from service.core.sim import SimConfig
from service.core.sim_rig import (
    GF7_AXES_ANGLE_DEG,
    gf7_rig,
    random_rig_points,
    simulate_rig_frames,
    tilt_mounting,
)
from service.core.types import Centroids


def test_gf7_rig_axes() -> None:
    rig = gf7_rig()
    assert len(rig.cameras) == 2 and rig.cameras[0].fov_deg == pytest.approx(8.9)
    assert rig.cameras[0].width == rig.cameras[0].height == 2048
    axes = [quat_to_matrix(np.asarray(m)).T @ [0, 0, 1] for m in rig.mountings]  # boresights in the body
    assert np.allclose(axes[0], [0, 0, 1])
    assert math.degrees(math.acos(axes[0] @ axes[1])) == pytest.approx(GF7_AXES_ANGLE_DEG)


@pytest.mark.parametrize(("angle", "azimuth"), [(30.0, 0.0), (90.0, 45.0), (120.0, -90.0)])
def test_tilt_mounting(angle: float, azimuth: float) -> None:
    r = quat_to_matrix(np.asarray(tilt_mounting(angle, azimuth)))
    assert np.allclose(r @ r.T, np.eye(3)) and np.linalg.det(r) == pytest.approx(1.0)
    assert math.degrees(math.acos(r[2, 2])) == pytest.approx(angle)  # boresight (row 2) vs body z


def test_truth_stars_project_through_the_mounting() -> None:
    rig = gf7_rig()
    frames = simulate_rig_frames(rig, 10, SimConfig(mag_limit=6.5, epoch=2026.0), rng=3)
    cat = load_hipparcos()
    vec = propagate(cat, 2026.0)
    row = {int(h): i for i, h in enumerate(cat.hip)}
    for rf in frames:
        r_body = quat_to_matrix(rf.quaternion)
        for f, cam, mount in zip(rf.frames, rig.cameras, rig.mountings, strict=True):
            r_cam = quat_to_matrix(np.asarray(mount)) @ r_body
            assert np.allclose(quat_to_matrix(f.quaternion), r_cam)
            for i, ((x, y), h) in enumerate(zip(f.centroids.xy, f.hip, strict=True)):
                xy, inside = cam.vector_to_pixel((r_cam @ vec[row[int(h)]])[None, :])
                # a blended double sits between its members (up to 0.03 deg = 7 px here)
                assert np.hypot(xy[0, 0] - x, xy[0, 1] - y) < (8.0 if i in f.blends else 1e-6)


def test_cameras_see_different_stars() -> None:
    rf = simulate_rig_frames(gf7_rig(), 1, SimConfig(), rng=11)[0]
    assert not set(rf.frames[0].hip.tolist()) & set(rf.frames[1].hip.tolist())


def test_seeded_and_uniform_body_attitudes() -> None:
    rig = gf7_rig()
    a = simulate_rig_frames(rig, 4, SimConfig(centroid_noise_px=0.5), rng=9)
    b = simulate_rig_frames(rig, 4, SimConfig(centroid_noise_px=0.5), rng=9)
    for x, y in zip(a, b, strict=True):
        assert np.array_equal(x.quaternion, y.quaternion)
        for p, q in zip(x.frames, y.frames, strict=True):
            assert np.array_equal(p.centroids.xy, q.centroids.xy)
    z = np.array([quat_to_matrix(f.quaternion)[2] for f in simulate_rig_frames(rig, 300, SimConfig(), rng=2)])
    assert abs(z.mean(axis=0)).max() < 0.15


def test_record_lists_cameras_and_truth_in_order() -> None:
    rig = gf7_rig()
    rf = simulate_rig_frames(rig, 1, SimConfig(false_stars=1), rng=5)[0]
    rec = rf.to_record("f1", rig)
    assert rec["id"] == "f1" and len(rec["cameras"]) == 2
    assert rec["truth"]["quaternion"] == pytest.approx(list(rf.quaternion))
    sizes = [len(c["centroids"]) for c in rec["cameras"]]
    assert sizes == [len(f.centroids) for f in rf.frames]
    assert rec["truth"]["hip"][sizes[0]:] == [None if h < 0 else int(h) for h in rf.frames[1].hip]
    for i, c in enumerate(rec["cameras"]):
        cam = Camera.from_spec(c["camera"])
        assert cam.f_px == pytest.approx(rig.cameras[i].f_px)
        assert c["camera"]["mounting_quaternion"] == pytest.approx(list(rig.mountings[i]))
        assert np.allclose(Centroids.from_list(c["centroids"]).xy, rf.frames[i].centroids.xy, atol=1e-4)


def test_inputs_feed_solve_rig_and_random_points_stay_inside() -> None:
    rig = gf7_rig()
    rf = simulate_rig_frames(rig, 1, SimConfig(), rng=1)[0]
    inputs = rf.inputs(rig)
    assert [m for _, _, m in inputs] == list(rig.mountings)
    pts = random_rig_points(rig, [7, 3], rng=0)
    assert [len(c) for c, _, _ in pts] == [7, 3]
    assert all(cam.contains(c.xy).all() for c, cam, _ in pts)
