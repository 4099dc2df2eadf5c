"""Cached kernels are dropped when the package's sources change (service.core._numba_cache):
numba keys a kernel on its own file only, so a kernel calling another module's function would
otherwise keep that function's old compiled code."""

import os
import subprocess
import sys
import textwrap
from pathlib import Path

from service.core._numba_cache import drop_stale_kernels, kernel_cache_dirs


def _package(root: Path) -> Path:
    pkg = root / "pkg"
    (pkg / "sub").mkdir(parents=True)
    (pkg / "a.py").write_text("x = 1\n")
    (pkg / "sub" / "b.py").write_text("y = 2\n")
    return pkg


def _kernels(dirs: list[Path]) -> list[Path]:
    for d in dirs:
        d.mkdir(parents=True, exist_ok=True)
        (d / "f-12.py311.nbi").write_bytes(b"index")
        (d / "f-12.py311.1.nbc").write_bytes(b"code")
        (d / "a.cpython-311.pyc").write_bytes(b"bytecode")
    return dirs


def test_kernels_beside_the_sources_go_when_a_source_changes(tmp_path: Path) -> None:
    pkg = _package(tmp_path)
    dirs = _kernels(kernel_cache_dirs(pkg))
    assert dirs == [pkg / "__pycache__", pkg / "sub" / "__pycache__"]
    assert drop_stale_kernels(pkg, cache_dir="") == 4  # no stamp yet: whatever is there may be stale
    assert all((d / "a.cpython-311.pyc").exists() for d in dirs)  # only numba's files
    _kernels(dirs)
    assert drop_stale_kernels(pkg, cache_dir="") == 0  # nothing changed since
    (pkg / "sub" / "b.py").write_text("y = 3  # changed\n")
    assert drop_stale_kernels(pkg, cache_dir="") == 4
    assert not any(f.suffix in (".nbi", ".nbc") for d in dirs for f in d.iterdir())


def test_kernels_under_numba_cache_dir_go_too(tmp_path: Path) -> None:
    pkg = _package(tmp_path)
    cache = tmp_path / "cache"
    dirs = _kernels(kernel_cache_dirs(pkg, str(cache)))
    assert all(d.parent == cache for d in dirs)
    assert drop_stale_kernels(pkg, cache_dir=str(cache)) == 4
    _kernels(dirs)
    assert drop_stale_kernels(pkg, cache_dir=str(cache)) == 0
    os.utime(pkg / "a.py", ns=(1, 1))
    assert drop_stale_kernels(pkg, cache_dir=str(cache)) == 4


def test_the_cache_dir_naming_is_numbas(tmp_path: Path) -> None:
    """The directories kernel_cache_dirs names under NUMBA_CACHE_DIR are the ones numba writes."""
    pkg = _package(tmp_path)
    (pkg / "k.py").write_text(textwrap.dedent("""
        from numba import njit

        @njit(cache=True)
        def twice(x):
            return 2 * x
    """))
    cache = tmp_path / "cache"
    subprocess.run([sys.executable, "-c", "import k; assert k.twice(2) == 4"], cwd=pkg, check=True,
                   env={**os.environ, "NUMBA_CACHE_DIR": str(cache)})
    written = {f.parent for f in cache.rglob("*.nbi")}
    assert written and written <= set(kernel_cache_dirs(pkg, str(cache)))
