"""Pinhole camera model, optional Brown-Conrady distortion, and multi-camera rigs.

Frames: pixel x = column, y = row, the centre of the top-left pixel is (0, 0); the camera
frame has +x right, +y down and +z along the boresight out into the sky (OpenCV's).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import cv2
import numpy as np
from numba import njit

from .errors import InvalidInputError
from .types import FloatArray


@dataclass(frozen=True, slots=True)
class Camera:
    """An ideal pinhole camera plus optional lens distortion.

    Attributes
    ----------
    width, height : int
        Image size in pixels.
    f_px : float
        Focal length in pixels.
    cx, cy : float
        Principal point, px (default ``((W-1)/2, (H-1)/2)``).
    distortion : tuple of float, optional
        Brown-Conrady coefficients in OpenCV order ``(k1, k2, p1, p2[, k3])``.
    """

    width: int
    height: int
    f_px: float
    cx: float
    cy: float
    distortion: tuple[float, ...] | None = None
    _hash: int = field(default=0, init=False, repr=False, compare=False)
    """The value's hash once asked (0: not yet; see ``__hash__``)."""

    def __hash__(self) -> int:
        """The hash of the camera's value, kept: a camera seen for the first time is looked up
        by value in ~10 caches (search plan, refusal, probes, packed rows, set-up), ~0.4 us a
        hash of its six fields each time."""
        got = self._hash
        if not got:
            got = hash((self.width, self.height, self.f_px, self.cx, self.cy, self.distortion))
            _keep_hash(self, got)
        return got

    def __getstate__(self) -> tuple[Any, ...]:
        """The fields, without the kept hash (``hash(None)`` differs between processes)."""
        return self.width, self.height, self.f_px, self.cx, self.cy, self.distortion

    def __setstate__(self, state: tuple[Any, ...]) -> None:
        for name, value in zip(_FIELDS, state, strict=True):
            object.__setattr__(self, name, value)
        object.__setattr__(self, "_hash", 0)

    # ---- constructors -------------------------------------------------------------------
    @classmethod
    def from_fov(cls, fov_deg: float, width: int, height: int, **kw: Any) -> Camera:
        """Camera whose horizontal field (left edge to right edge) is ``fov_deg`` degrees."""
        f_px = (width / 2.0) / math.tan(math.radians(fov_deg) / 2.0)
        return cls._make(width, height, f_px, **kw)

    @classmethod
    def from_focal(cls, focal_mm: float, pixel_um: float, width: int, height: int, **kw: Any) -> Camera:
        """Camera from focal length (mm) and pixel pitch (micrometres)."""
        return cls._make(width, height, focal_mm * 1000.0 / pixel_um, **kw)

    @classmethod
    def _make(
        cls,
        width: int,
        height: int,
        f_px: float,
        cx: float | None = None,
        cy: float | None = None,
        distortion: Any = None,
    ) -> Camera:
        dist = check_distortion(distortion)
        cam = cls(
            int(width),
            int(height),
            float(f_px),
            (width - 1) / 2.0 if cx is None else float(cx),
            (height - 1) / 2.0 if cy is None else float(cy),
            dist,
        )
        cam.validate()
        return cam

    @classmethod
    def from_spec(cls, spec: dict[str, Any], *, field: str = "camera") -> Camera:
        """From a wire-format dict: ``width``, ``height`` and one of ``fov_deg``;
        ``focal_mm`` + ``pixel_um``; ``f_px`` (with optional ``cx``, ``cy``, ``distortion``)."""
        try:
            w, h = int(spec["width"]), int(spec["height"])
        except (KeyError, TypeError, ValueError) as exc:
            raise InvalidInputError(f"{field}.width", "width and height (px) are required") from exc
        kw = {k: spec.get(k) for k in ("cx", "cy", "distortion")}
        if spec.get("fov_deg") is not None:
            return cls.from_fov(float(spec["fov_deg"]), w, h, **kw)
        if spec.get("focal_mm") is not None and spec.get("pixel_um") is not None:
            return cls.from_focal(float(spec["focal_mm"]), float(spec["pixel_um"]), w, h, **kw)
        if spec.get("f_px") is not None:
            return cls._make(w, h, float(spec["f_px"]), **kw)
        raise InvalidInputError(field, "give fov_deg, focal_mm + pixel_um, or f_px")

    def validate(self) -> None:
        """Raise InvalidInputError unless sizes and focal length are sane."""
        if not (0 < self.width <= 65536 and 0 < self.height <= 65536):
            raise InvalidInputError("camera.width", "image size must be 1..65536 px")
        if not (math.isfinite(self.f_px) and self.f_px > 0):
            raise InvalidInputError("camera.f_px", "focal length must be positive")
        if self.fov_deg >= 170:
            raise InvalidInputError("camera.fov_deg", "field of view must be below 170 deg")
        if not (math.isfinite(self.cx) and math.isfinite(self.cy)):
            raise InvalidInputError("camera.cx", "principal point must be finite")

    def to_spec(self) -> dict[str, Any]:
        """Wire-format dict (``f_px`` form)."""
        spec: dict[str, Any] = {"width": self.width, "height": self.height, "f_px": self.f_px,
                                "cx": self.cx, "cy": self.cy}
        if self.distortion:
            spec["distortion"] = list(self.distortion)
        return spec

    # ---- properties ---------------------------------------------------------------------
    @property
    def fov_deg(self) -> float:
        """Horizontal field of view, degrees."""
        return math.degrees(2 * math.atan((self.width / 2.0) / self.f_px))

    @property
    def fov_y_deg(self) -> float:
        """Vertical field of view, degrees."""
        return math.degrees(2 * math.atan((self.height / 2.0) / self.f_px))

    @property
    def diagonal_fov_deg(self) -> float:
        """Full diagonal field of view, degrees."""
        return math.degrees(2 * math.atan(math.hypot(self.width, self.height) / 2.0 / self.f_px))

    @property
    def pixel_scale_rad(self) -> float:
        """Angle subtended by one pixel at the principal point, radians."""
        return 1.0 / self.f_px

    @property
    def matrix(self) -> FloatArray:
        """The 3x3 intrinsic matrix K."""
        return np.array([[self.f_px, 0, self.cx], [0, self.f_px, self.cy], [0, 0, 1.0]])

    # ---- projections --------------------------------------------------------------------
    def pixel_to_vector(self, xy: FloatArray) -> FloatArray:
        """Unit vectors ``(N, 3)`` in the camera frame of pixel positions ``(N, 2)``.

        Distortion, if any, is removed first (OpenCV ``undistortPoints``).
        """
        xy = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
        if self.distortion:
            norm = cv2.undistortPoints(
                xy.reshape(-1, 1, 2), self.matrix, np.asarray(self.distortion, dtype=np.float64),
                criteria=(cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 30, 1e-10),
            ).reshape(-1, 2)
        else:  # one compiled loop: ~1 us where the numpy steps below take ~8 (every frame pays it)
            return _pinhole_vectors(np.ascontiguousarray(xy), float(self.cx), float(self.cy), float(self.f_px))
        v = np.empty((len(xy), 3))
        v[:, :2] = norm
        v[:, 2] = 1.0
        v /= np.linalg.norm(v, axis=1, keepdims=True)
        return v

    def vector_to_pixel(self, v: FloatArray) -> tuple[FloatArray, np.ndarray]:
        """Pixel positions ``(N, 2)`` of camera-frame vectors ``(N, 3)``, and a mask of those
        in front of the camera (``z > 0``) and inside the image."""
        v = np.asarray(v, dtype=np.float64).reshape(-1, 3)
        z = v[:, 2]
        front = z > 1e-9
        zs = np.where(front, z, 1.0)
        xn = v[:, 0] / zs
        yn = v[:, 1] / zs
        if not front.all():
            xn[~front] = np.nan
            yn[~front] = np.nan
        if self.distortion:
            xn, yn = _distort(xn, yn, self.distortion)
        xy = np.stack([self.f_px * xn + self.cx, self.f_px * yn + self.cy], axis=1)
        inside = front & self.contains(xy)
        return xy, inside

    def contains(self, xy: FloatArray, margin_px: float = 0.0) -> np.ndarray:
        """Mask of pixel positions inside the image (pixel edges at -0.5 and W-0.5)."""
        x, y = xy[:, 0], xy[:, 1]  # NaN (behind the camera) compares False, without a warning
        return (
            (x >= -0.5 + margin_px)
            & (x <= self.width - 0.5 - margin_px)
            & (y >= -0.5 + margin_px)
            & (y <= self.height - 0.5 - margin_px)
        )


