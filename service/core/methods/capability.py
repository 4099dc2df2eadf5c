"""Whether a method's tables in a database can serve a camera, and why not (issue 16).

One pure check per method whose pattern needs room or stars that some fields lack (``pso``,
``radial``); the others serve every camera their database serves (``dmv`` too: where it fails,
on fields of 2-3 deg at 7 Mv, ``pyramid`` fails the same frames, 0-4 of 40). A check takes the
method's build parameters (the manifest), the database's star count and magnitude limit, the
camera and the declared centroid error (px), and returns None (it can serve) or the reason in
words. The estimates spread the catalogue's stars evenly over
the sky (``n_stars / 41,253`` per square degree); measured against them in docs/benchmarks.md
("Every method on every paper camera's database").
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from typing import Any

from ..camera import Camera
from .radial import informative_radius

SKY_DEG2 = 4 * math.pi * math.degrees(1.0) ** 2
"""Square degrees on the sphere."""
PSO_MIN_MASTERS = 0.3
"""``pso`` refuses a field whose master region (at least the pattern radius inside every edge)
is expected to hold fewer stars than this. Measured at 6.5 Mv, 0.5 px, 1024 px (a refusal where
it would solve under 5% of frames): 9 deg 0.22 stars, 1 of 40 frames; 9.5 deg 0.49, 3 of 40;
10 deg 0.88, 7 of 40; a 12x9-deg camera 0.9, 17 of 30; 12 deg 3.5, 28 of 30."""
RADIAL_MIN_NEIGHBOURS = 3.5
"""``radial`` refuses when a star is expected to have fewer neighbours than this within the
radius its ring windows still inform (:func:`radial.informative_radius`). Measured on seed
004's database (20 deg, 6.5 Mv) at 0.5 px, 30 frames a camera: 512 px 3.2 neighbours, 0 frames;
560 px 3.8, 9; 600 px 4.2, 18; 640 px 4.7, 26; 1024 px 10.5, 29."""


def stars_per_deg2(n_stars: int) -> float:
    """Catalogue stars per square degree, spread evenly."""
    return n_stars / SKY_DEG2


def neighbours_within(n_stars: int, radius_deg: float) -> float:
    """Expected catalogue neighbours of a star within ``radius_deg`` (a spherical cap)."""
    return n_stars / 2.0 * (1.0 - math.cos(math.radians(radius_deg)))


def pattern_tolerance_rad(camera: Camera, sigma_px: float) -> float:
    """The tolerance on an inter-star angle a solve uses at centroid error ``sigma_px`` (px),
    radians: 3 sigma of both stars plus half a pixel (as ``pipeline._identify``)."""
    return (3.0 * math.sqrt(2.0) * sigma_px + 0.5) * camera.pixel_scale_rad


def pso_refusal(params: dict[str, Any], n_stars: int, mag_limit: float, camera: Camera,
                sigma_px: float) -> str | None:
    """``pso``: a master star must lie farther than its circle's radius ``r0`` from every image
    edge, so only a ``(w - 2 r0) x (h - 2 r0)`` centre holds masters (the paper's 20-deg field
    leaves 12 deg; an 8.6-deg one 0.6)."""
    r0 = float(params["radius_deg"])
    w, h = max(camera.fov_deg - 2 * r0, 0.0), max(camera.fov_y_deg - 2 * r0, 0.0)
    masters = stars_per_deg2(n_stars) * w * h
    if masters >= PSO_MIN_MASTERS:
        return None
    field = f"{camera.fov_deg:.3g}x{camera.fov_y_deg:.3g}"
    return (f"its {r0:g}-deg pattern circle must lie inside the {field}-deg field, which leaves a "
            f"{w:.2g}x{h:.2g}-deg centre for its master star, holding {masters:.2g} stars "
            f"at {mag_limit:g} Mv on average (it needs {PSO_MIN_MASTERS:g})")


def radial_refusal(params: dict[str, Any], n_stars: int, mag_limit: float, camera: Camera,
                   sigma_px: float) -> str | None:
    """``radial``: beyond :func:`radial.informative_radius` a ring window (two tolerances
    plus a ring) holds a catalogue star by chance, so only nearer neighbours score; too few
    of those (coarse pixels, a deep catalogue) and no candidate is significant."""
    eps = pattern_tolerance_rad(camera, sigma_px)
    ring = math.radians(float(params["ring_deg"]))
    reach = math.degrees(informative_radius(n_stars, ring, eps, math.radians(float(params["radius_deg"]))))
    reach = min(reach, camera.diagonal_fov_deg / 2)
    k = neighbours_within(n_stars, reach)
    if k >= RADIAL_MIN_NEIGHBOURS:
        return None
    window = math.degrees(2 * eps + ring) * 3600
    scale = math.degrees(camera.pixel_scale_rad) * 3600
    return (f"at {sigma_px:g} px of {scale:.3g}\"/px its {window:.0f}\" ring windows hold a catalogue star "
            f"by chance beyond {reach:.2g} deg, within which a star has {k:.2g} "
            f"neighbours at {mag_limit:g} Mv on average (it needs {RADIAL_MIN_NEIGHBOURS:g})")


Check = Callable[[dict[str, Any], int, float, Camera, float], str | None]
CHECKS: dict[str, Check] = {"pso": pso_refusal, "radial": radial_refusal}
"""The methods that can refuse a camera their database serves; every other serves it."""


def cannot_serve(db: Any, method: str, camera: Camera, sigma_px: float) -> str | None:
    """Why ``method``'s tables in the single database ``db`` cannot serve ``camera`` at
    centroid error ``sigma_px`` (px), or None if they can (or the method has no check)."""
    check = CHECKS.get(method)
    if check is None or method not in db.tables:
        return None
    m = db.manifest
    return check(db.method_params(method), int(m["n_stars"]), float(m["mag_limit"]), camera, sigma_px)


def serving(db: Any, cameras: Sequence[Camera], sigma_px: float, order: Sequence[str]) -> list[str]:
    """Methods of ``db`` (in ``order``, then the rest by name) that can serve every camera."""
    names = [m for m in order if m in db.tables] + sorted(m for m in db.tables if m not in order)
    return [m for m in names if all(cannot_serve(db, m, c, sigma_px) is None for c in cameras)]


def refusal_message(method: str, why: str, where: str, alternatives: Sequence[str]) -> str:
    """The sentence a refused ``method`` answers with: what it cannot serve (``where``), why,
    and what to use instead (``auto``, and the first of ``alternatives``; without one, a
    database built with other methods)."""
    use = f"auto or {alternatives[0]}" if alternatives else "a database built with other methods (--methods)"
    return f"{method} cannot serve {where}: {why}; use {use}"


FAILURE_HINTS: dict[str, str] = {
    "pso": ("pso's tour runs through every star of its circle: it searches the database's stars to its "
            "limit and to 0.5-1.5 Mv brighter (a database built before these cuts only to its limit: rebuild "
            "it for a shallower camera), and the circle (4 deg, 5 where few stars are seen) must lie inside "
            "the image, which a narrow field seeing few stars seldom allows; use auto or maxangle otherwise"),
}
"""What a named method's ``no_solution`` adds when the cause is one no check can see from the
request: the camera's magnitude limit is not part of it. Measured (issue 16): a 12-17 deg
database to 6.5 Mv, 12-deg frames, 0.5 px, 2 false stars: pso 91 of 100 frames to 6.5 Mv, 2 of
100 to 6.0 Mv on a table of one cut; 57 of 100 to 6.0 Mv with the cuts, where 69 hold a master
whose circle fits (every other published method but multifov solves 100)."""


NOMINAL_PX = 1024
NOMINAL_SIGMA_PX = 0.5


def build_warnings(db: Any, order: Sequence[str]) -> list[str]:
    """For a freshly built single database: one line per method that cannot serve the
    narrowest or the widest square camera its range claims (side ``fov_min_deg``; diagonal
    ``fov_max_deg``), at ``NOMINAL_PX`` px and ``NOMINAL_SIGMA_PX`` px of centroid error."""
    lo, hi = float(db.manifest["fov_min_deg"]), float(db.manifest["fov_max_deg"])
    sides = dict.fromkeys((lo, max(lo, hi / math.sqrt(2))))  # no claimed square is narrower than lo
    cams = {side: Camera.from_fov(side, NOMINAL_PX, NOMINAL_PX) for side in sides}
    ok = serving(db, list(cams.values()), NOMINAL_SIGMA_PX, order)
    out = []
    for m in db.methods:
        for label, (side, cam) in zip(("narrowest", "widest"), cams.items(), strict=False):
            why = cannot_serve(db, m, cam, NOMINAL_SIGMA_PX)
            if why is not None:
                where = (f"the {label} field this database claims ({side:.3g} deg square, {NOMINAL_PX} px, "
                         f"{NOMINAL_SIGMA_PX:g} px centroid error)")
                out.append(refusal_message(m, why, where, ok))
                break
    return out


__all__ = ["CHECKS", "FAILURE_HINTS", "build_warnings", "cannot_serve", "neighbours_within", "pattern_tolerance_rad",
           "pso_refusal", "radial_refusal", "refusal_message", "serving", "stars_per_deg2"]
