"""Settings from the environment; refusing to start when the configuration is unsafe or wrong."""

from __future__ import annotations

import pytest
from pydantic import ValidationError

from service.api import Settings
from service.api.settings import is_loopback

from .conftest import CAMERA_SPEC, start_server


@pytest.mark.parametrize(("host", "loopback"), [
    ("127.0.0.1", True), ("127.8.9.10", True), ("::1", True), ("[::1]", True), ("localhost", True),
    ("0.0.0.0", False), ("::", False), ("192.168.1.20", False), ("example.org", False)])
def test_is_loopback(host: str, loopback: bool) -> None:
    assert is_loopback(host) is loopback


def test_defaults_bind_loopback_without_a_key(monkeypatch: pytest.MonkeyPatch) -> None:
    for var in ("SKYFIX_HOST", "SKYFIX_API_KEY", "SKYFIX_DB_PATH", "SKYFIX_CAMERAS"):
        monkeypatch.delenv(var, raising=False)
    s = Settings()
    assert (s.host, s.api_key, s.db_path, s.cameras) == ("127.0.0.1", None, None, {})


@pytest.mark.parametrize("key", [None, ""])
def test_public_bind_needs_a_key(monkeypatch: pytest.MonkeyPatch, key: str | None) -> None:
    monkeypatch.delenv("SKYFIX_API_KEY", raising=False)
    with pytest.raises(ValidationError, match="SKYFIX_API_KEY"):
        Settings(host="0.0.0.0", api_key=key)
    s = Settings(host="0.0.0.0", api_key="s3cret")
    assert s.api_key is not None and "s3cret" not in repr(s)


def test_environment(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("SKYFIX_CAMERAS", '{"star": {"width": 640, "height": 480, "f_px": 2000,'
                                         ' "mounting_quaternion": [0, 1, 0, 0]}}')
    monkeypatch.setenv("SKYFIX_MAX_CENTROIDS", "64")
    monkeypatch.setenv("SKYFIX_SOLVE_TIMEOUT_S", "2.5")
    monkeypatch.setenv("SKYFIX_DB_PATH", "/srv/navdb")
    s = Settings()
    assert s.cameras["star"].f_px == 2000 and s.cameras["star"].mounting_quaternion == [0, 1, 0, 0]
    assert (s.max_centroids, s.solve_timeout_s, str(s.db_path)) == (64, 2.5, "/srv/navdb")
    monkeypatch.setenv("SKYFIX_MAX_CENTROIDS", "-1")
    with pytest.raises(ValidationError, match="max_centroids"):
        Settings()


def test_a_bad_named_camera_stops_the_server_starting(settings: Settings) -> None:
    bad = Settings(**{**settings.model_dump(), "cameras": {"wide": {**CAMERA_SPEC, "fov_deg": 175}}})
    with pytest.raises(RuntimeError, match="did not start"):
        start_server(bad)


def test_a_missing_database_stops_the_server_starting(settings: Settings, tmp_path: object) -> None:
    bad = Settings(**{**settings.model_dump(), "db_path": f"{tmp_path}/none"})
    with pytest.raises(RuntimeError, match="did not start"):
        start_server(bad)
