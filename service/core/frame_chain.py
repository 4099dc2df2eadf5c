"""``auto``'s first pass and, where it proves nothing, the fallback chain: one compiled call.

A one-camera frame the first pass (:mod:`.first_pass`) searched in full without a proof went
back to Python, which built the :class:`~.verify.Observation`, the chain's arguments and its
call (:func:`~.fallback_pass.fallbacks`), and then the refusal: on seed 002's unsolved frames of
5-6 stars (a quarter of its frames at 1 px with 2 false stars) ~13 us of a ~60-us frame between
the two compiled calls (``/work/s36/seg56.py``: the observation 3.5, the chain's set-up and
answer 6, the first pass's result 1, the chain's arguments handed over again ~3). Here
:func:`frame_chain_kernel` makes the vectors, runs the first pass and, on the same terms as
the pipeline (an exhaustive miss), the chain, and hands back one of three things (``stage``):

- :data:`STAGE_FIRST`: the first pass's own result, as :func:`~.first_pass.frame_first_pass_kernel`
  returns it (a proof, or a search the chain does not take up: the general path goes on);
- :data:`STAGE_BACK`: the chain handed the frame back (:data:`~.fallback_pass.CHAIN_BACK`); the
  first pass's result, for the general loop, which runs the chain's passes itself;
- :data:`STAGE_REFUSED`: the chain proved nothing: the hypotheses it counted in ``ints[0]``,
  what became of each pass in ``stage``'s upper bits (:func:`refused_chain`); the refusal needs
  no observation;
- :data:`STAGE_CHAIN`: a proof the call did not finish, packed (:func:`unpack_chain`), which
  gets its observation from the vectors made here;
- :data:`STAGE_SETTLED`: a fallback's answer on the first member, finished here as the first
  pass finishes its own (:func:`~.first_pass.settle_kernel`, with the first member's settle
  arguments): the answer's arrays as a proof of the first pass's, and the pass that proved it
  and what became of each pass in ``stage``'s upper bits (:func:`settled_passes`). Seed 002's
  7-star frames, most of which ``sparse``'s ``maxangle`` proves, spent ~25 us in Python after
  the call: the chain's outcome, the observation, the settle's call and its result.

The pipeline takes this call where it would have called the chain after the first pass
(``pipeline.FRAME_CHAIN``): the same passes, budget and answers (``tests/core/test_frame_chain.py``
compares the two frame by frame).
"""

from __future__ import annotations

from typing import Any, NamedTuple

import numpy as np
from numba import njit

from ._entry import EntryCall
from .camera import Camera, brightest_first
from .fallback_pass import (
    CHAIN_BACK,
    CHAIN_FOUND,
    KIND_NAMES,
    RAN,
    UNPROVABLE,
    Chain,
    _setup,
    chain_bounds,
    chain_kernel,
    passes_by_fate,
)
from .first_pass import _settle_packed, first_pass_kernel, settle_kernel
from .match import frame_rows
from .methods.maxangle import _extension_array, _pattern_array
from .methods.quad import QUERY_STARS
from .methods.quad_kernel import STATUS_NONE
from .navdb.reader import NavDatabase
from .packed import Packed, pack
from .verify import Observation, Verified, observation_of

STAGE_FIRST, STAGE_BACK, STAGE_CHAIN, STAGE_SETTLED, STAGE_REFUSED = 0, 1, 2, 3, 4
STAGE_BITS = 4
"""``stage``'s low bits; above them, for :data:`STAGE_SETTLED` and :data:`STAGE_REFUSED`, the
proving pass (4 bits) and each pass's fate (2 bits a pass)."""


class ChainSetup(NamedTuple):
    """The chain's arguments for one camera set-up and frame size (kept on the set-up)."""

    passes: list[tuple[NavDatabase, int]]
    kinds: np.ndarray
    head: Packed
    """The chain's per-camera numbers: kinds, members, the budget, tolerance, radius, bounds."""
    static: Packed
    """The members' arrays (:func:`~.fallback_pass._setup`)."""
    settle: Packed
    """The first member's settle arguments (:func:`~.first_pass._settle_packed`)."""
    n_tri: int
    tri: np.ndarray
    tri_ext: np.ndarray
    fates: dict[int, tuple[str, tuple[str, ...], tuple[str, ...]]]
    """What a call's ``stage`` says, kept per ``stage``: the proving (or last) pass's method, the
    methods that ran, those skipped as unprovable (:func:`refused_chain`, :func:`settled_passes`;
    ~7 us a refused frame when read from the bits each time)."""