_FIELDS = ("width", "height", "f_px", "cx", "cy", "distortion")
""":class:`Camera`'s fields as pickled (its kept hash aside)."""
_keep_hash = Camera.__dict__["_hash"].__set__
"""Writes the kept hash: the slot's own setter (a frozen camera refuses ``cam._hash = h``), ~60 ns
where ``object.__setattr__`` takes ~120 (every request of the service builds its camera anew)."""

DISTORTION_LENGTHS = (4, 5, 8, 12, 14)
"""Numbers of distortion coefficients OpenCV takes: ``k1, k2, p1, p2[, k3[, k4, k5, k6[, s1..s4[, tx, ty]]]]``."""


def check_distortion(values: Any, field: str = "camera.distortion") -> tuple[float, ...] | None:
    """The Brown-Conrady coefficients ``(k1, k2, p1, p2[, k3])`` of an OpenCV-style list, or None
    when all are zero. Raises InvalidInputError unless it has 4, 5, 8, 12 or 14 finite values,
    and unless the terms after ``k3`` (rational, thin-prism, tilt; not modelled) are zero."""
    if values is None:
        return None
    try:
        coeffs = tuple(float(v) for v in values)
    except (TypeError, ValueError) as exc:
        raise InvalidInputError(field, "a list of numbers") from exc
    if len(coeffs) not in DISTORTION_LENGTHS:
        raise InvalidInputError(field, f"{len(coeffs)} values; give 4, 5, 8, 12 or 14 as OpenCV takes "
                                       "(k1, k2, p1, p2[, k3[, k4, k5, k6[, s1..s4[, tx, ty]]]])")
    if not all(math.isfinite(c) for c in coeffs):
        raise InvalidInputError(field, "values must be finite")
    if any(coeffs[5:]):
        raise InvalidInputError(field, "only k1, k2, p1, p2, k3 are modelled; the rational, thin-prism and "
                                       "tilt terms (values 6 to 14) must be 0")
    return coeffs[:5] if any(coeffs) else None


