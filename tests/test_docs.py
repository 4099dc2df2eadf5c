"""Every ```sh, ```bash and ```python block of README.md and docs/**/*.md runs as written.

Found afresh at each collection, so new blocks are covered without touching this file. The rules
(docs/docs-tests.md says them to writers):

- Blocks of one file run in order, in one scratch directory per file that looks like the
  repository (its top-level entries linked in), beside a ``../shared`` link to the real data:
  a later block may use the files an earlier one wrote, and ``../shared/data/real/...`` paths
  work as they do from a clone. A block naming ``../shared/data/real`` is skipped when the data
  is absent.
- A real server is running for them (``skyfix serve``'s app under uvicorn, the default database,
  the camera ``tetra3`` configured as ``SKYFIX_CAMERAS``); ``127.0.0.1:8000`` and
  ``localhost:8000`` in a block are rewritten to its port, and ``SKYFIX_URL`` points at it.
- sh/bash blocks run under ``bash -e -o pipefail``, python blocks under ``python -c``, each
  with ``skyfix`` on PATH, and must exit 0 without a traceback.
- A block that cannot run here (docker, kubectl, a venv + pip install from the network, a
  foreground server, a signature listing) is fenced ```text (or ```yaml, ```json, ...).
"""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
SHARED = ROOT.parent / "shared"
RUNNABLE = {"sh": "sh", "bash": "sh", "shell": "sh", "python": "python", "py": "python", "python3": "python"}
FENCE = re.compile(r"^(?P<fence>`{3,})[ \t]*(?P<lang>[\w+-]*)[^\n]*\n(?P<code>.*?)^(?P=fence)[ \t]*$", re.S | re.M)
LOCAL = re.compile(r"\b(?:127\.0\.0\.1|localhost):8000\b")
TETRA3 = {"width": 1024, "height": 768, "fov_deg": 11.4}
BLOCK_TIMEOUT_S = 300
NOT_HERE = re.compile(r"\b(pip install|docker|kubectl|sbatch|helm|apt-get)\b")
"""Commands a block must not run here (they change the machine, or need what it lacks): such a
block is fenced ```text, and the runner refuses it unrun rather than let it touch the venv."""


@dataclass(frozen=True)
class Block:
    path: Path
    line: int
    kind: str
    code: str

    @property
    def id(self) -> str:
        return f"{self.path.relative_to(ROOT)}:{self.line}"


def doc_files() -> list[Path]:
    return [ROOT / "README.md", *sorted((ROOT / "docs").rglob("*.md"))]


def blocks() -> list[Block]:
    found = []
    for path in doc_files():
        text = path.read_text()
        for m in FENCE.finditer(text):
            kind = RUNNABLE.get(m["lang"].lower())
            if kind:
                found.append(Block(path, text.count("\n", 0, m.start()) + 1, kind, m["code"]))
    return found


BLOCKS = blocks()


@pytest.fixture(scope="module")
def doc_server() -> Iterator[str]:
    from service.api import Settings
    from service.core.navdb import ensure_default_database
    from tests.api.conftest import start_server

    live = start_server(Settings(db_path=ensure_default_database(), cameras={"tetra3": TETRA3}))
    yield live.url.removeprefix("http://")
    live.stop()


class _Scratch(dict[Path, Path]):
    """One scratch repository per document, made on first use."""

    def __init__(self, base: Path) -> None:
        super().__init__()
        self.base = base

    def __missing__(self, doc: Path) -> Path:
        d = self.base / re.sub(r"\W", "_", str(doc.relative_to(ROOT)))
        d.mkdir()
        for entry in ROOT.iterdir():
            if entry.name == "db":  # databases a block builds stay in the scratch directory
                (d / "db").mkdir()
            elif not entry.name.startswith("."):
                (d / entry.name).symlink_to(entry)
        self[doc] = d
        return d


@pytest.fixture(scope="module")
def scratch(tmp_path_factory: pytest.TempPathFactory) -> _Scratch:
    base = tmp_path_factory.mktemp("docs")
    if SHARED.exists():
        (base / "shared").symlink_to(SHARED)  # ../shared from every scratch repository
    return _Scratch(base)


def _env(host: str) -> dict[str, str]:
    env = {k: v for k, v in os.environ.items() if k != "SKYFIX_API_KEY"}
    env["PATH"] = os.pathsep.join([str(Path(sys.executable).parent), env.get("PATH", "")])
    env["PYTHONPATH"] = os.pathsep.join(p for p in [str(ROOT), env.get("PYTHONPATH", "")] if p)
    env["SKYFIX_URL"] = f"http://{host}"
    env["SKYFIX_CAMERAS"] = json.dumps({"tetra3": TETRA3})
    return env


@pytest.mark.parametrize("block", BLOCKS, ids=[b.id for b in BLOCKS])
def test_doc_block_runs(block: Block, doc_server: str, scratch: _Scratch) -> None:
    if "../shared/data/real" in block.code and not (SHARED / "data" / "real").is_dir():
        pytest.skip("real images absent")
    bad = NOT_HERE.search(block.code)
    assert bad is None, f"{block.id} runs `{bad and bad[0]}`: fence it ```text (tests/test_docs.py)"
    code = LOCAL.sub(doc_server, block.code)
    cwd = scratch[block.path]
    if block.kind == "sh":
        # `skyfix` in a block is the console script of the interpreter running the tests
        cmd = ["bash", "-e", "-o", "pipefail", "-c", code]
    else:
        cmd = [sys.executable, "-c", code]
    proc = subprocess.run(cmd, cwd=cwd, env=_env(doc_server), capture_output=True, text=True,
                          timeout=BLOCK_TIMEOUT_S)
    report = f"{block.id} exited {proc.returncode}\n--- stdout\n{proc.stdout[-3000:]}\n--- stderr\n{proc.stderr[-3000:]}"
    assert proc.returncode == 0, report
    assert "Traceback (most recent call last)" not in proc.stderr, report
    if block.path.name == "README.md":  # the README's examples solve: no made-up centroids
        answers = _json_objects(proc.stdout)
        assert all(a.get("status") == "solved" for a in answers if "status" in a), report


def _json_objects(text: str) -> list[dict[str, object]]:
    """The JSON objects printed one after another (curl prints no newline after one)."""
    dec, out, i = json.JSONDecoder(), [], 0
    while (i := text.find("{", i)) >= 0:
        try:
            obj, i = dec.raw_decode(text, i)
        except ValueError:
            i += 1
            continue
        if isinstance(obj, dict):
            out.append(obj)
    return out


def test_the_runner_finds_blocks() -> None:
    assert any(b.path.name == "README.md" and b.kind == "python" for b in BLOCKS)
    assert all(b.code.strip() for b in BLOCKS)
