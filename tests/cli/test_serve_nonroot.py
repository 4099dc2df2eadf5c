"""``skyfix serve`` as a non-root user with no writable home and a read-only package, as the
Docker image runs it (issue 12): the numba kernels must not fail at import ("no locator
available"), and the server must become healthy. Needs root here to switch the uid; skipped
elsewhere."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import tempfile
from collections.abc import Iterator
from pathlib import Path

import httpx
import pytest

from service.core.navdb import BuildConfig, build_database
from tests.api.conftest import free_port, stop_serve, wait_healthy

ROOT = Path(__file__).resolve().parents[2]


UID = GID = 65534  # nobody
SETPRIV = ["setpriv", f"--reuid={UID}", f"--regid={GID}", "--clear-groups",
           "--inh-caps=+dac_read_search", "--ambient-caps=+dac_read_search"]
"""Run as nobody. CAP_DAC_READ_SEARCH lets it read and traverse everything, as a world-readable
install would (this machine's interpreter lives under /root, mode 700); it grants no write, so
the home, the checkout and the database stay read-only to it."""


def _possible() -> bool:
    if not hasattr(os, "geteuid") or os.geteuid() != 0 or shutil.which("setpriv") is None:
        return False
    try:
        probe = subprocess.run([*SETPRIV, sys.executable, "-c", "import os, service; assert os.getuid() == 65534"],
                               cwd="/", env={"PYTHONPATH": str(ROOT), "HOME": "/nonexistent"},
                               capture_output=True, timeout=60)
    except OSError:
        return False
    return probe.returncode == 0


pytestmark = pytest.mark.skipif(not _possible(), reason="needs root and setpriv to run as another uid")


@pytest.fixture(scope="module")
def scratch() -> Iterator[Path]:
    d = Path(tempfile.mkdtemp(prefix="skyfix-nonroot-"))
    d.chmod(0o755)
    yield d
    shutil.rmtree(d, ignore_errors=True)


def _env(extra: dict[str, str]) -> dict[str, str]:
    return {"PATH": os.environ.get("PATH", "/usr/bin:/bin"), "PYTHONPATH": str(ROOT), "HOME": "/nonexistent",
            "PYTHONDONTWRITEBYTECODE": "1", **extra}


def _prefill(cache: Path) -> int:
    """Copy the kernels compiled in the checkout's __pycache__ (if any) to where numba looks
    under NUMBA_CACHE_DIR, with the stamp that says which sources they were compiled from, as
    the image's build stage fills /opt/skyfix/numba (without the stamp the server drops them
    as stale and compiles every kernel again: ~45 s)."""
    from numba.core.caching import _CacheLocator

    from service.core import _numba_cache

    n = 0
    for index in (ROOT / "service").rglob("__pycache__/*.nb[ic]"):
        src_dir = index.parent.parent
        dest = cache / _CacheLocator.get_suitable_cache_subpath(str(src_dir / "x.py"))
        dest.mkdir(parents=True, exist_ok=True)
        shutil.copy2(index, dest / index.name)
        n += 1
    core = (ROOT / "service" / "core").resolve()
    stamp = _numba_cache.stamp_path(core)
    if stamp.is_file() and stamp.read_text() == _numba_cache.sources_fingerprint(core):
        shutil.copy2(stamp, _numba_cache.stamp_path(core, str(cache)))
    return n


def test_kernels_import_with_no_writable_home_or_package(scratch: Path) -> None:
    proc = subprocess.run([*SETPRIV, sys.executable, "-c", "import service.core.attitude, service.core.match; "
                           "import os; print(os.environ.get('NUMBA_CACHE_DIR'))"],
                          capture_output=True, text=True, timeout=120, cwd="/", env=_env({}))
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert "skyfix-numba-" in proc.stdout  # a per-user cache under the temporary directory


def test_serve_as_nobody_becomes_healthy(scratch: Path) -> None:
    db = build_database(scratch / "db", BuildConfig(fov_max_deg=15.0, fov_min_deg=7.0, mag_limit=5.5,
                                                    methods=("pyramid",), epoch=2026.0))
    cache = scratch / "numba"
    _prefill(cache)
    for path in [scratch, *scratch.rglob("*")]:
        if path.is_dir():
            path.chmod(0o755)
        elif not path.is_symlink():
            path.chmod(0o644)
    for path in [cache, *cache.rglob("*")]:  # COPY --chown=skyfix: the image's cache is the user's
        os.chown(path, UID, GID)
    port = free_port()
    proc = subprocess.Popen(
        [*SETPRIV, sys.executable, "-m", "service.cli", "serve", "--port", str(port), "--db", str(db), "--log-level", "warning"],
        stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, start_new_session=True, cwd="/",
        env=_env({"NUMBA_CACHE_DIR": str(cache), "SKYFIX_DB_DIR": str(scratch / "dbdir")}))
    try:
        wait_healthy(f"http://127.0.0.1:{port}", proc)
        health = httpx.get(f"http://127.0.0.1:{port}/v1/health", timeout=5).json()
        assert health["status"] == "ok", health
    finally:
        stop_serve(proc)