def _distort(xn: FloatArray, yn: FloatArray, coeffs: tuple[float, ...]) -> tuple[FloatArray, FloatArray]:
    """Apply Brown-Conrady distortion (OpenCV order k1, k2, p1, p2, k3) to normalised coords."""
    k = list(coeffs) + [0.0] * (5 - len(coeffs))
    k1, k2, p1, p2, k3 = k[:5]
    r2 = xn * xn + yn * yn
    radial = 1 + k1 * r2 + k2 * r2 * r2 + k3 * r2 * r2 * r2
    xd = xn * radial + 2 * p1 * xn * yn + p2 * (r2 + 2 * xn * xn)
    yd = yn * radial + p1 * (r2 + 2 * yn * yn) + 2 * p2 * xn * yn
    return xd, yd


@dataclass(frozen=True, slots=True)
class Rig:
    """Several cameras fixed to one body.

    ``mountings[i]`` is the unit quaternion ``[w, x, y, z]`` rotating body-frame vectors into
    camera ``i``'s frame (``v_cam = R(q) v_body``). Camera 0 is usually the reference, with
    identity mounting, so that the body frame is camera 0's frame.
    """

    cameras: tuple[Camera, ...]
    mountings: tuple[tuple[float, float, float, float], ...]

    def __post_init__(self) -> None:
        if len(self.cameras) != len(self.mountings) or not self.cameras:
            raise InvalidInputError("cameras", "a rig needs one mounting quaternion per camera")

    def body_vectors(self, index: int, v_cam: FloatArray) -> FloatArray:
        """Rotate camera ``index``'s vectors ``(N, 3)`` into the body frame."""
        from .attitude import quat_to_matrix

        r = quat_to_matrix(np.asarray(self.mountings[index]))
        return np.asarray(v_cam) @ r  # R^T v for row vectors


