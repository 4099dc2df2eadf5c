"""Wire models: the one definition of skyfix's JSON, shared by the SDK and the server.

pydantic only (no numpy, no OpenCV), so the SDK installs light. The server imports these.

Frames and units
----------------
- Pixels: x = column, y = row, origin the centre of the top-left pixel.
- Quaternions: scalar first ``[w, x, y, z]``, rotating ICRS vectors into the camera frame
  (single camera) or the body frame (rig): ``v_cam = R(q) v_icrs``.
- Camera frame: +x right, +y down, +z the boresight out into the sky.
- Angles in degrees, residuals in arcseconds, times in milliseconds.
"""

from __future__ import annotations

from typing import Annotated, Any, Literal

from pydantic import BaseModel, ConfigDict, Field, field_validator, model_validator

MAX_CENTROIDS = 10_000
"""Hard cap on centroids per camera in one request (the server may set a lower one)."""

FrameId = str | int | None
Quaternion = Annotated[
    list[float],
    Field(min_length=4, max_length=4, description="Unit quaternion [w, x, y, z], scalar first."),
]
CentroidRow = Annotated[
    list[float],
    Field(min_length=2, max_length=3, description="[x, y] or [x, y, flux]: pixels; flux linear, any unit."),
]


class _Model(BaseModel):
    model_config = ConfigDict(extra="forbid", allow_inf_nan=False)


class CameraSpec(_Model):
    """A pinhole camera. Give exactly one of: ``fov_deg``; ``focal_mm`` + ``pixel_um``; ``f_px``."""

    width: int = Field(gt=0, le=65_536, description="Image width in pixels.")
    height: int = Field(gt=0, le=65_536, description="Image height in pixels.")
    fov_deg: float | None = Field(None, gt=0, lt=180, description="Horizontal field of view, degrees.")
    focal_mm: float | None = Field(None, gt=0, le=10_000, description="Focal length, millimetres.")
    pixel_um: float | None = Field(None, gt=0, le=1_000, description="Pixel pitch, micrometres.")
    f_px: float | None = Field(None, gt=0, le=1e7, description="Focal length in pixels.")
    cx: float | None = Field(None, description="Principal point x (column), px; default (width-1)/2.")
    cy: float | None = Field(None, description="Principal point y (row), px; default (height-1)/2.")
    distortion: list[float] | None = Field(
        None,
        max_length=14,
        description=("Brown-Conrady coefficients in OpenCV order: 4, 5, 8, 12 or 14 values "
                     "(k1, k2, p1, p2[, k3[, k4, k5, k6[, s1..s4[, tx, ty]]]]); terms after k3 must be 0."),
    )
    mounting_quaternion: Quaternion | None = Field(
        None,
        description="Rig cameras: rotation of body-frame vectors into this camera's frame, [w, x, y, z].",
    )

    @field_validator("distortion")
    @classmethod
    def _opencv_length(cls, v: list[float] | None) -> list[float] | None:
        if v is not None and len(v) not in (4, 5, 8, 12, 14):
            raise ValueError(f"{len(v)} values; give 4, 5, 8, 12 or 14 as OpenCV takes "
                             "(k1, k2, p1, p2[, k3[, k4, k5, k6[, s1..s4[, tx, ty]]]])")
        return v

    @model_validator(mode="after")
    def _one_focal(self) -> CameraSpec:
        given = [self.fov_deg is not None, self.focal_mm is not None or self.pixel_um is not None,
                 self.f_px is not None]
        if sum(given) != 1:
            raise ValueError("give exactly one of fov_deg, (focal_mm and pixel_um), or f_px")
        if (self.focal_mm is None) != (self.pixel_um is None):
            raise ValueError("focal_mm and pixel_um go together")
        return self


class CameraFrame(_Model):
    """One camera's centroids in a multi-camera (rig) request."""

    camera: CameraSpec | str = Field(description="Inline camera or the name of one configured on the server.")
    centroids: list[CentroidRow] = Field(
        max_length=MAX_CENTROIDS, description="This camera's star centroids, [x, y] or [x, y, flux] px rows."
    )


