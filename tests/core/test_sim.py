import numpy as np

from service.core.attitude import quat_to_matrix
from service.core.catalog import load_hipparcos, propagate
from service.core.sim import SimConfig, random_points, simulate_frames
from tests.conftest import SEED000_CAMERA


def test_truth_stars_project_to_their_centroids() -> None:
    cam = SEED000_CAMERA
    frames = simulate_frames(cam, 20, SimConfig(mag_limit=6.5, epoch=2026.0), rng=5)
    cat = load_hipparcos()
    vec = propagate(cat, 2026.0)
    row = {int(h): i for i, h in enumerate(cat.hip)}
    for f in frames:
        r = quat_to_matrix(f.quaternion)
        for (x, y), h in zip(f.centroids.xy, f.hip, strict=True):
            xy, inside = cam.vector_to_pixel((r @ vec[row[int(h)]])[None, :])
            # blended doubles move a little; everything else sits exactly on its star
            assert np.hypot(xy[0, 0] - x, xy[0, 1] - y) < 1.0
        assert np.all(np.diff(f.centroids.flux) <= 0)  # brightest first


def test_noise_false_missing_and_cap() -> None:
    cam = SEED000_CAMERA
    clean = simulate_frames(cam, 50, SimConfig(), rng=1)
    noisy = simulate_frames(cam, 50, SimConfig(false_stars=3, missing_prob=0.3, max_stars=10), rng=1)
    assert all(len(f.centroids) <= 10 for f in noisy)
    assert sum((f.hip < 0).sum() for f in noisy) > 50
    assert np.mean([len(f.centroids) for f in clean]) > np.mean([(f.hip >= 0).sum() for f in noisy])
    recs = noisy[0].to_record(0, cam)
    assert recs["truth"]["hip"].count(None) == int((noisy[0].hip < 0).sum())


def test_seeded_and_uniform_attitudes() -> None:
    a = simulate_frames(SEED000_CAMERA, 5, SimConfig(), rng=9)
    b = simulate_frames(SEED000_CAMERA, 5, SimConfig(), rng=9)
    assert all(np.array_equal(x.quaternion, y.quaternion) for x, y in zip(a, b, strict=True))
    boresights = np.array([quat_to_matrix(f.quaternion)[2] for f in simulate_frames(SEED000_CAMERA, 400, SimConfig(), rng=2)])
    assert abs(boresights.mean(axis=0)).max() < 0.12  # no preferred direction


def test_random_points_inside_image() -> None:
    c = random_points(SEED000_CAMERA, 100, 3)
    assert SEED000_CAMERA.contains(c.xy).all()
