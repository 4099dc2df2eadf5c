"""Wire models -> engine arguments (:mod:`service.api.convert`): requests of one camera reach the
engine with the same camera and options objects, so its per-camera set-up is found again."""

from __future__ import annotations

from client.models import CameraSpec, SolveRequest
from service.api import convert
from service.api.convert import frame_call, interned
from service.core.camera import Camera
from service.core.camera_setup import kept_setup
from service.core.pipeline import SolveOptions
from service.core.presets import PRESETS
from service.core.sim import SimConfig, simulate_frames


def _request(frame, sigma: float | None = 0.5) -> SolveRequest:
    cam = PRESETS["seed001"].camera
    rows = [[float(x), float(y), float(f)] for (x, y), f in zip(frame.centroids.xy, frame.centroids.flux, strict=True)]
    return SolveRequest(camera=CameraSpec(width=cam.width, height=cam.height, f_px=cam.f_px), centroids=rows,
                        centroid_sigma_px=sigma)


def test_requests_of_one_camera_bring_the_same_camera_and_options_objects(default_set_db) -> None:
    p = PRESETS["seed001"]
    frames = simulate_frames(p.camera, 3, SimConfig(mag_limit=p.mag_limit, centroid_noise_px=0.5), rng=61)
    base = SolveOptions()
    calls = [frame_call(_request(f), default_set_db, {}, max_centroids=1000, options=base) for f in frames]
    cameras = {id(c.args[1]) for c in calls}
    options = {id(c.keywords["options"]) for c in calls}
    assert len(cameras) == 1 and len(options) == 1
    assert calls[0].keywords["options"].centroid_sigma_px == 0.5
    sols = [c() for c in calls]
    assert all(s.solved for s in sols)
    # the first request made the camera's set-up; the later ones found it and proved their
    # frames from the centroids as given (their vectors made inside the compiled call)
    assert kept_setup(default_set_db, calls[0].args[1], "auto", calls[0].keywords["options"]) is not None
    assert [s.timings_ms["vectors"] == 0.0 for s in sols[1:]] == [True, True]


def test_interned_values_are_equal_ones_and_bounded(monkeypatch) -> None:
    monkeypatch.setattr(convert, "_INTERNED", {})
    monkeypatch.setattr(convert, "INTERNED_KEPT", 2)
    a, b = Camera.from_fov(10.0, 640, 480), Camera.from_fov(10.0, 640, 480)
    assert a is not b and interned(a) is a and interned(b) is a
    other = Camera.from_fov(12.0, 640, 480)
    assert interned(other) is other and interned(Camera.from_fov(12.0, 640, 480)) is other
    assert interned(SolveOptions(centroid_sigma_px=2.0)) == SolveOptions(centroid_sigma_px=2.0)
    assert len(convert._INTERNED) <= 2  # cleared when full