def chain_setup(setup: Any, n: int, few_trials: int, first_quad_only: bool, build: bool = True) -> ChainSetup | None:
    """The chain's arguments for a frame of ``n`` stars on camera set-up ``setup``
    (:class:`~.camera_setup.CameraSetup`), as :func:`~.fallback_pass.fallbacks` would pass them;
    None where the chain does not take this plan. Kept on the set-up per ``n``; ``build``
    False: only if kept already (a camera's first frames make them only after a miss of the
    first pass, the chain's ~40 us being a first sight's own cost otherwise: each real image is
    one)."""
    key = (n, few_trials, first_quad_only)
    if key in setup.chains or not build:
        return setup.chains.get(key)
    cam, options = setup.camera, setup.options
    sigma = float(options.centroid_sigma_px)
    bounds = chain_bounds(cam, float(cam.pixel_scale_rad), sigma, options.match_radius_px, options.max_false_prob)
    got = _setup(setup.plan, cam, bounds[1], n <= QUERY_STARS, first_quad_only)
    cs = None
    if got is not None:
        passes, kinds, members, static = got
        head = pack((kinds, members, int(few_trials), *bounds))
        n_tri = min(n, int(options.max_stars))
        settle = _settle_packed(setup.plan[0][0], setup.deepest, cam, sigma, options.match_radius_px,
                                float(options.max_false_prob))
        cs = ChainSetup(passes, kinds, head, static, settle, n_tri, _pattern_array(n_tri),
                        _extension_array(n_tri, n), {})
    if len(setup.chains) >= 256:
        setup.chains.clear()
    setup.chains[key] = cs
    return cs


@njit(cache=True, nogil=True)
def frame_chain_kernel(xy_in, flux_in, cx, cy, f_px, mounts, cams, dist, rows, row_off, probes, static, head, n_tri,
                       tri, tri_ext, chain_static, settle_static, settle_here):
    """The first pass on a pinhole camera's centroids as given (px, fluxes; ``static`` its
    :class:`~.packed.Packed` arguments), then, after an exhaustive miss, the fallback chain
    (``head``, ``n_tri``, ``tri``, ``tri_ext``, ``chain_static``: :class:`ChainSetup`), and
    where ``settle_here`` the finish of its answer on the first member (``settle_static``).
    Returns ``(stage, solved, used_deep, ints, floats)`` (see the module's docstring)."""
    order, xy, vec, flux = brightest_first(xy_in, flux_in, cx, cy, f_px)
    solved, used_deep, ints, floats = first_pass_kernel(vec, xy, flux, True, mounts, cams, dist, rows, row_off, order,
                                                        probes, *static.args)
    if solved or ints[0] != STATUS_NONE or ints[3] == 0:  # a proof, or not an exhaustive miss
        return STAGE_FIRST, solved, used_deep, ints, floats
    (kinds, members, few_trials, tol, radius_px, pixel_scale, max_false_prob, strong_false_prob, confirm_patterns,
     screen_stars, min_matches, area, agree_limit, max_candidates, checks_per_chunk, n_use, max_probes,
     max_checks) = head.args
    status, at, m_obs, m_cat, r, prob, n_trials, trials, ran = chain_kernel(
        vec, xy, mounts, cams, dist, rows, row_off, probes, kinds, members, ints[1], few_trials, n_tri, tri, tri_ext,
        tol, radius_px, pixel_scale, max_false_prob, strong_false_prob, confirm_patterns, screen_stars, min_matches,
        area, agree_limit, max_candidates, checks_per_chunk, n_use, max_probes, max_checks, chain_static)
    if status == CHAIN_BACK:
        return STAGE_BACK, False, False, ints, floats
    if status != CHAIN_FOUND:  # the hypotheses counted, and what became of each pass
        code = STAGE_REFUSED
        for i in range(len(ran)):
            code |= ran[i] << (2 * STAGE_BITS + 2 * i)
        counted = np.empty(1, np.int64)
        counted[0] = trials
        return code, False, False, counted, np.empty(0)
    if settle_here and members[at] == 0:
        ok, used_deep, s_ints, s_floats = settle_kernel(vec, xy, flux, True, mounts, cams, dist, rows, row_off, order,
                                                        m_obs, m_cat, r, prob, n_trials, *settle_static.args)
        if ok:
            code = STAGE_SETTLED | (at << STAGE_BITS)
            for i in range(len(ran)):
                code |= ran[i] << (2 * STAGE_BITS + 2 * i)
            return code, True, used_deep, s_ints, s_floats
    n, n_m, n_ran = len(order), len(m_obs), len(ran)
    c_ints = np.empty(6 + n_ran + 2 * n_m + n, np.int64)
    c_ints[0], c_ints[1], c_ints[2], c_ints[3], c_ints[4], c_ints[5] = status, at, n_trials, trials, n_ran, n_m
    c_ints[6:6 + n_ran] = ran
    i = 6 + n_ran
    c_ints[i:i + n_m] = m_obs
    c_ints[i + n_m:i + 2 * n_m] = m_cat
    c_ints[i + 2 * n_m:] = order
    c_floats = np.empty(10 + 6 * n)
    c_floats[0] = prob
    c_floats[1:10] = r.ravel()
    c_floats[10:10 + 2 * n] = xy.ravel()
    c_floats[10 + 2 * n:10 + 5 * n] = vec.ravel()
    c_floats[10 + 5 * n:] = flux
    return STAGE_CHAIN, False, False, c_ints, c_floats


