"""Where numba caches compiled kernels, when the usual places are read-only.

numba writes its cache beside the source (``__pycache__``) or under the user's home; when
neither is writable (a non-root user in a container, the package installed read-only, no home
directory), every ``cache=True`` kernel fails at import with "cannot cache function ...: no
locator available". ``ensure_writable_cache`` then points ``NUMBA_CACHE_DIR`` at a per-user
directory under the system's temporary directory, before numba reads its configuration. An
explicit ``NUMBA_CACHE_DIR`` is left alone (the Docker image sets one, pre-filled at build).

numba keys a cached kernel on its own source file's timestamp only. A kernel that calls
functions of other modules (``first_pass_kernel`` calls a dozen) would go on running their old
compiled code after they change, until its own file changes: after a ``git pull`` or an
upgrade in place, a fixed check could silently not apply. ``drop_stale_kernels`` deletes the
package's cached kernels whenever any of its source files changed since they were cached.
"""

from __future__ import annotations

import hashlib
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


KERNEL_SUFFIXES = (".nbi", ".nbc")
STAMP_NAME = "skyfix-kernels.stamp"


def sources_fingerprint(package_dir: Path) -> str:
    """A digest of the package's Python sources: name, size and modification time of each."""
    parts = []
    for path in sorted(package_dir.rglob("*.py")):
        st = path.stat()
        parts.append(f"{path.relative_to(package_dir)}:{st.st_size}:{st.st_mtime_ns}")
    return hashlib.sha1("\n".join(parts).encode()).hexdigest()


def kernel_cache_dirs(package_dir: Path, cache_dir: str = "") -> list[Path]:
    """Where numba keeps the package's cached kernels: beside each source directory's files
    (``__pycache__``), or under ``cache_dir`` (``NUMBA_CACHE_DIR``) in numba's own naming."""
    dirs = sorted({p.parent for p in package_dir.rglob("*.py")})
    if not cache_dir:
        return [d / "__pycache__" for d in dirs]
    return [Path(cache_dir) / f"{d.name}_{hashlib.sha1(str(d).encode()).hexdigest()}" for d in dirs]


def stamp_path(package_dir: Path, cache_dir: str = "") -> Path:
    """The file that names the sources the package's cached kernels were compiled from: in
    ``__pycache__``, or under ``cache_dir`` (``NUMBA_CACHE_DIR``) named after the package's path."""
    if not cache_dir:
        return package_dir / "__pycache__" / STAMP_NAME
    return Path(cache_dir) / f"{STAMP_NAME}-{hashlib.sha1(str(package_dir).encode()).hexdigest()[:12]}"


def drop_stale_kernels(package_dir: Path | None = None, cache_dir: str | None = None) -> int:
    """Delete the package's cached kernels if its sources changed since they were cached (see
    the module's docstring); returns how many files were deleted. A read-only cache (an image
    built with its kernels) is left as it is."""
    here = (package_dir or Path(__file__).resolve().parent).resolve()
    if cache_dir is None:
        cache_dir = os.environ.get("NUMBA_CACHE_DIR", "")
    dirs = kernel_cache_dirs(here, cache_dir)
    stamp = stamp_path(here, cache_dir)
    now = sources_fingerprint(here)
    try:
        if stamp.read_text() == now:
            return 0
    except OSError:
        pass
    dropped = 0
    for d in dirs:
        if not d.is_dir():
            continue
        for f in d.iterdir():
            if f.suffix in KERNEL_SUFFIXES:
                try:
                    f.unlink()
                    dropped += 1
                except OSError:
                    pass
    try:
        stamp.parent.mkdir(parents=True, exist_ok=True)
        tmp = stamp.with_name(f"{stamp.name}.{os.getpid()}.tmp")
        tmp.write_text(now)
        os.replace(tmp, stamp)
    except OSError:
        pass
    return dropped
