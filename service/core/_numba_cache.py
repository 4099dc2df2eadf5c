"""Where numba caches compiled kernels, when the usual places are read-only.

numba writes its cache beside the source (``__pycache__``) or under the user's home; when
neither is writable (a non-root user in a container, the package installed read-only, no home
directory), every ``cache=True`` kernel fails at import with "cannot cache function ...: no
locator available". ``ensure_writable_cache`` then points ``NUMBA_CACHE_DIR`` at a per-user
directory under the system's temporary directory, before numba reads its configuration. An
explicit ``NUMBA_CACHE_DIR`` is left alone (the Docker image sets one, pre-filled at build).
"""

from __future__ import annotations

import os
import sys
import tempfile
from pathlib import Path


def _writable(path: Path) -> bool:
    """True if a file can be created in ``path`` (made if missing)."""
    try:
        path.mkdir(parents=True, exist_ok=True)
        with tempfile.TemporaryFile(dir=path):
            return True
    except OSError:
        return False


def ensure_writable_cache(package_dir: Path | None = None) -> str | None:
    """Set ``NUMBA_CACHE_DIR`` if numba would find nowhere to write; return what was set."""
    if os.environ.get("NUMBA_CACHE_DIR") or "numba" in sys.modules and _configured():
        return None
    here = package_dir or Path(__file__).resolve().parent
    if _writable(here / "__pycache__"):
        return None
    home_cache = Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache")
    try:
        if _writable(home_cache / "numba"):
            return None
    except RuntimeError:  # no home directory at all
        pass
    uid = os.getuid() if hasattr(os, "getuid") else 0
    target = Path(tempfile.gettempdir()) / f"skyfix-numba-{uid}"
    if not _writable(target):
        return None
    os.environ["NUMBA_CACHE_DIR"] = str(target)
    if "numba" in sys.modules:  # numba read its configuration at import: tell it too
        from numba.core import config

        config.CACHE_DIR = str(target)
    return str(target)


def _configured() -> bool:
    from numba.core import config

    return bool(getattr(config, "CACHE_DIR", ""))
