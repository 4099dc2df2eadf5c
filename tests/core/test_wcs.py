"""The FITS WCS of a solved frame: a pixel's sky position through CRVAL, CRPIX and CD agrees with
the attitude's own projection."""

from __future__ import annotations

import math

import numpy as np

from service.core.attitude import quat_to_matrix
from service.core.camera import Camera
from service.core.wcs import tan_wcs


def test_the_wcs_maps_pixels_as_the_attitude_does() -> None:
    camera = Camera.from_fov(10.0, 1024, 768)
    q = np.array([0.9, 0.1, -0.3, 0.2])
    r = quat_to_matrix(q / np.linalg.norm(q))  # ICRS -> camera
    w = tan_wcs(r, camera)
    assert (w["NAXIS1"], w["NAXIS2"]) == (1024, 768)
    for x, y in ((0.0, 0.0), (1023.0, 767.0), (300.0, 600.0), (camera.cx, camera.cy)):
        v_icrs = r.T @ camera.pixel_to_vector(np.array([[x, y]]))[0]
        # FITS: intermediate world coordinates from the 1-based pixel offsets, then the gnomonic projection
        dx, dy = x + 1.0 - w["CRPIX1"], y + 1.0 - w["CRPIX2"]
        xi = math.radians(w["CD1_1"] * dx + w["CD1_2"] * dy)
        eta = math.radians(w["CD2_1"] * dx + w["CD2_2"] * dy)
        a0, d0 = math.radians(w["CRVAL1"]), math.radians(w["CRVAL2"])
        east = np.array([-math.sin(a0), math.cos(a0), 0.0])
        north = np.array([-math.sin(d0) * math.cos(a0), -math.sin(d0) * math.sin(a0), math.cos(d0)])
        centre = np.array([math.cos(d0) * math.cos(a0), math.cos(d0) * math.sin(a0), math.sin(d0)])
        v_wcs = centre + xi * east + eta * north
        v_wcs /= np.linalg.norm(v_wcs)
        assert math.degrees(math.acos(min(1.0, float(v_wcs @ v_icrs)))) * 3600 < 0.01
