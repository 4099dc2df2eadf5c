"""`Client` and `AsyncClient`: the skyfix REST API over httpx.

Both sit on `_BaseClient`, which builds requests, decides on retries and parses answers; the
two subclasses only do the I/O (blocking or ``await``). Pass ``transport=`` to plug in any
httpx transport (``httpx.MockTransport``, ``httpx.ASGITransport``) instead of the network.
"""

from __future__ import annotations

import asyncio
import json
import os
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import IO, TYPE_CHECKING, Any, TypeVar

import httpx
import pydantic

from ._config import DEFAULT_TIMEOUT_S, DEFAULT_URL, Retry, as_retry, parse_retry_after
from ._exceptions import (
    SkyfixConnectError,
    SkyfixHTTPError,
    SkyfixProtocolError,
    SkyfixTimeoutError,
    SkyfixTransportError,
)
from .models import (
    AttitudeHint,
    CameraFrame,
    CameraSpec,
    HealthResponse,
    InfoResponse,
    SolveRequest,
    SolveResult,
)

if TYPE_CHECKING:
    from ._stream import AsyncStream, Stream

__all__ = ["AsyncClient", "Client"]

API_KEY_HEADER = "X-API-Key"
USER_AGENT = "skyfix-client/0.1"

CameraLike = CameraSpec | Mapping[str, Any] | str
_M = TypeVar("_M", bound=pydantic.BaseModel)
ImageLike = bytes | str | os.PathLike[str] | IO[bytes]

# Failures where the request certainly or harmlessly did not complete: solving is a pure
# function of the request, so sending it again is safe.
_RETRYABLE_EXC = (httpx.ConnectError, httpx.ConnectTimeout, httpx.RemoteProtocolError,
                  httpx.ReadError, httpx.WriteError)


@dataclass(frozen=True, slots=True)
class _RequestSpec:
    method: str
    path: str
    json: Any = None
    data: dict[str, str] | None = None
    files: dict[str, tuple[str, bytes, str]] | None = None

    def kwargs(self) -> dict[str, Any]:
        out: dict[str, Any] = {}
        if self.json is not None:
            out["json"] = self.json
        if self.data is not None:
            out["data"] = self.data
        if self.files is not None:
            out["files"] = self.files
        return out


def ws_url(base_url: str, path: str = "/v1/stream") -> str:
    """The WebSocket URL of ``path`` on the server at ``base_url`` (http -> ws, https -> wss)."""
    url = httpx.URL(base_url)
    scheme = {"http": "ws", "https": "wss", "ws": "ws", "wss": "wss"}.get(url.scheme)
    if scheme is None:
        raise ValueError(f"unsupported URL scheme {url.scheme!r}")
    return str(url.copy_with(scheme=scheme, path=url.path.rstrip("/") + path))


def _camera_model(camera: CameraLike | None) -> CameraSpec | str | None:
    if camera is None or isinstance(camera, CameraSpec | str):
        return camera
    return CameraSpec.model_validate(dict(camera))


def _read_image(image: ImageLike, filename: str | None) -> tuple[bytes, str]:
    if isinstance(image, bytes | bytearray | memoryview):
        return bytes(image), filename or "image"
    if isinstance(image, str | os.PathLike):
        path = Path(image)
        return path.read_bytes(), filename or path.name
    data = image.read()
    return data, filename or Path(getattr(image, "name", "image") or "image").name


_CONTENT_TYPES = {".png": "image/png", ".tif": "image/tiff", ".tiff": "image/tiff",
                  ".fits": "application/fits", ".fit": "application/fits", ".fts": "application/fits",
                  ".jpg": "image/jpeg", ".jpeg": "image/jpeg"}


