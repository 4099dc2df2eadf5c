"""``client`` installs without the engine: importing it pulls in no service, numpy or OpenCV."""

import json
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
FORBIDDEN = ("service", "numpy", "cv2", "scipy", "fastapi", "starlette", "uvicorn")


@pytest.mark.parametrize("module", ["client", "client.replay", "client.recording", "client.cli"])
def test_importing_client_loads_no_engine(module: str) -> None:
    code = (
        f"import json, sys; import {module}; "
        f"print(json.dumps(sorted(m for m in sys.modules if m.split('.')[0] in {FORBIDDEN!r})))"
    )
    out = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, check=True)
    assert json.loads(out.stdout) == []


def test_client_sources_never_import_service() -> None:
    for path in (ROOT / "client").glob("*.py"):
        text = path.read_text()
        assert "from service" not in text and "import service" not in text, path.name
