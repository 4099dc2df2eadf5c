"""A rich progress bar for database builds, shared by the CLI commands."""

from __future__ import annotations

import sys
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path

from rich.console import Console
from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn

err_console = Console(stderr=True, soft_wrap=True)


@contextmanager
def build_progress(title: str) -> Iterator[Callable[[str, float], None]]:
    """Yield a ``(stage, fraction)`` callback drawing a progress bar on stderr."""
    with Progress(
        TextColumn("[bold]{task.description}"),
        BarColumn(),
        TextColumn("{task.percentage:>3.0f}%"),
        TimeElapsedColumn(),
        console=err_console,
        transient=False,
    ) as bar:
        task = bar.add_task(title, total=1.0)

        def update(stage: str, frac: float) -> None:
            bar.update(task, completed=frac, description=f"{title}: {stage} (peak {peak_memory()})")

        yield update


def peak_memory_bytes() -> int | None:
    """This process's peak resident memory so far, bytes (None where the OS does not say)."""
    try:
        import resource
    except ImportError:  # pragma: no cover - Windows
        return None
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    return int(peak) if sys.platform == "darwin" else int(peak) * 1024  # macOS: bytes; Linux: KiB


def peak_memory() -> str:
    """``peak_memory_bytes`` for people: ``"412 MB"``, ``"3.1 GB"``."""
    peak = peak_memory_bytes()
    if peak is None:
        return "unknown"
    return f"{peak / 1e9:.1f} GB" if peak >= 1e9 else f"{peak / 1e6:.0f} MB"


def resolve_db(path: Path | None) -> Path:
    """The database to use: ``path``, or the default one (built on first use, with a bar)."""
    from ..core.navdb import default_database_dir, default_database_ready, ensure_default_database

    if path is not None:
        return path
    target = default_database_dir() / "default"
    if default_database_ready():
        return target
    err_console.print(f"building the default navigation database in {target} (first use or older schema)")
    with build_progress("default database") as cb:
        return ensure_default_database(progress=cb)
