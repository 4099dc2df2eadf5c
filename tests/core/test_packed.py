"""A kernel's fixed arguments packed into one numba ``StructRef`` (:mod:`service.core.packed`)."""

from __future__ import annotations

import gc

import numpy as np
from numba import njit

from service.core import first_pass
from service.core.camera_setup import kept_setup
from service.core.packed import Packed, pack
from service.core.pipeline import SolveOptions, solve
from service.core.presets import PRESETS
from service.core.sim import SimConfig, simulate_frames


@njit(cache=False)
def _read(packed, k):
    a, b, c = packed.args
    return a[k] + b * c[0]


def test_a_packed_tuple_is_read_in_compiled_code_and_keeps_its_arrays() -> None:
    a = np.arange(5, dtype=np.float64)
    packed = pack((a, 2.5, np.array([3], np.int64)))
    assert isinstance(packed, Packed)
    del a
    gc.collect()  # the packed tuple holds its own references
    assert _read(packed, 4) == 4.0 + 2.5 * 3


def test_the_first_pass_answers_alike_packed_and_spread(default_set_db) -> None:
    """The first pass from the centroids as given (its static arguments packed) and the general
    path's first pass (the same arguments spread) on the same frames: the same result."""
    p = PRESETS["seed002"]
    options = SolveOptions(centroid_sigma_px=1.0)
    frames = [f.centroids for f in simulate_frames(p.camera, 40, SimConfig(mag_limit=p.mag_limit,
                                                                           centroid_noise_px=1.0, false_stars=2),
                                                   rng=61) if len(f.centroids) >= 5][:15]
    solve(frames[0], p.camera, default_set_db, options=options)
    setup = kept_setup(default_set_db, p.camera, "auto", options)
    from service.core.pipeline import _ONE_CAMERA, _observation
    cam = p.camera
    for c in frames:
        packed = first_pass.frame_first_pass_kernel(*_args(c, cam, setup))
        obs = _observation([(c, cam, None)], _ONE_CAMERA)
        k = obs.kernel_arrays
        spread = first_pass.first_pass_kernel(obs.vec, obs.xy, obs.flux, True, k.mounts, k.cams, k.dist, k.rows,
                                              k.row_off, obs.index, setup.probes, *setup.static)
        assert packed[:2] == spread[:2]
        if packed[0]:  # a proof: the answer's arrays whole
            np.testing.assert_array_equal(packed[2], spread[2])
            np.testing.assert_array_equal(packed[3], spread[3])
        else:  # the search's result; its hypothesis slots (ints 9-16) and matrix are unset without one
            np.testing.assert_array_equal(packed[2][:9], spread[2][:9])
            np.testing.assert_array_equal(packed[2][17:], spread[2][17:])
            np.testing.assert_array_equal(packed[3][9:], spread[3][9:])
    assert any(first_pass.frame_first_pass_kernel(*_args(c, cam, setup))[0] for c in frames)  # some proven


def _args(c, cam, setup) -> tuple:
    """``frame_first_pass_kernel``'s arguments for centroids ``c`` on the kept set-up."""
    from service.core.match import frame_rows, rig_arrays
    from service.core.pipeline import _ONE_CAMERA

    arrays = rig_arrays((cam,), _ONE_CAMERA, (frame_rows(len(c))[1],))
    return (np.ascontiguousarray(c.xy, dtype=np.float64), np.ascontiguousarray(c.flux, dtype=np.float64),
            float(cam.cx), float(cam.cy), float(cam.f_px), arrays.mounts, arrays.cams, arrays.dist, arrays.rows,
            arrays.row_off, setup.probes, setup.packed)