def _error_from_response(response: httpx.Response) -> SkyfixHTTPError:
    """``SkyfixHTTPError`` carrying the server's message and field, whatever the body's shape."""
    detail: str = response.reason_phrase or "error"
    field: str | None = None
    try:
        body = response.json()
    except (json.JSONDecodeError, UnicodeDecodeError):
        text = response.text.strip()
        if text:
            detail = text[:500]
        return SkyfixHTTPError(response.status_code, detail, None)
    if isinstance(body, dict) and "detail" in body:
        raw = body["detail"]
        field = body.get("field") if isinstance(body.get("field"), str) else None
        if isinstance(raw, str):
            detail = raw
        elif isinstance(raw, list) and raw and isinstance(raw[0], dict):
            # FastAPI's default validation body: [{"loc": [...], "msg": ..., "type": ...}, ...]
            first = raw[0]
            detail = str(first.get("msg", raw))
            loc = [str(p) for p in first.get("loc", []) if p not in ("body", "query", "path")]
            field = field or (".".join(loc) or None)
        else:
            detail = json.dumps(raw)[:500]
    return SkyfixHTTPError(response.status_code, detail, field)


class _BaseClient:
    """Request building, retry decisions and answer parsing shared by both clients."""

    def __init__(self, *, base_url: str, api_key: str | None, timeout: float | httpx.Timeout | None,
                 retries: Retry | int | None, headers: Mapping[str, str] | None) -> None:
        self.base_url = str(base_url).rstrip("/")
        self.api_key = api_key
        self.retry = as_retry(retries)
        self.timeout = timeout
        self._headers = {"User-Agent": USER_AGENT, **(dict(headers) if headers else {})}
        if api_key:
            self._headers[API_KEY_HEADER] = api_key

    # -- requests ---------------------------------------------------------------------------

    @staticmethod
    def build_solve_request(
        centroids: Sequence[Sequence[float]] | SolveRequest | None = None,
        camera: CameraLike | None = None,
        *,
        cameras: Sequence[CameraFrame | Mapping[str, Any]] | None = None,
        id: str | int | None = None,
        method: str = "auto",
        attitude_hint: AttitudeHint | Mapping[str, Any] | None = None,
        epoch: float | None = None,
        observer_velocity_km_s: Sequence[float] | None = None,
        fov_max_error_deg: float | None = None,
    ) -> SolveRequest:
        """Validate the arguments of a solve into a `SolveRequest` (raises on misuse)."""
        if isinstance(centroids, SolveRequest):
            return centroids
        return SolveRequest.model_validate({
            "id": id,
            "camera": _camera_model(camera),
            "centroids": [list(map(float, row)) for row in centroids] if centroids is not None else None,
            "cameras": list(cameras) if cameras is not None else None,
            "method": method,
            "attitude_hint": attitude_hint,
            "epoch": epoch,
            "observer_velocity_km_s": list(observer_velocity_km_s) if observer_velocity_km_s is not None else None,
            "fov_max_error_deg": fov_max_error_deg,
        })

    def _solve_spec(self, request: SolveRequest) -> _RequestSpec:
        return _RequestSpec("POST", "/v1/solve", json=request.model_dump(mode="json", exclude_none=True))

    def _image_spec(self, image: ImageLike, *, camera: CameraLike | None, fov_deg: float | None,
                    id: str | int | None, method: str, filename: str | None,
                    content_type: str | None) -> _RequestSpec:
        data, name = _read_image(image, filename)
        ctype = content_type or _CONTENT_TYPES.get(Path(name).suffix.lower(), "application/octet-stream")
        form: dict[str, str] = {"method": method}
        cam = _camera_model(camera)
        if isinstance(cam, CameraSpec):
            form["camera"] = cam.model_dump_json(exclude_none=True)
        elif isinstance(cam, str):
            form["camera"] = cam
        if id is not None:
            form["id"] = str(id)
        if fov_deg is not None:
            form["fov_deg"] = repr(float(fov_deg))
        return _RequestSpec("POST", "/v1/solve/image", data=form, files={"image": (name, data, ctype)})

    # -- retries ----------------------------------------------------------------------------

    def _delay_after_exception(self, failures: int, exc: httpx.TransportError) -> float | None:
        """Seconds to wait before the next try after ``exc``, or None to give up."""
        if not isinstance(exc, _RETRYABLE_EXC) or failures >= self.retry.attempts:
            return None
        return self.retry.delay_s(failures)

    def _delay_after_response(self, failures: int, response: httpx.Response) -> float | None:
        if response.status_code not in self.retry.statuses or failures >= self.retry.attempts:
            return None
        retry_after = parse_retry_after(response.headers.get("Retry-After"))
        return self.retry.delay_s(failures, retry_after_s=retry_after)

    @staticmethod
    def _transport_error(exc: httpx.TransportError, url: str, tries: int) -> SkyfixTransportError:
        what = f"{type(exc).__name__}: {exc}" if str(exc) else type(exc).__name__
        msg = f"{url}: {what} (after {tries} attempt{'s' if tries != 1 else ''})"
        if isinstance(exc, httpx.TimeoutException) and not isinstance(exc, httpx.ConnectTimeout):
            return SkyfixTimeoutError(msg)
        return SkyfixConnectError(msg)

    # -- answers ----------------------------------------------------------------------------

    @staticmethod
    def _json(response: httpx.Response) -> Any:
        if response.status_code >= 400:
            raise _error_from_response(response)
        try:
            return response.json()
        except (json.JSONDecodeError, UnicodeDecodeError) as exc:
            raise SkyfixProtocolError(
                f"{response.request.url}: expected JSON, got {response.headers.get('content-type')!r}"
            ) from exc

    @classmethod
    def _parse(cls, response: httpx.Response, model: type[_M]) -> _M:
        body = cls._json(response)
        try:
            return model.model_validate(body)
        except pydantic.ValidationError as exc:
            raise SkyfixProtocolError(f"{response.request.url}: not a {model.__name__}: {exc}") from exc