@njit(cache=True, nogil=True)
def project_rows(r_cam: np.ndarray, vec: np.ndarray, rows: np.ndarray, cam: np.ndarray, dist: np.ndarray,
                 xy: np.ndarray) -> np.ndarray:
    """Pixels of the ICRS directions ``vec[rows]`` under ``r_cam`` (ICRS -> camera), written to
    ``xy`` ``(len(rows), 2)``, for a camera as the kernels take it (``cam`` = ``f, cx, cy, w, h``;
    ``dist`` = Brown-Conrady ``k1, k2, p1, p2, k3``). Returns whether each is in front and inside
    the image (as :meth:`Camera.vector_to_pixel`).

    One call for a batch, with the arithmetic in its own loop: a kernel that called (or inlined)
    a function of array arguments once a star paid two atomic reference counts an argument a
    star, which numba keeps around the call."""
    inside = np.zeros(len(rows), np.bool_)
    k1, k2, p1, p2, k3 = dist[0], dist[1], dist[2], dist[3], dist[4]
    distorted = k1 != 0 or k2 != 0 or p1 != 0 or p2 != 0 or k3 != 0
    f, cx, cy, x_max, y_max = cam[0], cam[1], cam[2], cam[3] - 0.5, cam[4] - 0.5
    for i in range(len(rows)):
        row = rows[i]
        v0, v1, v2 = vec[row, 0], vec[row, 1], vec[row, 2]
        z = r_cam[2, 0] * v0 + r_cam[2, 1] * v1 + r_cam[2, 2] * v2
        if z <= 1e-9:
            continue
        xn = (r_cam[0, 0] * v0 + r_cam[0, 1] * v1 + r_cam[0, 2] * v2) / z
        yn = (r_cam[1, 0] * v0 + r_cam[1, 1] * v1 + r_cam[1, 2] * v2) / z
        if distorted:
            r2 = xn * xn + yn * yn
            radial = 1 + k1 * r2 + k2 * r2 * r2 + k3 * r2 * r2 * r2
            xd = xn * radial + 2 * p1 * xn * yn + p2 * (r2 + 2 * xn * xn)
            yd = yn * radial + p1 * (r2 + 2 * yn * yn) + 2 * p2 * xn * yn
            xn, yn = xd, yd
        x = f * xn + cx
        y = f * yn + cy
        xy[i, 0] = x
        xy[i, 1] = y
        inside[i] = x >= -0.5 and x <= x_max and y >= -0.5 and y <= y_max
    return inside


@njit(cache=True, nogil=True)
def _pinhole_vectors(xy: np.ndarray, cx: float, cy: float, f_px: float) -> np.ndarray:
    """Unit camera-frame vectors ``(N, 3)`` of pixel positions ``(N, 2)`` through a pinhole."""
    v = np.empty((xy.shape[0], 3))
    for i in range(xy.shape[0]):
        x = (xy[i, 0] - cx) / f_px
        y = (xy[i, 1] - cy) / f_px
        n = math.sqrt(x * x + y * y + 1.0)
        v[i, 0] = x / n
        v[i, 1] = y / n
        v[i, 2] = 1.0 / n
    return v


@njit(cache=True, nogil=True)
def brightest_first(xy: np.ndarray, flux: np.ndarray, cx: float, cy: float, f_px: float
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """A pinhole frame's stars brightest first: ``(order, xy[order], unit vectors (N, 3) in the
    camera frame, flux[order])``, ties in input order (one compiled call where the numpy steps
    took ~4 us a frame)."""
    order = np.argsort(-flux, kind="mergesort")
    n = len(order)
    xy_sorted = np.empty((n, 2))
    flux_sorted = np.empty(n)
    for i in range(n):
        xy_sorted[i, 0] = xy[order[i], 0]
        xy_sorted[i, 1] = xy[order[i], 1]
        flux_sorted[i] = flux[order[i]]
    return order, xy_sorted, _pinhole_vectors(xy_sorted, cx, cy, f_px), flux_sorted