class AttitudeHint(_Model):
    """A prior attitude: search only near it (tracking)."""

    quaternion: Quaternion
    radius_deg: float = Field(5.0, gt=0, le=180, description="How far the boresight may be from the hint.")


VelocityKmS = Annotated[float, Field(ge=-1000, le=1000, allow_inf_nan=False)]
"""One component of an observer velocity, km/s."""


class SolveRequest(_Model):
    """Centroids in, identification out. Single camera: ``camera`` + ``centroids``; a rig:
    ``cameras`` (one centroid list per camera)."""

    id: FrameId = Field(None, description="Echoed back in the result.")
    camera: CameraSpec | str | None = Field(
        None, description="Single camera: inline, or the name of one configured on the server."
    )
    centroids: list[CentroidRow] | None = Field(
        None, max_length=MAX_CENTROIDS,
        description="Single camera: star centroids, [x, y] or [x, y, flux] rows in pixels (x = column, "
        "y = row, origin the centre of the top-left pixel); without flux, brightest first.",
    )
    cameras: list[CameraFrame] | None = Field(
        None, min_length=1, max_length=16,
        description="A rig: one centroid list per camera (instead of camera + centroids).",
    )
    method: str = Field("auto", max_length=32, description="Identification method, or 'auto'.")
    attitude_hint: AttitudeHint | None = Field(
        None, description="Prior attitude (tracking); none = lost in space."
    )
    epoch: float | None = Field(
        None, ge=1900, le=2200,
        description="Decimal year of the observation (TDB). The identified stars are moved by their proper "
        "motions from the database's epoch (/v1/info) to this one before the attitude is fitted; the stars' "
        "ra_deg/dec_deg are then at this epoch. None: the database's epoch.",
    )
    observer_velocity_km_s: list[VelocityKmS] | None = Field(
        None, min_length=3, max_length=3,
        description="The observer's velocity relative to the solar-system barycentre, [vx, vy, vz] in ICRS "
        "axes, km/s (the Earth's orbital ~30 km/s plus the spacecraft's). Stellar aberration (up to ~20 "
        "arcsec) is applied to the catalogue directions before the attitude is fitted, so the quaternion is "
        "the camera's true inertial attitude. Each component within +-1000 km/s.",
    )
    fov_max_error_deg: float | None = Field(
        None, gt=0, le=30,
        description="Single camera: how far the camera's horizontal field of view may be off, degrees. A frame "
        "not identified with the camera as given is searched again over the focal lengths this allows, and the "
        "answer is fitted with the focal length its stars say (the result's fov_deg). Each extra step is a test "
        "of its own, accepted only below the coincidence bound divided by their number. None: the camera is "
        "exact.",
    )
    centroid_sigma_px: float | None = Field(
        None, gt=0, le=20,
        description="Expected centroid error per axis, px (default 1). Sets the pattern tolerance and the "
        "match radius: raise it for faint or distorted stars.",
    )
    truth: dict[str, Any] | None = Field(
        None, description="Ignored: a recording's known answer (`skyfix sim`), accepted so that a recorded "
        "frame can be sent as it is. The server never reads it.",
    )

    @model_validator(mode="after")
    def _single_or_rig(self) -> SolveRequest:
        if self.cameras is None:
            if self.centroids is None or self.camera is None:
                raise ValueError("give camera and centroids, or cameras")
        elif self.centroids is not None or self.camera is not None:
            raise ValueError("give either camera + centroids or cameras, not both")
        elif self.fov_max_error_deg is not None:
            raise ValueError("fov_max_error_deg is for a single camera; calibrate a rig's cameras (skyfix calibrate)")
        return self


