"""The search plan over the default set (:mod:`service.core.plan`)."""

from __future__ import annotations

import pytest

from service.core.plan import covered_fallbacks, maxangle_reach_deg, search_plan
from service.core.presets import PRESETS


def _names(plan) -> list[tuple[str, list[str]]]:
    return [(member.path.name, methods) for member, methods in plan]


@pytest.mark.parametrize(("preset", "expected"), [
    # mid's maxangle holds every triangle of seed 000's 12.2-deg diagonal: narrow's fallbacks
    # (triangles to 3.5 deg) are left out; its quad stays
    ("seed000", [("mid", ["quad"]), ("narrow", ["quad"]), ("mid", ["maxangle", "pyramid"])]),
    # no member's maxangle sees the whole field: each keeps its fallbacks
    ("seed001", [("narrow", ["quad"]), ("narrow", ["maxangle", "pyramid"])]),
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
    assert maxangle_reach_deg(mid) == 12.5 and maxangle_reach_deg(narrow) == 3.5
    lists = [["quad", "maxangle", "pyramid"], ["quad", "maxangle", "pyramid"]]
    assert covered_fallbacks([mid, narrow], lists, 12.2) == [lists[0], ["quad"]]
    assert covered_fallbacks([narrow, mid], lists, 12.2) == lists  # the covering one comes last
    assert covered_fallbacks([mid, narrow], lists, 13.0) == lists  # mid no longer sees the whole field
    assert covered_fallbacks([mid, narrow], lists, 3.0) == lists  # both see it all
    # a member with no fallbacks to run (its first pass alone) counts as no cover
    assert covered_fallbacks([mid, narrow], [["quad"], lists[1]], 12.2) == [["quad"], lists[1]]


def test_a_named_method_keeps_every_member_that_holds_it(default_set_db) -> None:
    plan, _ = search_plan(default_set_db, [PRESETS["seed000"].camera], "maxangle", 0.5)
    assert [name for name, _ in _names(plan)] == ["mid", "narrow"]
