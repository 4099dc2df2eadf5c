import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from service.core.camera import Camera, Rig
from service.core.errors import InvalidInputError


def test_fov_constructor_puts_edges_at_half_fov() -> None:
    cam = Camera.from_fov(10.0, 1000, 800)
    left, right = cam.pixel_to_vector(np.array([[-0.5, cam.cy], [999.5, cam.cy]]))
    assert math.degrees(math.acos(left @ right)) == pytest.approx(10.0, abs=1e-9)
    assert cam.fov_deg == pytest.approx(10.0)


def test_focal_constructor_matches_seed000() -> None:
    cam = Camera.from_focal(94.9489, 14.0, 1024, 1024)
    assert cam.f_px == pytest.approx(94.9489e3 / 14.0)
    assert cam.fov_deg == pytest.approx(math.degrees(2 * math.atan(7.168 / 94.9489)))


def test_axes_convention() -> None:
    cam = Camera.from_fov(10.0, 101, 101)
    centre, right, down = cam.pixel_to_vector(np.array([[50.0, 50.0], [60.0, 50.0], [50.0, 60.0]]))
    np.testing.assert_allclose(centre, [0, 0, 1], atol=1e-15)
    assert right[0] > 0 and abs(right[1]) < 1e-15
    assert down[1] > 0 and abs(down[0]) < 1e-15


@pytest.mark.parametrize("dist", [None, (-0.2, 0.05, 0.001, -0.0005, 0.0), (0.1, 0.0, 0.0, 0.0)])
def test_pixel_vector_pixel_round_trip(dist: tuple[float, ...] | None) -> None:
    cam = Camera.from_fov(20.0, 1280, 960, distortion=dist)
    gen = np.random.default_rng(1)
    xy = np.column_stack([gen.uniform(0, 1279, 500), gen.uniform(0, 959, 500)])
    back, inside = cam.vector_to_pixel(cam.pixel_to_vector(xy))
    assert inside.all()
    np.testing.assert_allclose(back, xy, atol=1e-6)


@settings(max_examples=50, deadline=None)
@given(st.floats(1.0, 60.0), st.integers(16, 4096), st.integers(16, 4096), st.floats(0, 1), st.floats(0, 1))
def test_round_trip_property(fov: float, w: int, h: int, fx: float, fy: float) -> None:
    cam = Camera.from_fov(fov, w, h)
    xy = np.array([[fx * (w - 1), fy * (h - 1)]])
    back, _ = cam.vector_to_pixel(cam.pixel_to_vector(xy))
    np.testing.assert_allclose(back, xy, atol=1e-7 * max(w, h))


def test_behind_camera_is_not_inside() -> None:
    cam = Camera.from_fov(10.0, 100, 100)
    _, inside = cam.vector_to_pixel(np.array([[0.0, 0.0, -1.0], [0.0, 0.0, 1.0]]))
    assert inside.tolist() == [False, True]


@pytest.mark.parametrize("spec,field", [
    ({"width": 100, "height": 100}, "camera"),
    ({"width": 0, "height": 100, "fov_deg": 10}, "camera.width"),
    ({"width": 100, "height": 100, "fov_deg": 175}, "camera.fov_deg"),
    ({"height": 100, "fov_deg": 10}, "camera.width"),
])
def test_bad_specs_name_the_field(spec: dict, field: str) -> None:
    with pytest.raises(InvalidInputError) as err:
        Camera.from_spec(spec)
    assert err.value.field == field


def test_rig_rotates_into_body() -> None:
    cam = Camera.from_fov(10.0, 100, 100)
    s = math.sqrt(0.5)
    rig = Rig((cam, cam), ((1.0, 0, 0, 0), (s, s, 0, 0)))  # camera 1 rotated 90 deg about x
    v_body = rig.body_vectors(1, np.array([[0.0, 0.0, 1.0]]))
    from service.core.attitude import quat_to_matrix
    np.testing.assert_allclose(quat_to_matrix(np.array([s, s, 0, 0])) @ v_body[0], [0, 0, 1], atol=1e-12)


