"""``POST /v1/solve`` (centroids as JSON) and ``POST /v1/solve/image`` (an image upload)."""

from __future__ import annotations

from functools import partial
from typing import Annotated, Any

from fastapi import APIRouter, Depends, File, Form, UploadFile

from client.models import ErrorResponse, SolveRequest, SolveResult

from ...core import pipeline
from ...core.centroid import decode_image
from .. import convert, validation
from ..deps import CamerasDep, NavDbDep, SettingsDep, SolverDep, require_media_type
from ..errors import ApiError

router = APIRouter(prefix="/v1", tags=["solve"])

ERRORS: dict[int | str, dict[str, Any]] = {
    code: {"model": ErrorResponse, "description": text}
    for code, text in {
        400: "Malformed JSON (field `body`).",
        401: "Missing or wrong `X-API-Key` (when the server has a key).",
        413: "Body or image larger than the server's limit (field `body` or `image`).",
        415: "Wrong Content-Type (field `content-type`).",
        422: "Invalid input; `field` is its dotted path (`centroids.3.1`, `camera.fov_deg`, `method`...).",
        503: "Server busy or database unavailable; retry.",
        504: "The solve passed the time limit.",
    }.items()
}


@router.post("/solve", response_model=SolveResult, responses=ERRORS,
             dependencies=[Depends(require_media_type("application/json"))])
async def solve(req: SolveRequest, db: NavDbDep, solver: SolverDep, cameras: CamerasDep,
                settings: SettingsDep) -> dict[str, Any]:
    """Identify the stars of one frame given as centroids (one camera, or a rig via `cameras`)."""
    call = convert.frame_call(req, db, cameras, max_centroids=settings.max_centroids,
                              options=solver.options)
    sol = await solver.solve(call)
    return sol.to_dict(req.id)


@router.post("/solve/image", response_model=SolveResult, responses=ERRORS,
             dependencies=[Depends(require_media_type("multipart/form-data"))])
async def solve_image(
    image: Annotated[UploadFile, File(description="PNG, JPEG, TIFF (8/16-bit), FITS or .npy; mono or colour.")],
    db: NavDbDep, solver: SolverDep, cameras: CamerasDep, settings: SettingsDep,
    camera: Annotated[str | None, Form(max_length=4096, description=(
        "Camera: a JSON CameraSpec object, or the name of a configured camera. Or give fov_deg."))] = None,
    fov_deg: Annotated[float | None, Form(gt=0, lt=170, allow_inf_nan=False, description=(
        "Horizontal field of view, degrees; camera = this FOV at the image's size, centred. "
        "Give camera or fov_deg, not both."))] = None,
    method: Annotated[str, Form(max_length=32, description="Identification method, or 'auto'.")] = "auto",
    id: Annotated[str | None, Form(max_length=256, description="Echoed back in the result.")] = None,
) -> dict[str, Any]:
    """Detect the stars of an uploaded image and identify them."""
    if image.size is not None and image.size > settings.max_image_bytes:
        raise ApiError(413, f"image is {image.size} bytes, the limit is {settings.max_image_bytes}", "image")
    validation.one_camera(camera, fov_deg)
    data = await image.read()
    convert.check_method(db, method)
    pixels = await solver.run(partial(decode_image, data, max_pixels=settings.max_image_pixels))
    cam = convert.image_camera(camera, fov_deg, pixels.shape, cameras)
    sol = await solver.solve(partial(pipeline.solve_image, pixels, cam, db, method=method,
                                     options=solver.options))
    return sol.to_dict(id)