class StarResult(BaseModel):
    """One identified star."""

    centroid: int = Field(description="Index into the request's centroid list (of its camera).")
    camera: int = Field(0, description="Index of the camera in a rig request; 0 otherwise.")
    hip: int = Field(description="Hipparcos catalogue number.")
    ra_deg: float = Field(description="Right ascension (ICRS, at the database epoch), degrees.")
    dec_deg: float = Field(description="Declination (ICRS, at the database epoch), degrees.")
    mag: float = Field(description="Approximate Johnson V magnitude.")
    residual_arcsec: float = Field(description="Angle between the observed and the catalogue direction.")


NoSolutionReason = Literal[
    "too_few_stars", "camera_outside_database", "no_pattern_match", "not_proven", "time_limit"
]
"""Machine-readable reasons for ``no_solution`` (``SolveResult.reason``)."""


class SolveResult(BaseModel):
    """A solve's outcome: ``solved`` with attitude and stars, or ``no_solution`` (never a guess)."""

    id: FrameId = Field(None, description="The request's id.")
    status: Literal["solved", "no_solution"] = Field(description="Identified, or not (never a guess).")
    quaternion: list[float] | None = Field(None, description="ICRS -> camera (or body), [w, x, y, z].")
    ra_deg: float | None = Field(None, description="Boresight right ascension, degrees.")
    dec_deg: float | None = Field(None, description="Boresight declination, degrees.")
    roll_deg: float | None = Field(
        None, description="Position angle of image-up (-y) at the boresight, north through east, [0, 360)."
    )
    stars: list[StarResult] = Field(default_factory=list, description="The identified stars.")
    rms_arcsec: float | None = Field(None, description="RMS residual of the matched stars, arcsec.")
    false_match_probability: float | None = Field(
        None, description="Upper bound on the probability that the match is a coincidence."
    )
    attitude_sigma_arcsec: list[float] | None = Field(
        None, description="1-sigma attitude error about camera x, y (cross-boresight) and z (roll), arcsec."
    )
    method: str = Field(
        description="Method that produced the answer; for no_solution the last one tried, or the requested "
        "name ('auto') when the frame was refused before any method ran."
    )
    methods_tried: list[str] = Field(
        default_factory=list, description="Methods that actually ran on the frame, in order (auto's expansion)."
    )
    reason: NoSolutionReason | None = Field(
        None,
        description="Why no_solution (null when solved): too_few_stars (under 3 centroids) and "
        "camera_outside_database (no database member serves the camera's field) are refused at once, before "
        "any search; no_pattern_match (no catalogue pattern matched), not_proven (candidates checked, none "
        "proven beyond the coincidence bound), time_limit (the time limit ended the search).",
    )
    message: str | None = Field(
        None, description="The reason in words, for people (for camera_outside_database: the `skyfix db build` "
        "command that would serve the camera). Not a stable interface: parse `reason`."
    )
    timings_ms: dict[str, float] = Field(default_factory=dict, description="Per-stage wall time, ms.")
    fov_deg: float | None = Field(
        None, description="When the request gave fov_max_error_deg and the frame was identified: the horizontal "
        "field of view (deg) of the focal length fitted to the identified stars, with which the answer was made."
    )
    wcs: dict[str, float | str] | None = Field(
        None,
        description="Images only: FITS WCS (TAN) of the solution: CTYPE1/2, CRVAL1/2 (deg), CRPIX1/2 "
        "(1-based FITS pixels), CD1_1..CD2_2 (deg/px), NAXIS1/2.",
    )
    n_detected: int | None = Field(None, description="Images only: stars detected in the image.")
    centroids: list[list[float]] | None = Field(
        None, description="Images only: the detected stars [x, y, flux] (px, origin the centre of the top-left "
        "pixel); each star's `centroid` indexes this list."
    )


class Truth(BaseModel):
    """Known answer of a simulated or reference frame."""

    model_config = ConfigDict(extra="allow")
    quaternion: list[float] | None = None
    hip: list[int | None] | None = Field(None, description="HIP per centroid, null for a false star.")


