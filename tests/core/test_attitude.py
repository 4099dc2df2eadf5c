import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from service.core.attitude import (
    ARCSEC_PER_RAD,
    estimate,
    matrix_from_radec_roll,
    matrix_to_quat,
    quat_multiply,
    quat_to_matrix,
    quest,
    radec_roll,
    random_rotations,
    wahba_svd,
)
from service.core.camera import Camera
from service.core.geometry import radec_to_vector

quats = st.lists(st.floats(-1, 1), min_size=4, max_size=4).filter(lambda q: np.linalg.norm(q) > 0.1)


@settings(max_examples=200, deadline=None)
@given(quats)
def test_quaternion_matrix_round_trip(q: list[float]) -> None:
    qa = np.asarray(q) / np.linalg.norm(q)
    r = quat_to_matrix(qa)
    np.testing.assert_allclose(r @ r.T, np.eye(3), atol=1e-12)
    assert np.linalg.det(r) == pytest.approx(1.0)
    back = matrix_to_quat(r)
    assert abs(abs(back @ qa) - 1) < 1e-12


def test_hamilton_product_composes_matrices() -> None:
    a, b = random_rotations(2, np.random.default_rng(3))
    np.testing.assert_allclose(quat_to_matrix(quat_multiply(a, b)), quat_to_matrix(a) @ quat_to_matrix(b), atol=1e-12)


def test_identity_attitude_looks_at_ra0_dec0_with_north_up() -> None:
    # boresight +z = ICRS +x (RA 0, Dec 0); image-up (-y) = north (ICRS +z); right (+x) = west
    r = np.array([[0.0, -1.0, 0.0], [0.0, 0.0, -1.0], [1.0, 0.0, 0.0]])
    ra, dec, roll = radec_roll(r)
    assert (ra, dec, roll) == pytest.approx((0.0, 0.0, 0.0), abs=1e-12)
    np.testing.assert_allclose(matrix_from_radec_roll(0, 0, 0), r, atol=1e-15)
    q = matrix_to_quat(r)
    np.testing.assert_allclose(q, [0.5, 0.5, -0.5, 0.5], atol=1e-15)


def test_roll_is_position_angle_of_image_up_east_of_north() -> None:
    # roll 90: image-up points east
    r = matrix_from_radec_roll(0.0, 0.0, 90.0)
    up_icrs = -r[1]
    np.testing.assert_allclose(up_icrs, [0, 1, 0], atol=1e-15)


def test_known_star_at_known_pixel() -> None:
    # Vega-ish direction at the boresight; a star 1 deg north appears straight up the image.
    cam = Camera.from_fov(10.0, 1001, 1001)
    r = matrix_from_radec_roll(279.23, 38.78, 0.0)
    star = radec_to_vector(math.radians(279.23), math.radians(39.78))
    xy, inside = cam.vector_to_pixel((r @ star)[None, :])
    assert inside[0]
    assert xy[0, 0] == pytest.approx(500.0, abs=1e-9)
    assert xy[0, 1] == pytest.approx(500.0 - cam.f_px * math.tan(math.radians(1.0)), abs=1e-6)
    # and one 1 deg east (RA larger) appears on the left (x < centre): the sky seen from inside
    east = radec_to_vector(math.radians(279.23 + 1 / math.cos(math.radians(38.78))), math.radians(38.78))
    xy, _ = cam.vector_to_pixel((r @ east)[None, :])
    assert xy[0, 0] < 500 - 80


@settings(max_examples=100, deadline=None)
@given(st.floats(0, 359.99), st.floats(-89.9, 89.9), st.floats(0, 359.99))
def test_radec_roll_round_trip(ra: float, dec: float, roll: float) -> None:
    got = radec_roll(matrix_from_radec_roll(ra, dec, roll))
    assert got[1] == pytest.approx(dec, abs=1e-9)
    assert min(abs(got[0] - ra), 360 - abs(got[0] - ra)) < 1e-7
    assert min(abs(got[2] - roll), 360 - abs(got[2] - roll)) < 1e-7


