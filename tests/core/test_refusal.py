"""The refusals decided before any search (:mod:`service.core.refusal`)."""

from __future__ import annotations

import numpy as np

from service.core.camera import Camera
from service.core.refusal import _camera_refusal, refusal
from service.core.types import Centroids


def test_one_cameras_refusal_is_the_rigs_of_that_camera(default_set_db) -> None:
    """One camera's decision (its own short path) is a rig of two such cameras' (the general
    one): outside the range or not, with the same message, for ``auto`` and a named method
    (which the default set's members serve wherever the camera fits one)."""
    stars = Centroids(np.array([[10.0, 20.0], [300.0, 40.0], [500.0, 600.0]]), np.ones(3))
    outside = 0
    for fov in (0.4, 1.0, 3.0, 8.6, 20.0, 45.0, 70.0, 100.0, 150.0):
        for height in (768, 1024, 4096):
            cam = Camera.from_fov(fov, 1024, height)
            for method, sigma in (("auto", 1.0), ("auto", None), ("maxangle", 3.0)):
                one = _camera_refusal([(stars, cam, None)], default_set_db, method, sigma)
                assert one == _camera_refusal([(stars, cam, None)] * 2, default_set_db, method, sigma)
                outside += one is not None
    assert outside >= 10
    few = refusal([(Centroids(np.zeros((2, 2)), np.ones(2)), Camera.from_fov(8.6, 1024, 768), None)],
                  default_set_db, "auto", 0.0, 1.0)
    assert few is not None and "2 star(s) given" in few.message
