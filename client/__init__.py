"""skyfix client: the REST and WebSocket API, recorded frames, replay and CCSDS attitude output.

```python
from client import Client

with Client("http://127.0.0.1:8000") as sky:
    result = sky.solve(centroids, camera={"width": 1024, "height": 768, "fov_deg": 11.4})
```

Needs only httpx, websockets and pydantic (no numpy). Public modules: ``client.models`` (the
wire models the server also uses), ``client.recording`` (JSON Lines recordings),
``client.replay`` (replaying a recording against a server) and ``client.cli`` (the
``skyfix replay`` command). Everything else lives in private modules and is re-exported here.
See docs/client.md.
"""

from ._aem import AemRecord, format_aem, quaternion_to_ccsds, write_aem
from ._attitude import AttitudeError, attitude_error
from ._client import AsyncClient, Client
from ._config import Retry
from ._exceptions import (
    RecordingError,
    SkyfixClientError,
    SkyfixConnectError,
    SkyfixFrameError,
    SkyfixHTTPError,
    SkyfixProtocolError,
    SkyfixStreamError,
    SkyfixTimeoutError,
    SkyfixTransportError,
)
from ._report import Distribution, FrameReport, ReplayReport, WrongBars
from ._stream import AsyncStream, Stream
from ._time import parse_frame_time
from .models import (
    AttitudeHint,
    CameraFrame,
    CameraSpec,
    ErrorResponse,
    HealthResponse,
    InfoResponse,
    RecordedFrame,
    SolveRequest,
    SolveResult,
    StarResult,
    Truth,
)
from .recording import RecordingWriter, read_recording, resolve_image

__all__ = [
    "AemRecord",
    "AsyncClient",
    "AsyncStream",
    "attitude_error",
    "AttitudeError",
    "AttitudeHint",
    "CameraFrame",
    "CameraSpec",
    "Client",
    "Distribution",
    "ErrorResponse",
    "format_aem",
    "FrameReport",
    "HealthResponse",
    "InfoResponse",
    "parse_frame_time",
    "quaternion_to_ccsds",
    "read_recording",
    "RecordedFrame",
    "RecordingError",
    "RecordingWriter",
    "ReplayReport",
    "resolve_image",
    "Retry",
    "SkyfixClientError",
    "SkyfixConnectError",
    "SkyfixFrameError",
    "SkyfixHTTPError",
    "SkyfixProtocolError",
    "SkyfixStreamError",
    "SkyfixTimeoutError",
    "SkyfixTransportError",
    "SolveRequest",
    "SolveResult",
    "StarResult",
    "Stream",
    "Truth",
    "write_aem",
    "WrongBars",
]

# Show the public path in reprs and docs (as httpx does); the wire models keep client.models.
for _name in __all__:
    _obj = globals()[_name]
    if getattr(_obj, "__module__", "").startswith("client._"):
        try:
            _obj.__module__ = "client"
        except (AttributeError, TypeError):  # pragma: no cover - builtins, slotted objects
            pass
del _name, _obj