def test_wahba_svd_and_quest_agree_with_noise(rng: np.random.Generator) -> None:
    q = random_rotations(1, rng)[0]
    r = quat_to_matrix(q)
    ref = rng.normal(size=(20, 3))
    ref /= np.linalg.norm(ref, axis=1, keepdims=True)
    obs = ref @ r.T + rng.normal(0, 1e-4, (20, 3))
    obs /= np.linalg.norm(obs, axis=1, keepdims=True)
    q_svd = matrix_to_quat(wahba_svd(obs, ref))
    assert abs(abs(q_svd @ quest(obs, ref)) - 1) < 1e-12
    assert abs(abs(q_svd @ q) - 1) < 1e-7


def test_estimate_reports_residuals_and_sigma(rng: np.random.Generator) -> None:
    r = matrix_from_radec_roll(10, 20, 30)
    cam = Camera.from_fov(10, 1024, 1024)
    xy = rng.uniform(0, 1023, (30, 2))
    obs = cam.pixel_to_vector(xy)
    ref = obs @ r  # exact
    noisy = cam.pixel_to_vector(xy + rng.normal(0, 1.0, xy.shape))
    fit = estimate(noisy, ref)
    px_arcsec = math.degrees(1 / cam.f_px) * 3600
    assert fit.rms_arcsec == pytest.approx(px_arcsec * math.sqrt(2), rel=0.35)
    assert fit.sigma_arcsec[2] > fit.sigma_arcsec[0]  # roll is the weak axis


@pytest.mark.parametrize("prior", [False, True])
def test_reported_sigma_predicts_the_error(prior: bool) -> None:
    """Monte Carlo: 12 stars in a 10-deg field, 20" per-axis noise; the error about each
    camera axis divided by the reported 1-sigma has a standard deviation of 1 (within 10%),
    from the residuals alone and pooled with the declared noise."""
    rng = np.random.default_rng(42)
    sigma = 20.0 / ARCSEC_PER_RAD
    ratios = []
    for _ in range(1500):
        xy = rng.uniform(-0.087, 0.087, size=(12, 2))
        ref = np.column_stack([xy, np.ones(12)])
        ref /= np.linalg.norm(ref, axis=1)[:, None]
        east = np.cross([0.0, 1.0, 0.0], ref)
        east /= np.linalg.norm(east, axis=1)[:, None]
        north = np.cross(ref, east)
        noise = rng.normal(0, sigma, size=(12, 2))
        obs = ref + noise[:, :1] * east + noise[:, 1:] * north
        obs /= np.linalg.norm(obs, axis=1)[:, None]
        fit = estimate(obs, ref, prior_sigma_rad=sigma if prior else None)
        e = fit.matrix  # truth is the identity: the error rotation is the fit itself
        err = np.array([e[2, 1] - e[1, 2], e[0, 2] - e[2, 0], e[1, 0] - e[0, 1]]) / 2 * ARCSEC_PER_RAD
        ratios.append(err / np.asarray(fit.sigma_arcsec))
    std = np.std(ratios, axis=0)
    assert np.all((std > 0.9) & (std < 1.1)), std


def _svd_rotation(b: np.ndarray) -> np.ndarray:
    u, _, vt = np.linalg.svd(b)
    if np.linalg.det(u @ vt) < 0:
        u[:, 2] = -u[:, 2]
    return u @ vt


@pytest.mark.parametrize("cone_rad", [0.01, 0.05, 0.2, 0.6])
def test_wahba_by_polar_iteration_equals_the_svd(rng: np.random.Generator, cone_rad: float) -> None:
    # star-camera fields (a narrow cone of vectors: B is ill-conditioned), 3-40 pairs, noise
    from service.core.attitude import _polar_rotation, wahba_kernel

    for _ in range(300):
        n = int(rng.integers(3, 40))
        v = np.column_stack([rng.normal(0, cone_rad, (n, 2)), np.ones(n)])
        v /= np.linalg.norm(v, axis=1, keepdims=True)
        r_true = quat_to_matrix(rng.normal(size=4) / 2)
        obs = v + rng.normal(0, 2e-5, v.shape)
        obs /= np.linalg.norm(obs, axis=1, keepdims=True)
        ref = v @ r_true  # R^T v: obs = R ref
        r = wahba_kernel(obs, ref, np.ones(n))
        # answered by the iteration, not the fallback (a 1-deg field's B, det ~1e-9 scaled, may fall back)
        assert _polar_rotation(obs.T @ ref)[0] or cone_rad < 0.05
        np.testing.assert_allclose(r, _svd_rotation(obs.T @ ref), atol=1e-10)
        assert np.linalg.det(r) == pytest.approx(1.0, abs=1e-12)