class Client(_BaseClient):
    """A blocking client for the skyfix REST API.

    ```python
    from client import Client

    with Client("http://127.0.0.1:8000") as sky:
        result = sky.solve([[512.3, 300.1], [100.0, 220.5], ...],
                           camera={"width": 1024, "height": 768, "fov_deg": 11.4})
        if result.status == "solved":
            print(result.quaternion, [s.hip for s in result.stars])
    ```

    **Parameters:**

    * **base_url** - the server, e.g. ``"http://127.0.0.1:8000"``.
    * **api_key** - sent as the ``X-API-Key`` header when the server requires one.
    * **timeout** - seconds (or an ``httpx.Timeout``) for each attempt.
    * **retries** - a `Retry` policy, or the number of retries (``0`` = try once).
    * **transport** - any httpx transport, e.g. ``httpx.ASGITransport(app)`` or a mock.
    * **headers** - extra headers for every request.
    """

    def __init__(self, base_url: str = DEFAULT_URL, *, api_key: str | None = None,
                 timeout: float | httpx.Timeout | None = DEFAULT_TIMEOUT_S,
                 retries: Retry | int | None = None, transport: httpx.BaseTransport | None = None,
                 headers: Mapping[str, str] | None = None) -> None:
        super().__init__(base_url=base_url, api_key=api_key, timeout=timeout, retries=retries,
                         headers=headers)
        self._http = httpx.Client(base_url=self.base_url, timeout=timeout, transport=transport,
                                  headers=self._headers)

    def __enter__(self) -> Client:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()

    def close(self) -> None:
        """Close the connection pool."""
        self._http.close()

    def _send(self, spec: _RequestSpec) -> httpx.Response:
        failures = 0
        while True:
            try:
                response = self._http.request(spec.method, spec.path, **spec.kwargs())
            except httpx.TransportError as exc:
                failures += 1
                wait = self._delay_after_exception(failures, exc)
                if wait is None:
                    raise self._transport_error(exc, self.base_url + spec.path, failures) from exc
                time.sleep(wait)
                continue
            failures += 1
            wait = self._delay_after_response(failures, response)
            if wait is None:
                return response
            response.close()
            time.sleep(wait)

    def solve(
        self,
        centroids: Sequence[Sequence[float]] | SolveRequest | None = None,
        camera: CameraLike | None = None,
        *,
        cameras: Sequence[CameraFrame | Mapping[str, Any]] | None = None,
        id: str | int | None = None,
        method: str = "auto",
        attitude_hint: AttitudeHint | Mapping[str, Any] | None = None,
        epoch: float | None = None,
        observer_velocity_km_s: Sequence[float] | None = None,
        fov_max_error_deg: float | None = None,
    ) -> SolveResult:
        """Identify stars from centroids (``POST /v1/solve``).

        Give ``centroids`` (rows ``[x, y]`` or ``[x, y, flux]``, px) and ``camera`` (a
        `CameraSpec`, a dict, or the name of a camera configured on the server), or
        ``cameras`` for a rig, or a ready `SolveRequest` as the first argument.
        ``fov_max_error_deg``: how far the camera's horizontal field may be off (deg); the server
        then searches focal lengths and ``SolveResult.fov_deg`` is the one fitted.
        Returns a `SolveResult`: ``status`` is ``"solved"`` or ``"no_solution"``.
        Raises `SkyfixHTTPError` when the server refuses the request.
        """
        request = self.build_solve_request(centroids, camera, cameras=cameras, id=id, method=method,
                                           attitude_hint=attitude_hint, epoch=epoch,
                                           observer_velocity_km_s=observer_velocity_km_s,
                                           fov_max_error_deg=fov_max_error_deg)
        return self._parse(self._send(self._solve_spec(request)), SolveResult)

    def solve_image(self, image: ImageLike, *, camera: CameraLike | None = None, fov_deg: float | None = None,
                    id: str | int | None = None, method: str = "auto", filename: str | None = None,
                    content_type: str | None = None) -> SolveResult:
        """Detect stars in an image and identify them (``POST /v1/solve/image``).

        ``image`` is the file's bytes, a path, or a binary file object (PNG, JPEG, TIFF, FITS).
        Give ``camera`` (spec, dict or configured name) or just ``fov_deg`` (horizontal field of
        view; the camera is then that FOV at the image's size, centred).
        """
        spec = self._image_spec(image, camera=camera, fov_deg=fov_deg, id=id, method=method,
                                filename=filename, content_type=content_type)
        return self._parse(self._send(spec), SolveResult)

    def health(self) -> HealthResponse:
        """``GET /v1/health``: version, database size, worker pid and uptime."""
        return self._parse(self._send(_RequestSpec("GET", "/v1/health")), HealthResponse)

    def info(self) -> InfoResponse:
        """``GET /v1/info``: the database, methods, cameras and limits of the server."""
        return self._parse(self._send(_RequestSpec("GET", "/v1/info")), InfoResponse)

    def stream(self, **kwargs: Any) -> Stream:
        """A `Stream` to this server's ``/v1/stream`` with the same key, timeout and retry policy;
        keyword arguments go to `Stream`."""
        from ._stream import Stream

        kwargs.setdefault("api_key", self.api_key)
        kwargs.setdefault("retries", self.retry)
        if isinstance(self.timeout, int | float):
            kwargs.setdefault("timeout", float(self.timeout))
        return Stream(ws_url(self.base_url), **kwargs)


