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
    )
}

AUTO_ORDER: tuple[str, ...] = ("maxangle", "pyramid", "triangle")
"""``auto`` tries these in order, skipping methods whose tables the database lacks, then any
other method the database holds. Measured by bench/bench_methods.py: ``maxangle`` is the
fastest at every noise level, ``pyramid`` the most reliable at 1-2 px, and ``triangle`` the
only one that proves 3-star frames (a uniquely matched triangle, see docs/methods.md)."""


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
WIDE_AUTO_ORDER: tuple[str, ...] = ("pso", "dmv", "maxangle", "pyramid", "triangle")
"""For fields of ``WIDE_FIELD_DEG`` and more: bench_methods measured ``pso`` and ``dmv`` at 100%
on the 20-deg camera up to 2 px, where ``maxangle`` and ``pyramid`` fall to about a third."""


def resolve(db: NavDatabase, name: str, *, fov_deg: float | None = None) -> list[str]:
    """Methods to try for ``name``: ``auto`` expands to those ``db`` has, in the order measured
    best for a camera of horizontal field ``fov_deg``."""
    if name == "auto":
        first = WIDE_AUTO_ORDER if fov_deg is not None and fov_deg >= WIDE_FIELD_DEG else AUTO_ORDER
        order = [m for m in first if m in db.tables]
        order += [m for m in method_names() if m in db.tables and m not in order]
        return order
    get_method(name)
    if name not in db.tables:
        raise UnknownMethodError(name, ["auto", *db.methods])
    return [name]


__all__ = ["AUTO_ORDER", "WIDE_AUTO_ORDER", "Matcher", "Method", "SolveContext", "get_matcher", "get_method", "method_names", "resolve"]
