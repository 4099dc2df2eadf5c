"""Shared fixtures: the real catalogue, real databases built into a temp dir, seeded rngs."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from service.core._cores import usable_cores
from service.core.camera import Camera
from service.core.navdb import BuildConfig, NavDatabase, build_database, open_database

ROOT = Path(__file__).resolve().parents[1]

START_TIMEOUT_S = 300.0
"""How long a test waits for a server to start, s. A first start on a fresh checkout compiles every
kernel (~75 s on a 2-core VM; longer while the other test worker compiles too): a limit that
fails a stuck start, not a speed check."""

SEED000_CAMERA = Camera.from_focal(94.9489, 14.0, 1024, 1024)
"""Seed 000's camera: 1024x1024, f 94.9489 mm, 14 um pixels (8.6 deg across)."""


def pytest_xdist_auto_num_workers(config: pytest.Config) -> int:
    """``-n auto`` (the default, pyproject.toml): one test worker a core, at most 4. Each worker
    builds the session's databases for itself, so more would cost memory and build time for
    little gain; a test file runs whole on one worker (``--dist loadfile``)."""
    return max(1, min(4, usable_cores()))


HEAVY_FIRST = (
    "tests/cli/test_cli.py", "tests/api/reliability/test_workers.py", "tests/test_docs.py",
    "tests/client/test_replay_server.py", "tests/api/ui/test_console.py", "tests/core/methods/test_pso.py",
    "tests/bench/test_bench_smoke.py", "tests/core/test_calibrate.py", "tests/core/methods/test_quad.py",
    "tests/cluster/test_reprocess.py", "tests/api/reliability/test_limits.py", "tests/api/test_serve.py",
)
"""The test files that take longest (``python -m pytest --durations=0``, session 37), collected
first: a file runs whole on one worker (``--dist loadfile``), and one of them handed out last
(``test_docs.py`` was collected after ``tests/core``) can leave the other worker idle for its
length. (The clean-clone CI's tests took 5:25 and 5:34 with this order, 5:31 and 5:55 before:
within this VM's run-to-run spread, so the order's gain is the tail it rules out, not a measured
figure.)"""


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """The files of :data:`HEAVY_FIRST` first, in that order; the rest as collected."""
    rank = {name: i for i, name in enumerate(HEAVY_FIRST)}
    root = Path(str(config.rootpath))

    def key(pair: tuple[int, pytest.Item]) -> tuple[int, int]:
        i, item = pair
        try:
            rel = Path(str(item.path)).relative_to(root).as_posix()
        except ValueError:
            rel = ""
        return rank.get(rel, len(rank)), i

    items[:] = [item for _, item in sorted(enumerate(items), key=key)]


def seed000_config(methods: tuple[str, ...] = ("pyramid", "maxangle")) -> BuildConfig:
    cam = SEED000_CAMERA
    return BuildConfig(fov_max_deg=cam.diagonal_fov_deg + 0.2, fov_min_deg=cam.fov_deg, mag_limit=6.5,
                       epoch=2026.0, methods=methods)


@pytest.fixture(scope="session")
def seed000_db(tmp_path_factory: pytest.TempPathFactory) -> NavDatabase:
    """A database for seed 000's camera (maxangle + pyramid), built once per test session."""
    path = tmp_path_factory.mktemp("db") / "seed000"
    build_database(path, seed000_config())
    return open_database(path)


@pytest.fixture(scope="session")
def default_set_db(tmp_path_factory: pytest.TempPathFactory):
    """The default database set, as ``skyfix`` builds it on first use (into ``$SKYFIX_DB_DIR``: a
    temp dir in CI), so that the session builds it once for these tests and the service's."""
    from service.core.navdb.default import ensure_default_database

    return open_database(ensure_default_database())


@pytest.fixture
def rng() -> np.random.Generator:
    return np.random.default_rng(20261122)
