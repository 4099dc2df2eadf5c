"""The FITS world coordinate system of a solved frame (gnomonic TAN, no distortion terms)."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from .attitude import radec_roll
from .camera import Camera


def tan_wcs(r: np.ndarray, camera: Camera) -> dict[str, Any]:
    """FITS WCS (gnomonic TAN) of an ICRS -> camera attitude: the reference pixel is the
    principal point; CD maps FITS pixel offsets to (east, north) tangent-plane degrees.
    Lens distortion, if any, is not represented (no SIP terms)."""
    ra, dec, _ = radec_roll(r)
    a, d = math.radians(ra), math.radians(dec)
    east = np.array([-math.sin(a), math.cos(a), 0.0])
    north = np.array([-math.sin(d) * math.cos(a), -math.sin(d) * math.sin(a), math.cos(d)])
    k = math.degrees(1.0) / camera.f_px
    return {
        "CTYPE1": "RA---TAN", "CTYPE2": "DEC--TAN",
        "CRVAL1": ra, "CRVAL2": dec,
        "CRPIX1": camera.cx + 1.0, "CRPIX2": camera.cy + 1.0,
        "CD1_1": k * float(r[0] @ east), "CD1_2": k * float(r[1] @ east),
        "CD2_1": k * float(r[0] @ north), "CD2_2": k * float(r[1] @ north),
        "NAXIS1": camera.width, "NAXIS2": camera.height,
    }


__all__ = ["tan_wcs"]