FRAME_CHAIN = EntryCall(frame_chain_kernel)
""":func:`frame_chain_kernel` past the dispatcher once its one signature is known (:mod:`._entry`)."""


class ChainOutcome(NamedTuple):
    """What the chain did, from :data:`STAGE_CHAIN`'s arrays (as :func:`~.fallback_pass.fallbacks`
    tells it), and the frame's stars as the call ordered them (brightest first)."""

    chain: Chain
    order: np.ndarray
    xy: np.ndarray
    vec: np.ndarray
    flux: np.ndarray

    def observation(self, cam: Camera, mountings: list[np.ndarray]) -> Observation:
        """The frame's :class:`~.verify.Observation` from these stars (``pipeline._observation``'s,
        without making the vectors again)."""
        camera, rows, _ = frame_rows(len(self.order))
        return observation_of(self.vec, self.xy, self.order, camera, (cam,), tuple(mountings), (rows,), self.flux)


def _fates(stage: int, cs: ChainSetup, fate: int) -> list[str]:
    """The methods of the passes whose fate in ``stage``'s upper bits is ``fate``, in order."""
    fates = [(stage >> (2 * STAGE_BITS + 2 * i)) & 3 for i in range(len(cs.kinds))]
    return passes_by_fate(cs.kinds, fates, fate)


def _stage_names(stage: int, cs: ChainSetup) -> tuple[str, tuple[str, ...], tuple[str, ...]]:
    """``stage``'s proving pass's method (the last pass's where none proved), the methods that
    ran and those skipped as unprovable (kept on ``cs``: a camera's frames repeat a few stages)."""
    got = cs.fates.get(stage)
    if got is None:
        if len(cs.fates) >= 256:
            cs.fates.clear()
        at = (stage >> STAGE_BITS) & 15 if stage & 15 == STAGE_SETTLED else len(cs.kinds) - 1
        got = cs.fates[stage] = (KIND_NAMES[int(cs.kinds[at])], tuple(_fates(stage, cs, RAN)),
                                 tuple(_fates(stage, cs, UNPROVABLE)))
    return got


def settled_passes(stage: int, cs: ChainSetup) -> tuple[str, list[str]]:
    """A :data:`STAGE_SETTLED` call's proving method and the methods the chain ran, in order
    (``stage``'s upper bits)."""
    method, ran, _ = _stage_names(stage, cs)
    return method, list(ran)


def refused_chain(stage: int, ints: np.ndarray, cs: ChainSetup) -> Chain:
    """A :data:`STAGE_REFUSED` call's :class:`~.fallback_pass.Chain` (no answer)."""
    method, ran, unprovable = _stage_names(stage, cs)
    return Chain(None, None, method, int(ints[0]), list(ran), list(unprovable))


def unpack_chain(ints: np.ndarray, floats: np.ndarray, cs: ChainSetup, n: int) -> ChainOutcome:
    """:data:`STAGE_CHAIN`'s packed arrays of a frame of ``n`` stars (a proof), as :class:`ChainOutcome`."""
    status, at, n_trials, trials, n_ran, n_m = ints[:6].tolist()
    ran = ints[6:6 + n_ran].tolist()
    kinds = cs.kinds
    tried, unprovable = passes_by_fate(kinds, ran, RAN), passes_by_fate(kinds, ran, UNPROVABLE)
    i = 6 + n_ran
    order = ints[i + 2 * n_m:]
    xy = floats[10:10 + 2 * n].reshape(n, 2)
    vec = floats[10 + 2 * n:10 + 5 * n].reshape(n, 3)
    flux = floats[10 + 5 * n:]
    found = Verified(ints[i:i + n_m].copy(), ints[i + n_m:i + 2 * n_m].copy(), floats[1:10].reshape(3, 3).copy(),
                     float(floats[0]), int(n_trials))
    chain = Chain(found, cs.passes[at][0], KIND_NAMES[kinds[at]], trials, tried, unprovable)
    return ChainOutcome(chain, order, xy, vec, flux)


__all__ = ["FRAME_CHAIN", "STAGE_BACK", "STAGE_BITS", "STAGE_CHAIN", "STAGE_FIRST", "STAGE_REFUSED", "STAGE_SETTLED",
           "ChainOutcome", "ChainSetup", "chain_setup", "frame_chain_kernel", "refused_chain", "settled_passes",
           "unpack_chain"]