def test_wahba_of_a_reflection_or_two_pairs_falls_back_to_the_svd(rng: np.random.Generator) -> None:
    from service.core.attitude import wahba_kernel

    v = rng.normal(size=(6, 3))
    v /= np.linalg.norm(v, axis=1, keepdims=True)
    mirrored = v * np.array([1.0, 1.0, -1.0])  # det(B) < 0: no rotation maps one onto the other
    r = wahba_kernel(mirrored, v, np.ones(6))
    np.testing.assert_allclose(r, _svd_rotation(mirrored.T @ v), atol=1e-12)
    assert np.linalg.det(r) == pytest.approx(1.0)
    two = wahba_kernel(v[:2], v[:2], np.ones(2))  # rank 2: the SVD's proper rotation (identity)
    np.testing.assert_allclose(two, np.eye(3), atol=1e-9)


@pytest.mark.real
def test_real_image_sigma_ratio_does_not_regress(default_set_db) -> None:
    """The 38 real centroid lists (matches.json) against their reference solutions, as
    ``python -m bench.bench_sigma --real`` measures them: std(error / sigma) per axis. Before
    the residual-field test (docs/attitude.md, "An honest 1-sigma") it was 1.73 / 2.21 / 1.91
    against truth.json's quaternion and 1.73 / 2.21 / 1.74 against the rigid reference; with
    it 1.52 / 1.27 / 1.82 and 1.52 / 1.27 / 1.63. The goal, 0.9-1.1, is not met: see there."""
    from bench.bench_sigma import ratios
    from bench.common import REAL_DIR, real_frames
    from bench.real_reference import rigid_references
    from service.core.pipeline import SolveOptions, solve

    if not (REAL_DIR / "truth.json").is_file():
        pytest.skip(f"real images absent ({REAL_DIR})")
    rigid = rigid_references(REAL_DIR)
    got, got_rigid = [], []
    for rf in real_frames():
        sol = solve(rf.centroids, rf.camera, default_set_db, options=SolveOptions(centroid_sigma_px=1.0))
        assert sol.solved and sol.attitude_sigma_arcsec is not None, rf.name
        got.append((sol.quaternion, rf.quaternion, sol.attitude_sigma_arcsec))
        got_rigid.append((sol.quaternion, rigid[rf.name].quaternion, sol.attitude_sigma_arcsec))
    std, std_rigid = ratios(got).std(axis=0), ratios(got_rigid).std(axis=0)
    assert len(got) == 38
    assert np.all(std <= [1.6, 1.35, 1.9]), std
    assert np.all(std_rigid <= [1.6, 1.35, 1.7]), std_rigid


@pytest.mark.real
def test_real_image_sigma_covers_the_split_halves_difference(default_set_db) -> None:
    """A test of the 1-sigma on the real images that needs no reference (``python -m
    bench.bench_sigma_real --split 1,0.3``): each frame's paired stars split in two by
    brightness, each half solved alone, the halves' attitude difference over their combined
    reported sigma. At the default declared 1 px its std is 0.45 / 0.47 / 0.34 (32 of 38 frames;
    their RMS residuals are 0.2-1.1 px, and the declared noise weighs in the pooled sigma), at
    0.3 px 0.86 / 0.74 / 0.75: the sigma is conservative for the error the centroids' own scatter
    makes. This fails if it falls short of it by more than 10% at either."""
    from bench.bench_sigma_real import split_halves
    from bench.common import REAL_DIR, real_frames

    if not (REAL_DIR / "truth.json").is_file():
        pytest.skip(f"real images absent ({REAL_DIR})")
    frames = real_frames()
    for sigma_px in (1.0, 0.3):
        z, solved = split_halves(frames, default_set_db, sigma_px)
        assert solved == 38 and len(z) >= 30, (sigma_px, solved, len(z))
        assert np.all(z.std(axis=0) <= 1.1), (sigma_px, z.std(axis=0))
