"""Server settings: environment variables with the ``SKYFIX_`` prefix (pydantic-settings).

No settings object exists at import time; ``get_settings()`` reads the environment once per
process (each ``--workers`` process reads the same variables), and tests pass ``Settings(...)``
to ``create_app`` directly.
"""

from __future__ import annotations

import ipaddress
from functools import lru_cache
from pathlib import Path

from pydantic import Field, SecretStr, model_validator
from pydantic_settings import BaseSettings, SettingsConfigDict

from client.models import MAX_CENTROIDS, CameraSpec

MiB = 1024 * 1024


def is_loopback(host: str) -> bool:
    """True for ``localhost`` and loopback addresses (127.0.0.0/8, ::1)."""
    if host.strip().lower() == "localhost":
        return True
    try:
        return ipaddress.ip_address(host.strip("[]")).is_loopback
    except ValueError:
        return False


class Settings(BaseSettings):
    """Everything the server can be told; each field is also ``SKYFIX_<FIELD>`` in the environment."""

    model_config = SettingsConfigDict(env_prefix="SKYFIX_", extra="ignore", frozen=True)

    host: str = Field("127.0.0.1", description="Interface to bind; anything but loopback needs api_key.")
    port: int = Field(8000, ge=0, le=65535)
    workers: int = Field(1, ge=1, le=64, description="Server processes sharing the memory-mapped database.")
    db_path: Path | None = Field(None, description="Navigation database directory; default: built on first use.")
    api_key: SecretStr | None = Field(None, description="If set, every request but /v1/health needs X-API-Key.")
    max_body_bytes: int = Field(2 * MiB, ge=1024, le=256 * MiB, description="Largest JSON body, bytes.")
    max_image_bytes: int = Field(32 * MiB, ge=1024, le=1024 * MiB, description="Largest image upload, bytes.")
    max_image_pixels: int = Field(50_000_000, ge=1, le=1_000_000_000, description="Largest decoded image, px.")
    max_centroids: int = Field(2000, ge=3, le=MAX_CENTROIDS, description="Most centroids per camera.")
    solve_timeout_s: float = Field(
        10.0, gt=0, le=600, description="Hard time limit of one request's engine work (decode, solve), s: 504."
    )
    search_timeout_ms: float = Field(
        500.0, gt=0, le=600_000, description="The engine stops searching after this long: no_solution."
    )
    solve_threads: int = Field(
        2, ge=1, le=256,
        description="Solves running at once in each worker. The GIL lets one run Python at a time, so "
        "more threads add contention, not speed; the second keeps one slow solve from stalling the worker. "
        "Scale with --workers (one per core).",
    )
    max_connections: int = Field(
        256, ge=1, le=100_000, description="HTTP requests and WebSocket streams served at once by each worker; "
        "past it REST gets 503 with Retry-After and a stream is closed with 1013 (/v1/health, /metrics exempt)."
    )
    max_in_flight: int = Field(
        8, ge=1, le=1024, description="Messages a stream may have read and not yet answered; then the server "
        "stops reading that connection (back-pressure)."
    )
    header_timeout_s: float = Field(
        10.0, gt=0, le=3600, description="A request's headers must arrive within this, s (408 and close)."
    )
    drain_timeout_s: float = Field(
        10.0, gt=0, le=3600, description="On SIGTERM, time for streams to answer what they have read, s."
    )
    cameras: dict[str, CameraSpec] = Field(
        default_factory=dict, description="Named cameras (JSON: name -> camera spec, mounting optional)."
    )

    @model_validator(mode="after")
    def _key_off_loopback(self) -> Settings:
        if self.api_key is not None and not self.api_key.get_secret_value():
            object.__setattr__(self, "api_key", None)
        if self.api_key is None and not is_loopback(self.host):
            raise ValueError(
                f"binding {self.host} (not loopback) requires an API key: set SKYFIX_API_KEY"
            )
        return self

    @property
    def max_upload_bytes(self) -> int:
        """Body limit of the image upload: the image plus room for the form fields."""
        return self.max_image_bytes + 64 * 1024

    @property
    def ws_max_message_bytes(self) -> int:
        """Largest WebSocket message: a JSON frame or an image."""
        return max(self.max_body_bytes, self.max_image_bytes)


@lru_cache
def get_settings() -> Settings:
    """The process's settings, read from the environment once."""
    return Settings()
