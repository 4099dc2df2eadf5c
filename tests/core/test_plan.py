"""The search plan over the default set (:mod:`service.core.plan`)."""

from __future__ import annotations

import pytest

from service.core.plan import covered_fallbacks, maxangle_reach_deg, search_plan
from service.core.presets import PRESETS


def _names(plan) -> list[tuple[str, list[str]]]:
    return [(member.path.name, methods) for member, methods in plan]


@pytest.mark.parametrize(("preset", "expected"), [
    # mid's maxangle holds every triangle of seed 000's 12.2-deg diagonal and seed 001's 12.56:
    # narrow's fallbacks (triangles to 3.5 deg) are left out; its quad stays
    ("seed000", [("mid", ["quad"]), ("narrow", ["quad"]), ("mid", ["maxangle", "pyramid"])]),
    ("seed001", [("mid", ["quad"]), ("narrow", ["quad"]), ("mid", ["maxangle", "pyramid"])]),
    # no member's maxangle sees seed 002's whole field: each keeps its fallbacks
    ("seed002", [("sparse", ["quad"]), ("narrow", ["quad"]), ("sparse", ["maxangle", "pyramid", "triangle"]),
                 ("narrow", ["maxangle", "pyramid"])]),
    ("seed004", [("wide", ["quad"]), ("wide", ["maxangle", "pyramid"])]),
])
def test_auto_plans_of_the_paper_cameras(default_set_db, preset, expected) -> None:
    plan, deepest = search_plan(default_set_db, [PRESETS[preset].camera], "auto", 0.5)
    assert _names(plan) == expected
    assert deepest.path.name == ("wide" if preset == "seed004" else "narrow")


def test_only_a_member_after_a_covering_one_loses_its_fallbacks(default_set_db) -> None:
    members = {m.path.name: m for m, _ in search_plan(default_set_db, [PRESETS["seed000"].camera], "auto", 0.5)[0]}
    mid, narrow = members["mid"], members["narrow"]
    assert maxangle_reach_deg(mid) == 13.0 and maxangle_reach_deg(narrow) == 3.5
    lists = [["quad", "maxangle", "pyramid"], ["quad", "maxangle", "pyramid"]]
    assert covered_fallbacks([mid, narrow], lists, 12.2) == [lists[0], ["quad"]]
    assert covered_fallbacks([narrow, mid], lists, 12.2) == lists  # the covering one comes last
    assert covered_fallbacks([mid, narrow], lists, 13.5) == lists  # mid no longer sees the whole field
    assert covered_fallbacks([mid, narrow], lists, 3.0) == lists  # both see it all
    # a member with no fallbacks to run (its first pass alone) counts as no cover
    assert covered_fallbacks([mid, narrow], [["quad"], lists[1]], 12.2) == [["quad"], lists[1]]


def test_a_named_method_keeps_every_member_that_holds_it(default_set_db) -> None:
    plan, _ = search_plan(default_set_db, [PRESETS["seed000"].camera], "maxangle", 0.5)
    assert [name for name, _ in _names(plan)] == ["mid", "narrow"]


def test_a_new_camera_takes_the_plan_of_its_shape(default_set_db) -> None:
    """Cameras of many fields (1-40 deg, square and not, one camera and a rig of two) and
    centroid errors: the plan kept by shape (:func:`~service.core.plan._plan_shape`) is the
    plan chosen anew for each of them, and cameras of one shape share one plan object."""
    import numpy as np

    from service.core.camera import Camera
    from service.core.plan import _choose

    rng = np.random.default_rng(3)
    shared = 0
    for _ in range(300):
        cams = [Camera.from_fov(float(rng.uniform(1.0, 40.0)), 1024, int(rng.choice([768, 1024])))
                for _ in range(int(rng.choice([1, 1, 2])))]
        sigma = float(rng.choice([0.5, 2.0]))
        for method in ("auto", "maxangle"):
            plan = search_plan(default_set_db, cams, method, sigma)
            fresh = _choose(default_set_db, cams, method, sigma)
            assert (_names(plan[0]), plan[1]) == (_names(fresh[0]), fresh[1])
            near = [Camera.from_fov(c.fov_deg * (1 + 1e-9), c.width, c.height) for c in cams]
            shared += search_plan(default_set_db, near, method, sigma) is plan
    assert shared >= 500  # a camera a hair's breadth away shares the plan, except at a range's edge


def test_a_plans_shape_holds_the_wide_field_order_and_the_covering_member(tmp_path) -> None:
    """On a set whose plans differ with the field's width (``dmv`` first for wide, noisy
    frames) and with whether the first member's ``maxangle`` covers the diagonal, cameras that
    fit the same members but differ there get their own plans."""
    from service.core.camera import Camera
    from service.core.navdb import BuildConfig, build_database_set, open_database

    path = tmp_path / "set"
    build_database_set(path, {
        "a": BuildConfig(fov_min_deg=6.0, fov_max_deg=30.0, mag_limit=4.5, methods=("maxangle", "dmv"),
                         method_params={"maxangle": {"d_max_deg": 10.0}}),
        "b": BuildConfig(fov_min_deg=3.0, fov_max_deg=30.0, mag_limit=5.0, methods=("maxangle", "pyramid"),
                         method_params={"maxangle": {"d_max_deg": 3.0}}),
    })
    db = open_database(path)

    def plan(fov: float, sigma: float) -> list[tuple[str, list[str]]]:
        return _names(search_plan(db, [Camera.from_fov(fov, 1024, 1024)], "auto", sigma)[0])

    assert plan(7.0, 0.5) == [("a", ["maxangle"]), ("b", ["maxangle"]), ("a", ["dmv"])]  # diagonal 9.9: covered
    assert plan(8.0, 0.5) == [("a", ["maxangle"]), ("b", ["maxangle"]), ("a", ["dmv"]), ("b", ["pyramid"])]
    assert plan(14.0, 2.0) == [("a", ["maxangle"]), ("b", ["maxangle"]), ("a", ["dmv"]), ("b", ["pyramid"])]
    assert plan(16.0, 2.0) == [("a", ["dmv"]), ("b", ["maxangle"]), ("a", ["maxangle"]), ("b", ["pyramid"])]
    assert plan(16.0, 0.5) == plan(14.0, 2.0)  # wide but not noisy: the usual order