class AsyncClient(_BaseClient):
    """The `Client` API with ``async`` methods, for many frames in flight at once.

    ```python
    async with AsyncClient("http://127.0.0.1:8000") as sky:
        results = await asyncio.gather(*(sky.solve(c, camera=cam) for c in frames))
    ```

    Parameters as for `Client`; ``transport`` is an ``httpx.AsyncBaseTransport``.
    """

    def __init__(self, base_url: str = DEFAULT_URL, *, api_key: str | None = None,
                 timeout: float | httpx.Timeout | None = DEFAULT_TIMEOUT_S,
                 retries: Retry | int | None = None, transport: httpx.AsyncBaseTransport | None = None,
                 headers: Mapping[str, str] | None = None, max_connections: int = 100) -> None:
        super().__init__(base_url=base_url, api_key=api_key, timeout=timeout, retries=retries,
                         headers=headers)
        limits = httpx.Limits(max_connections=max_connections, max_keepalive_connections=max_connections)
        self._http = httpx.AsyncClient(base_url=self.base_url, timeout=timeout, transport=transport,
                                       headers=self._headers, limits=limits)

    async def __aenter__(self) -> AsyncClient:
        return self

    async def __aexit__(self, *exc_info: object) -> None:
        await self.aclose()

    async def aclose(self) -> None:
        """Close the connection pool."""
        await self._http.aclose()

    async def _send(self, spec: _RequestSpec) -> httpx.Response:
        failures = 0
        while True:
            try:
                response = await self._http.request(spec.method, spec.path, **spec.kwargs())
            except httpx.TransportError as exc:
                failures += 1
                wait = self._delay_after_exception(failures, exc)
                if wait is None:
                    raise self._transport_error(exc, self.base_url + spec.path, failures) from exc
                await asyncio.sleep(wait)
                continue
            failures += 1
            wait = self._delay_after_response(failures, response)
            if wait is None:
                return response
            await response.aclose()
            await asyncio.sleep(wait)

    async def solve(
        self,
        centroids: Sequence[Sequence[float]] | SolveRequest | None = None,
        camera: CameraLike | None = None,
        *,
        cameras: Sequence[CameraFrame | Mapping[str, Any]] | None = None,
        id: str | int | None = None,
        method: str = "auto",
        attitude_hint: AttitudeHint | Mapping[str, Any] | None = None,
        epoch: float | None = None,
        observer_velocity_km_s: Sequence[float] | None = None,
        fov_max_error_deg: float | None = None,
    ) -> SolveResult:
        """As `Client.solve`."""
        request = self.build_solve_request(centroids, camera, cameras=cameras, id=id, method=method,
                                           attitude_hint=attitude_hint, epoch=epoch,
                                           observer_velocity_km_s=observer_velocity_km_s,
                                           fov_max_error_deg=fov_max_error_deg)
        return self._parse(await self._send(self._solve_spec(request)), SolveResult)

    async def solve_image(self, image: ImageLike, *, camera: CameraLike | None = None,
                          fov_deg: float | None = None, id: str | int | None = None, method: str = "auto",
                          filename: str | None = None, content_type: str | None = None) -> SolveResult:
        """As `Client.solve_image` (the file is read before sending)."""
        spec = self._image_spec(image, camera=camera, fov_deg=fov_deg, id=id, method=method,
                                filename=filename, content_type=content_type)
        return self._parse(await self._send(spec), SolveResult)

    async def health(self) -> HealthResponse:
        """As `Client.health`."""
        return self._parse(await self._send(_RequestSpec("GET", "/v1/health")), HealthResponse)

    async def info(self) -> InfoResponse:
        """As `Client.info`."""
        return self._parse(await self._send(_RequestSpec("GET", "/v1/info")), InfoResponse)

    def stream(self, **kwargs: Any) -> AsyncStream:
        """An `AsyncStream` to this server's ``/v1/stream`` (use ``async with``)."""
        from ._stream import AsyncStream

        kwargs.setdefault("api_key", self.api_key)
        kwargs.setdefault("retries", self.retry)
        if isinstance(self.timeout, int | float):
            kwargs.setdefault("timeout", float(self.timeout))
        return AsyncStream(ws_url(self.base_url), **kwargs)