class RecordedFrame(BaseModel):
    """One line of a recording (JSON Lines). ``image`` is a path relative to the recording file."""

    model_config = ConfigDict(extra="allow")
    id: FrameId = None
    time: float | str | None = None
    camera: CameraSpec | None = None
    centroids: list[list[float]] | None = None
    image: str | None = None
    cameras: list[CameraFrame] | None = None
    truth: Truth | None = None


class ErrorResponse(BaseModel):
    """Body of every 4xx/5xx: what is wrong, and where."""

    detail: str = Field(description="What is wrong.")
    field: str | None = Field(
        None, description="Dotted path of the offending input (centroids.3.1, camera.fov_deg, method)."
    )


# ---- service metadata and the WebSocket stream's control messages ---------------------------


class HealthResponse(BaseModel):
    """``GET /v1/health``: the worker is up and its navigation database is open."""

    status: Literal["ok"] = Field("ok", description="Always ok (a worker that cannot serve does not answer).")
    version: str = Field(description="skyfix version of the server.")
    n_stars: int = Field(description="Navigation stars in the open database.")
    methods: list[str] = Field(description="Methods whose tables the open database holds.")
    pid: int = Field(description="Process id of the worker that answered (several with --workers N).")
    uptime_s: float = Field(description="Seconds since this worker started.")


class Limits(BaseModel):
    """Request limits the server enforces (4xx beyond them)."""

    max_body_bytes: int = Field(description="Largest JSON request body, bytes.")
    max_image_bytes: int = Field(description="Largest uploaded image file, bytes.")
    max_image_pixels: int = Field(description="Largest decoded image, width x height pixels.")
    max_centroids: int = Field(description="Most centroids per camera in one frame.")
    solve_timeout_s: float = Field(description="Time limit of one solve, seconds (504 beyond it).")


class InfoResponse(BaseModel):
    """``GET /v1/info``: what this server can solve with."""

    version: str = Field(description="skyfix version of the server.")
    database: dict[str, object] = Field(description="The navigation database's manifest (build parameters).")
    methods: list[str] = Field(description="Every registered identification method ('auto' picks one).")
    database_methods: list[str] = Field(description="Methods whose tables the open database holds.")
    cameras: dict[str, CameraSpec] = Field(description="Cameras configured on the server, by name.")
    limits: Limits = Field(description="Request limits (4xx beyond them).")


class StreamConfig(_Model):
    """WebSocket text message ``{"type": "config", ...}``: defaults for the frames that follow.

    Fields left out keep their current value. Binary frames (images) need ``camera`` or
    ``fov_deg`` from here or from the connection's query parameters.
    """

    type: Literal["config"]
    camera: CameraSpec | str | None = Field(
        None, description="Camera for image frames: inline or a configured name."
    )
    fov_deg: float | None = Field(
        None, gt=0, lt=180, description="Image frames without a camera: horizontal field of view, degrees."
    )
    method: str | None = Field(None, max_length=32, description="Identification method, or 'auto'.")
    track: bool | None = Field(None, description="Use each solution as the attitude hint of the next frame.")
    hint_radius_deg: float | None = Field(
        None, gt=0, le=180, description="Search radius around a tracking hint, degrees."
    )


class StreamAck(BaseModel):
    """Reply to a ``config`` message: the connection's settings now in force."""

    status: Literal["config"] = "config"
    camera: CameraSpec | str | None = None
    fov_deg: float | None = None
    method: str = "auto"
    track: bool = False
    hint_radius_deg: float


class StreamError(BaseModel):
    """Reply to a WebSocket message that could not be solved; the stream goes on.

    It has no ``status`` key: a reply with ``status`` is a ``SolveResult`` (or a ``StreamAck``).
    """

    id: FrameId = Field(None, description="The frame's id (its message number if it had none).")
    code: int = Field(
        description="The HTTP status the same input would get over REST (400, 413, 422, 504...)."
    )
    detail: str
    field: str | None = None
