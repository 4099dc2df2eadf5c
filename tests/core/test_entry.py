"""Big kernels called past numba's dispatcher (service/core/_entry.py)."""

from __future__ import annotations

import numpy as np
from numba import njit

from service.core import fallback_pass, first_pass
from service.core._entry import EntryCall, plain, sole_entry
from service.core.pipeline import SolveOptions, solve
from service.core.presets import PRESETS
from service.core.sim import SimConfig, simulate_frames


@njit(cache=False)
def _weighted(a, w, k):
    return (a * w).sum() + k


def test_the_entry_is_taken_only_while_the_kernel_holds_one_signature() -> None:
    a, w = np.arange(6.0).reshape(2, 3), np.ones((2, 3))
    call = EntryCall(_weighted)
    assert call(a, w, 2) == 17.0 and call.entry is not None  # compiled once: its entry from now on
    assert call(a, 2 * w, 1) == _weighted(a, 2 * w, 1) == 31.0
    _weighted(a.astype(np.float32), w, 0)  # a second signature
    assert sole_entry(_weighted) is None
    late = EntryCall(_weighted)
    assert late(a, w, 2) == 17.0 and late.entry is None  # the dispatcher, every call


def test_plain_arrays_are_c_contiguous_and_writable() -> None:
    a = np.zeros((4, 3))
    ro = a.view()
    ro.flags.writeable = False
    assert plain(a, a[1:], np.zeros(0))
    assert not plain(a, np.asfortranarray(a))
    assert not plain(a[:, :2])
    assert not plain(ro)


def test_the_chain_and_the_settle_answer_as_through_the_dispatcher(default_set_db, monkeypatch) -> None:
    """Seed 002's frames of 5-9 stars at 1 px with 2 false stars, most of which go through the
    compiled fallbacks (those of 7 stars are proven there and settled): the same answers, stars
    and messages when both calls go through numba's dispatcher, and the entry points were taken."""
    p = PRESETS["seed002"]
    opts = SolveOptions(centroid_sigma_px=1.0)
    frames = [f.centroids for f in simulate_frames(p.camera, 400, SimConfig(mag_limit=p.mag_limit,
                                                                            centroid_noise_px=1.0, false_stars=2),
                                                   rng=12) if 5 <= len(f.centroids) <= 9][:60]
    fast = [solve(c, p.camera, default_set_db, options=opts) for c in frames]
    assert fallback_pass._CHAIN.entry is not None and first_pass._SETTLE.entry is not None
    assert sum(s.solved and s.method == "maxangle" for s in fast) >= 10
    monkeypatch.setattr(fallback_pass, "_CHAIN", fallback_pass.chain_kernel)
    monkeypatch.setattr(first_pass, "_SETTLE", first_pass.packed_settle_kernel)
    slow = [solve(c, p.camera, default_set_db, options=opts) for c in frames]
    for a, b in zip(fast, slow, strict=True):
        assert (a.solved, a.method, a.message, a.stars) == (b.solved, b.method, b.message, b.stars)
        assert np.array_equal(a.quaternion, b.quaternion)
