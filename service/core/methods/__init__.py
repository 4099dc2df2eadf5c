"""Identification methods behind one registry.

Each method is one module owning its tables (built into the navigation database) and its
matcher. Adding a method = adding a module and one line to ``_REGISTRY``.
"""

from __future__ import annotations

from ..errors import UnknownMethodError
from ..navdb.reader import NavDatabase
from .base import Matcher, Method, SolveContext
from .dmv import Dmv
from .maxangle import MaxAngle
from .multifov import MultiFov
from .pso import Pso
from .pyramid import Pyramid
from .quad import Quad
from .radial import Radial
from .triangle import Triangle

_REGISTRY: dict[str, Method] = {
    m.name: m
    for m in (
        MaxAngle(),
        Pyramid(),
        Triangle(),
        Radial(),
        Dmv(),
        Pso(),
        MultiFov(),
        Quad(),
    )
}

AUTO_ORDER: tuple[str, ...] = ("quad", "maxangle", "pyramid", "triangle")
"""``auto`` tries these in order, skipping methods whose tables the database lacks, then any
other method the database holds. ``quad`` (one compiled call, a hash lookup per pattern) goes
first where the database holds it (the default database does; docs/performance.md). Measured
by bench/bench_methods.py: ``maxangle`` is the fastest of the published methods at every noise
level, ``pyramid`` the most reliable at 1-2 px, and ``triangle`` the only one that proves
3-star frames (a uniquely matched triangle, see docs/methods.md)."""


def method_names() -> list[str]:
    """Registered method names (``auto`` excluded)."""
    return sorted(_REGISTRY)


def get_method(name: str) -> Method:
    """The method called ``name``; raises ``UnknownMethodError``."""
    try:
        return _REGISTRY[name]
    except KeyError:
        raise UnknownMethodError(name, ["auto", *method_names()]) from None


def get_matcher(db: NavDatabase, name: str) -> Matcher:
    """A matcher for ``name`` over ``db``, created once per opened database."""
    cache = db.__dict__.setdefault("_matchers", {})
    if name not in cache:
        get_method(name)
        if name not in db.tables:
            raise UnknownMethodError(name, ["auto", *db.methods])
        cache[name] = _REGISTRY[name].matcher(db)
    return cache[name]


WIDE_FIELD_DEG = 15.0
WIDE_NOISY_PX = 1.5
WIDE_AUTO_ORDER: tuple[str, ...] = ("quad", "pso", "dmv", "maxangle", "pyramid", "triangle")
"""For fields of ``WIDE_FIELD_DEG`` and more at a declared centroid error of ``WIDE_NOISY_PX``
or more. bench_methods (100 frames a point, git 8701d30) on the 20-deg camera (seed 004):
``maxangle`` 100% up to 1.25 px at 0.6-3.2 ms median, 98% at 1.5 px (11 ms), 71% at 1.75 px
(43 ms), 35% at 2 px (105 ms), where ``pso`` holds 100% at 2.4-4.8 ms and ``dmv`` 100%; on the
15.2-deg camera (seed 003) ``maxangle`` holds 100% to 2 px (0.4-2.5 ms). So below
``WIDE_NOISY_PX`` a wide field keeps ``AUTO_ORDER`` (maxangle first: 4x faster than pso at
0 px), and from it on pso and dmv go first (after ``quad``, where the database holds it)."""


def resolve(db: NavDatabase, name: str, *, fov_deg: float | None = None, sigma_px: float | None = None) -> list[str]:
    """Methods to try for ``name``: ``auto`` expands to those ``db`` has, in the order measured
    best for a camera of horizontal field ``fov_deg`` at centroid error ``sigma_px``."""
    if name == "auto":
        wide = fov_deg is not None and fov_deg >= WIDE_FIELD_DEG
        noisy = sigma_px is None or sigma_px >= WIDE_NOISY_PX
        first = WIDE_AUTO_ORDER if wide and noisy else AUTO_ORDER
        order = [m for m in first if m in db.tables]
        order += [m for m in method_names() if m in db.tables and m not in order]
        return order
    get_method(name)
    if name not in db.tables:
        raise UnknownMethodError(name, ["auto", *db.methods])
    return [name]


__all__ = ["AUTO_ORDER", "WIDE_AUTO_ORDER", "WIDE_FIELD_DEG", "WIDE_NOISY_PX", "Matcher", "Method", "SolveContext", "get_matcher", "get_method", "method_names", "resolve"]
