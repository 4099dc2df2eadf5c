"""The engine stays pure: service.core imports no web framework and nothing of client/api."""

import subprocess
import sys

FORBIDDEN_FOR_CORE = ["fastapi", "starlette", "pydantic", "httpx", "uvicorn", "client", "service.api"]


def test_core_imports_no_web_stack() -> None:
    code = (
        "import sys\n"
        "import service.core.pipeline, service.core.navdb, service.core.sim, service.core.methods\n"
        "import service.core.evaluate, service.core.centroid, service.core.render\n"
        f"bad = [m for m in sys.modules if any(m == f or m.startswith(f + '.') for f in {FORBIDDEN_FOR_CORE!r})]\n"
        "print(','.join(bad))\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout.strip()
    assert out == ""
