"""The pure star-identification engine: numpy, scipy and OpenCV only.

Nothing here imports FastAPI, pydantic, httpx or the ``client`` package (a test pins it).
"""

from ._numba_cache import drop_stale_kernels as _drop_stale_kernels
from ._numba_cache import ensure_writable_cache as _ensure_writable_cache

_ensure_writable_cache()  # before any kernel module imports numba (read-only installs, no home)
_drop_stale_kernels()  # numba would keep a kernel's callees from other modules as they were cached