@pytest.mark.parametrize("dist", [None, (-0.2, 0.05, 0.001, -0.0005, 0.0)])
def test_project_rows_is_vector_to_pixel(dist: tuple[float, ...] | None) -> None:
    """The kernels' batch projection gives Camera.vector_to_pixel's pixels and inside mask,
    stars behind the camera and outside the image included."""
    from service.core.attitude import quat_to_matrix
    from service.core.camera import project_rows
    from service.core.match import _camera_rows

    cam = Camera.from_fov(12.0, 1024, 768, distortion=dist)
    gen = np.random.default_rng(3)
    vec = gen.normal(size=(400, 3))
    vec /= np.linalg.norm(vec, axis=1, keepdims=True)
    r = quat_to_matrix(np.array([0.9, 0.1, -0.3, 0.2]) / np.linalg.norm([0.9, 0.1, -0.3, 0.2]))
    vec[:200] = (r.T @ (np.array([0, 0, 1.0]) + gen.normal(scale=0.1, size=(200, 3))).T).T  # near the boresight
    vec /= np.linalg.norm(vec, axis=1, keepdims=True)
    rows = gen.permutation(len(vec))[:300].astype(np.int64)
    cams, dists = _camera_rows((cam,))
    xy = np.empty((len(rows), 2))
    inside = project_rows(r, vec, rows, cams[0], dists[0], xy)
    want_xy, want_inside = cam.vector_to_pixel(vec[rows] @ r.T)
    assert 20 < inside.sum() < len(rows)
    np.testing.assert_array_equal(inside, want_inside)
    np.testing.assert_allclose(xy[inside], want_xy[inside], atol=1e-6)


def test_brightest_first_orders_and_projects_as_numpy() -> None:
    from service.core.camera import brightest_first

    cam = Camera.from_fov(12.0, 1024, 768)
    gen = np.random.default_rng(5)
    xy = gen.uniform(0, 1000, (40, 2))
    flux = gen.integers(1, 6, 40).astype(np.float64)  # ties: kept in input order
    order, xy_sorted, vec, flux_sorted = brightest_first(xy, flux, cam.cx, cam.cy, cam.f_px)
    want = np.argsort(-flux, kind="stable")
    np.testing.assert_array_equal(order, want)
    np.testing.assert_array_equal(xy_sorted, xy[want])
    np.testing.assert_array_equal(flux_sorted, flux[want])
    np.testing.assert_allclose(vec, cam.pixel_to_vector(xy[want]), atol=1e-15)


def test_a_camera_keeps_its_hash_and_a_copy_or_a_pickle_makes_its_own() -> None:
    """The hash is kept on the camera once asked (it keys the first sight's caches), equal
    cameras hash alike, and neither equality nor the repr sees it; a pickled or replaced camera
    starts afresh (``hash(None)`` differs between processes)."""
    import copy
    import dataclasses
    import pickle

    cam = Camera.from_fov(10.0, 1024, 768, distortion=(0.01, 0.0, 0.0, 0.0))
    twin = Camera.from_fov(10.0, 1024, 768, distortion=(0.01, 0.0, 0.0, 0.0))
    assert hash(cam) == hash(twin) == hash(cam) and cam == twin and {cam: 1}[twin] == 1
    assert cam._hash == hash(cam) and twin._hash == hash(cam)
    assert "_hash" not in repr(cam) and "_hash" not in Camera.__match_args__
    for other in (pickle.loads(pickle.dumps(cam)), copy.copy(cam), copy.deepcopy(cam)):
        assert other._hash == 0 and other == cam and hash(other) == hash(cam)
    moved = dataclasses.replace(cam, f_px=cam.f_px * 2)
    assert moved._hash == 0 and moved != cam and hash(moved) != hash(cam)
    assert dataclasses.replace(moved, f_px=cam.f_px) == cam
