"""The refusals decided before any search (:mod:`service.core.refusal`)."""

from __future__ import annotations

import numpy as np

from service.core.camera import Camera
from service.core.refusal import _camera_refusal, refusal
from service.core.types import Centroids


def test_one_cameras_refusal_is_the_rigs_of_that_camera(default_set_db) -> None:
    """One camera's decision (its own short path) is a rig of two such cameras' (the general
    one): outside the range or not, with the same message, for ``auto`` and a named method
    (which the default set's members serve wherever the camera fits one)."""
    stars = Centroids(np.array([[10.0, 20.0], [300.0, 40.0], [500.0, 600.0]]), np.ones(3))
    outside = 0
    for fov in (0.4, 1.0, 3.0, 8.6, 20.0, 45.0, 70.0, 100.0, 150.0):
        for height in (768, 1024, 4096):
            cam = Camera.from_fov(fov, 1024, height)
            for method, sigma in (("auto", 1.0), ("auto", None), ("maxangle", 3.0)):
                one = _camera_refusal([(stars, cam, None)], default_set_db, method, sigma)
                assert one == _camera_refusal([(stars, cam, None)] * 2, default_set_db, method, sigma)
                outside += one is not None
    assert outside >= 10
    few = refusal([(Centroids(np.zeros((2, 2)), np.ones(2)), Camera.from_fov(8.6, 1024, 768), None)],
                  default_set_db, "auto", 0.0, 1.0)
    assert few is not None and "2 star(s) given" in few.message


def test_no_solution_names_the_reason_and_what_ran_on_every_call() -> None:
    """The reason and message of a searched frame's refusal, the same on a repeated call (they are
    kept per arguments) and apart where an argument differs."""
    from service.core.refusal import no_solution
    from service.core.types import NoSolutionReason, SolveStatus

    timings = {"total": 0.1}
    for _ in range(2):
        none = no_solution("auto", ["quad", "maxangle", "quad"], 0, False, timings)
        assert none.status is SolveStatus.NO_SOLUTION and none.reason is NoSolutionReason.NO_PATTERN_MATCH
        assert none.methods_tried == ("quad", "maxangle") and none.method == "quad"
        assert none.message.startswith("no catalogue pattern matched the frame's (methods tried: quad, maxangle)")
        checked = no_solution("auto", ["quad"], 7, False, timings)
        assert checked.reason is NoSolutionReason.NOT_PROVEN and checked.message.startswith("7 candidate attitude(s)")
        assert no_solution("auto", ["quad"], 8, False, timings).message.startswith("8 candidate")
        late = no_solution("auto", ["quad"], 7, True, timings)
        assert late.reason is NoSolutionReason.TIME_LIMIT
        few = no_solution("auto", [], 0, False, timings, ["pyramid"], 3, "build one")
        assert few.reason is NoSolutionReason.TOO_FEW_STARS and few.message.startswith("3 stars are too few")
        assert "not run: pyramid" in few.message and few.message.endswith("; build one")
        assert few.timings_ms is timings
