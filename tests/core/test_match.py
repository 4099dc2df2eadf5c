"""``match``'s packing of a frame's cameras and rows for the kernels."""

from __future__ import annotations

import numpy as np

from service.core.match import IDENTITY_MOUNTING, frame_rows, rig_arrays
from service.core.pipeline import _observation
from service.core.presets import PRESETS
from service.core.types import Centroids


def test_frame_rows_are_kept_per_size_and_hold_the_rows() -> None:
    camera, rows, off = frame_rows(7)
    assert camera.tolist() == [0] * 7 and rows.tolist() == list(range(7)) and off.tolist() == [0, 7]
    assert all(a.dtype == np.int64 and a.flags.writeable for a in (camera, rows, off))  # one compiled type
    again = frame_rows(7)
    assert all(a is b for a, b in zip(again, (camera, rows, off), strict=True))
    assert frame_rows(8)[1] is not rows


def test_one_camera_frame_reuses_its_arrays_and_others_get_their_own() -> None:
    cam = PRESETS["seed000"].camera
    rng = np.random.default_rng(1)
    cents = Centroids(rng.uniform(0, 1000, (9, 2)), rng.uniform(1, 100, 9))
    first = _observation([(cents, cam, None)], [IDENTITY_MOUNTING]).kernel_arrays
    second = _observation([(cents, cam, None)], [IDENTITY_MOUNTING]).kernel_arrays
    assert first is second  # solve()'s frames of one camera and size: packed once
    assert first.rows.tolist() == list(range(9)) and first.row_off.tolist() == [0, 9]
    assert first.mounts.shape == (1, 3, 3) and np.array_equal(first.mounts[0], np.eye(3))
    # rows that are not the kept ones, or another mounting: packed for the frame
    own = rig_arrays((cam,), [IDENTITY_MOUNTING], (np.arange(9, dtype=np.int64),))
    assert own is not first and own.rows.tolist() == list(range(9))
    tilted = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    turned = rig_arrays((cam,), [tilted], (frame_rows(9)[1],))
    assert turned is not first and np.array_equal(turned.mounts[0], tilted)


def test_a_star_just_outside_the_image_crowds_the_blob_it_may_have_made() -> None:
    """A blob 1.5 px inside the left edge lies 3 px from a star inside and 3.2 px from one
    predicted 1.5 px outside: it may be either, so it is not paired (match.EDGE_CROWDS); alone,
    the inside star pairs it, and a star outside beyond the crowding reach does not crowd it."""
    from service.core.camera import Camera
    from service.core.match import _project_and_pair

    cam = Camera.from_fov(10.0, 1024, 1024)
    dist = np.zeros(5)

    def ray(x: float, y: float) -> np.ndarray:
        v = np.array([(x - cam.cx) / cam.f_px, (y - cam.cy) / cam.f_px, 1.0])
        return v / np.linalg.norm(v)

    blob = np.array([[1.0, 500.0]])
    inside, outside, far = ray(4.0, 500.0), ray(-2.0, 499.0), ray(-20.0, 500.0)

    def paired(*stars: np.ndarray) -> list[int]:
        obs, pred, _ = _project_and_pair(np.array(stars), cam.f_px, cam.cx, cam.cy, cam.width, cam.height, dist, blob,
                                         3.0, 2.0)
        return pred.tolist()

    assert paired(inside) == [0]
    assert paired(inside, outside) == []
    assert paired(inside, far) == [0]
    assert paired(outside) == []  # a star outside is not paired itself
