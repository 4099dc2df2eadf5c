"""Image -> star centroids: decoding (:func:`decode_image`) and detection (:func:`extract`).

>>> import numpy as np
>>> from service.core.centroid import extract
>>> yy, xx = np.mgrid[0:32, 0:32]
>>> img = 10.0 + 500.0 * np.exp(-((xx - 12.3) ** 2 + (yy - 20.6) ** 2) / 2.0)
>>> det = extract(img)
>>> np.round(det.centroids.xy, 2).tolist()
[[12.3, 20.6]]
"""

from __future__ import annotations

from .decode import decode_image, load_image
from .detect import Detections, extract

__all__ = ["Detections", "decode_image", "extract", "load_image"]
