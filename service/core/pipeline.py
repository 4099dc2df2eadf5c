"""One frame in, one answer out: centroids (or an image) -> identified stars and attitude.

Every stage is timed into ``Solution.timings_ms``: ``vectors`` (camera model), ``identify``
(the methods, verification included), ``attitude`` (final fit and diagnostics), ``total``;
``detect`` too when the input is an image. A frame the first pass proves from the centroids as
given (a camera's kept set-up, :mod:`service.core.camera_setup`) makes its vectors inside that
compiled call: its ``vectors`` is 0 and ``identify`` holds them.
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from .attitude import quat_to_matrix
from .camera import Camera, brightest_first
from .camera_setup import SETUP_SIZES_KEPT, CameraSetup, keep_setup, kept_setup
from .deeper import refine_deeper
from .errors import InvalidInputError
from .fallback_pass import MIN_CLOCK_S, Chain, fallbacks
from .finish import solution
from .frame_chain import (
    FRAME_CHAIN,
    STAGE_BACK,
    STAGE_CHAIN,
    STAGE_REFUSED,
    STAGE_SETTLED,
    ChainOutcome,
    ChainSetup,
    chain_setup,
    frame_chain_kernel,
    refused_chain,
    settled_passes,
    unpack_chain,
)
from .first_pass import (
    FirstPass,
    _static_args,
    first_pass,
    frame_first_pass_kernel,
    kernel_entry,
    settle,
    solved_solution,
    unsolved,
)
from .match import IDENTITY_MOUNTING, frame_rows, rig_arrays
from .methods import SolveContext, get_matcher
from .methods.quad import MIN_STARS as QUAD_MIN_STARS
from .methods.quad import QUERY_STARS
from .methods.quad_kernel import STATUS_NONE
from .navdb.reader import NavDatabase, NavDatabaseSet
from .packed import pack
from .plan import fallback_next, search_plan
from .refusal import SPARSE_ADVICE_STARS, no_solution, refusal, sparse_advice
from .solution import solution_of
from .sparse_screen import HOPELESS, MAX_SCREENED_STARS, SCREENED_METHODS, SEARCH, SPARSE_ONLY, screen
from .types import Centroids, Solution
from .verify import Observation, Verified, Verifier, camera_probes, observation_of
from .wcs import tan_wcs

Quaternion = Sequence[float]


@dataclass(frozen=True, slots=True)
class SolveOptions:
    """Tuning knobs of a solve (defaults suit 0-2 px centroid noise).

    Attributes
    ----------
    centroid_sigma_px : float
        Expected centroid error per axis, px. Sets the pattern tolerance (3 sigma, both stars)
        and the match radius.
    match_radius_px : float or None
        Radius for pairing observed and predicted stars, px (default ``max(2.5, 3 sigma)``).
    max_false_prob : float
        Largest accepted probability that the identification is a coincidence.
    max_stars : int
        Brightest stars a method may combine into patterns.
    timeout_ms : float
        Give up after this long.
    epoch : float, optional
        Decimal year of the frame. The matched stars are moved by proper motion from the
        database's epoch to this one before the final attitude fit (None: the database's).
    observer_velocity_km_s : (3,), optional
        The observer's velocity relative to the solar-system barycentre, ICRS axes, km/s. The
        matched stars' directions are aberrated by it before the final fit, so the quaternion
        is the camera's true inertial attitude (None: no aberration applied).
    retry_sigma_factor : float
        If nothing is proven, search once more assuming ``centroid_sigma_px`` times this (real
        faint stars are often worse than assumed); the hypotheses of the first pass still count
        in the coincidence bound. The default 1 disables the retry: it doubles the cost of
        frames that have no answer.
    fov_max_error_deg : float, optional
        The camera's horizontal field of view may be off by up to this much (deg): a frame not
        proven with the camera as given is searched again over the focal lengths that range
        allows, and the answer is fitted with the focal length its stars say
        (:mod:`service.core.fov_search`; ``Solution.fov_deg`` reports the field). One camera
        only. None: the camera is exact.
    """

    centroid_sigma_px: float = 1.0
    match_radius_px: float | None = None
    max_false_prob: float = 1e-5
    max_stars: int = 8
    timeout_ms: float = 500.0
    retry_sigma_factor: float = 1.0
    epoch: float | None = None
    observer_velocity_km_s: tuple[float, float, float] | None = None
    fov_max_error_deg: float | None = None


DEFAULT_OPTIONS = SolveOptions()

MANY_STARS_MAX_TRIALS = 20_000
"""Hypotheses the first fallback (``maxangle`` on the default set) may add, over every member,
after ``quad`` searched a frame of more than ``QUERY_STARS`` stars exhaustively (every pattern
of its brightest stars, on every member) without a proof: bright false detections can hide the
stars from the brightest. A count of work, as ``FEW_STARS_MAX_TRIALS`` is, so that a loaded
machine gives the same answer; until session 16 it was 50 ms of the clock. Measured (session
16): the real image cedar-solve/tree.jpg (92 detections, branches among the brightest) is
proven after 2,839; 17 such proofs in 21,000 simulated frames (the five paper cameras at
0.5/1/2 px with 2/5 false stars) after at most 523; the passes that prove nothing stop at the
end of their triangles, after at most 8,769 (5.6 ms) there and 2,547 on random points, so the
budget binds none of them and bounds the rest at ~25 ms on this machine. The later fallbacks
(``pyramid``, ``triangle``) proved 2 more frames in 9,000 of the five paper cameras (0.5-2 px,
0-2 false stars) at 17-27 ms each, and spent up to 64 ms on each of the 288 they could not
prove; on random points ``pyramid`` took 130-500 ms: they do not run after an exhaustive miss.
Measured with ``python -m bench.profile_default`` (docs/performance.md)."""
FEW_STARS_MAX_TRIALS = 1000
"""Hypotheses the first fallback may add, over every member, after ``quad`` searched a frame
of 5 to ``QUERY_STARS`` stars exhaustively without a proof: a count of work, so the same frame
gets the same answer on a loaded machine, as the issue asks of budgets. Such a frame may still
be proven by a triangle and two more stars where 4 + 1 is not enough, or by stars that ``quad``'s
table leaves out: its pattern stars are the brightest of each region, so a frame whose bright
detections are false can hold only fainter true stars (seed 002 at 0.5 px with 3-5 false stars:
8-10-star frames, refused here until session 16, proven by ``maxangle``: 96 -> 118, 84 -> 111,
99 -> 119 of 200 frames, where tetra3rs names 106, 93 and 101). Running it on the first member
only saved ~0.3 ms on a third of seed 002's frames but lost 6 frames in 100,000 of
``bench.bench_wrong``, which a deeper member's pattern stars prove. Session 13, 2,593 frames of
5-7 stars that reached the fallback (the five paper cameras at 0.5/1/2 px with 0/2/5 false
stars): the 875 it proved took at most 220 hypotheses (p99 103), those it could not prove up
to 16,455 (p99 617; seed 000 at 2 px: up to 13 ms). Until session 13 the fallback had 20 ms
of the clock; a 3-ms clock budget tried here refused 2 frames of 47,500 it proves in 0.4-0.7
ms when the machine stalled."""

SMALL_FRAME_FALLBACK_FIRST = True
"""On a frame of 5 to ``QUERY_STARS`` stars that a member's ``quad`` searched exhaustively
without a proof, that member's first fallback runs before the next member's ``quad``: there
``quad``'s 4-star patterns with one more star rarely pass the bound (seed 002's 4096-px camera,
7 stars of which 2 false: the next member's ``quad`` proved none of 443, at 0.087 ms a frame,
and ``maxangle`` on the first member proved 422). Its hypotheses do not count against the
fallbacks' ``FEW_STARS_MAX_TRIALS``."""

SPARSE_FRAME_ONE_MEMBER = True
"""On a one-camera frame of 3-4 stars (too few for ``quad``), ``auto`` runs the fallbacks of the
plan's first member that holds them, not a later member's as well. Seed 002's camera: the
default set's ``narrow`` member's ``maxangle`` and ``pyramid`` after ``sparse``'s proved none of
2,203 4-star and 994 3-star frames over the benchmark's grid (seeds 1-8 of bench_peers' 20
points; a 4-star frame's bound allows one or two hypotheses on the deeper, denser member), at
~0.11 ms of every 4-star frame that ``sparse`` leaves (``/work/s25/who.py``). The general loop
(written as a flag so that a test can compare the two)."""

FIRST_QUAD_ONLY_STARS = 6
"""Frames of at most this many stars run ``quad`` on the plan's first member only (the first
pass); the later members' fallbacks still run (in the compiled chain and the general loop). Seed
002's unsolved 5-6-star frames spent 0.03-0.045 ms in ``narrow``'s ``quad`` after ``sparse``'s
(``/work/s27/who57.py``), which proved none of them: the same stars and attitude on every one of
bench_wrong's 47,952 seed 002 frames (seeds 3, 7, 11) and 63,936 of the other four cameras (seed
7) with it at 4 and at 6 (``/work/s28/dump_one.py``); the benchmark's seed 002 sweeps 1-4%
faster in the mean (``/work/s28/ab_quad.py``). ``narrow``'s ``maxangle`` stays: without it 3
of 31,968 frames were lost."""

SPARSE_PROOF_METHODS = frozenset({"triangle", "multifov"})
"""Methods that can prove a frame of fewer stars than the verifier's ``min_matches`` (4): the
verifier needs a pair beyond the pattern, so only ``triangle``'s unique-triangle proof
(``sparse_proof.check_unique_triangle``) and ``multifov``'s cross-camera one
(``methods/rig_proof.py``, 3-star rig frames) name a 3-star frame; the others are skipped on it
(seed 002 at 1.5 px, 3 centroids of which one false: 0.8 -> 0.2 ms median; a true 3-star frame's
time is triangle's own, ~12 ms)."""

TRIANGLE_PROOF_METHODS = frozenset({"maxangle", "pyramid"})
"""``auto``'s fallbacks whose only proof is the verifier's bound on a triangle and the stars
beyond it: skipped where even every star matching could not pass it (``Verifier.could_prove``,
e.g. any 4-star frame of seed 000's 1024-px camera, where ``pyramid`` spent up to 16 ms at 2 px
on frames nothing could prove; ``triangle``'s unique-triangle proof and ``multifov``'s rig proof
do not use that bound)."""

SPARSE_SCREEN = True
"""Before ``maxangle``, ``pyramid`` or ``triangle`` search a one-camera frame of 3-4 stars on a
member, one compiled call counts the catalogue triples fitting each of its triangles; where none
could lead to a proof, they are not searched, and where only ``triangle``'s unique-triangle proof
could, ``maxangle`` and ``pyramid`` are not (:mod:`service.core.sparse_screen`; seed 002's
unsolved 4-star frames: 0.16-0.5 ms each before). False searches them as before (the tests
compare the two)."""

VERIFIER_ONLY = frozenset({"maxangle", "pyramid"})
"""Screened fallbacks whose only proof is the verifier's (at least 4 stars paired): not run on a
frame the screen leaves to ``triangle``'s unique-triangle proof (``sparse_screen.SPARSE_ONLY``)."""

COMPILED_FIRST_PASS = True
"""Run ``auto``'s first pass as one compiled call (:mod:`service.core.first_pass`); False takes
the same steps through the general path (four compiled calls; the tests compare the two)."""

COMPILED_FALLBACKS = True
"""Run the fallbacks after the first pass's exhaustive miss on one camera as one compiled call
(:mod:`service.core.fallback_pass`; a small frame's and, since session 18, a larger one's);
False takes the general loop (the tests compare the two)."""

FRAME_CHAIN_CALL = True
"""Run the fallback chain in the first pass's own compiled call where the pipeline would call
it after the first pass's exhaustive miss (:mod:`service.core.frame_chain`: no observation, no
second call); False makes the two calls (the tests compare the two)."""

FIRST_PASS_CLOCK_S = 0.05
"""Time the first pass may take at most, beyond :data:`~.fallback_pass.MIN_CLOCK_S`: the chain
runs in the first pass's call only when the frame has both left before that call (the first
pass's work is bounded by its probes and checks, well under this)."""

COMPILED_SETTLE = True
"""Finish an answer that another method proved (one camera, no epoch or aberration) as the first
pass finishes its own, in one compiled call (:func:`~service.core.first_pass.settle`: the
deeper member's recheck, the answer's checks, the fit); False takes the general path
(``_refine``, :func:`~service.core.finish.solution`; the tests compare the two)."""


def solve(
    centroids: Centroids,
    camera: Camera,
    db: NavDatabase | NavDatabaseSet,
    *,
    method: str = "auto",
    hint: tuple[Quaternion, float] | None = None,
    options: SolveOptions = DEFAULT_OPTIONS,
) -> Solution:
    """Identify the stars of one camera frame.

    Parameters
    ----------
    centroids : Centroids
        Star positions (px) and fluxes.
    camera : Camera
    db : NavDatabase
    method : str
        A registered method or ``"auto"``.
    hint : (quaternion [w, x, y, z], radius_deg), optional
        Prior attitude; answers whose boresight lies farther than ``radius_deg`` are refused.
    """
    if options.fov_max_error_deg is not None:  # a field known roughly: a search over focal lengths
        from .fov_search import solve_uncertain_fov

        return solve_uncertain_fov(centroids, camera, db, method=method, hint=hint, options=options)
    return solve_rig([(centroids, camera, None)], db, method=method, hint=hint, options=options,
                     _mountings=_ONE_CAMERA)


def solve_rig(
    frames: Sequence[tuple[Centroids, Camera, Quaternion | None]],
    db: NavDatabase | NavDatabaseSet,
    *,
    method: str = "auto",
    hint: tuple[Quaternion, float] | None = None,
    options: SolveOptions = DEFAULT_OPTIONS,
    _mountings: list[np.ndarray] | None = None,
) -> Solution:
    """Identify the stars of several cameras fixed to one body, fired at the same instant.

    ``frames`` holds ``(centroids, camera, mounting)`` with ``mounting`` the quaternion
    rotating body vectors into that camera (None = identity). The answer's quaternion rotates
    ICRS into the body frame.
    """
    if not frames:
        raise InvalidInputError("cameras", "at least one camera frame is required")
    if options.fov_max_error_deg is not None:
        raise InvalidInputError("fov_max_error_deg", "a search over focal lengths is for one camera (solve); "
                                "calibrate a rig's cameras (skyfix calibrate) instead")
    t0 = time.perf_counter()
    timings: dict[str, float] = {}
    given = db  # (``db`` names the member being searched below)
    one = _mountings is _ONE_CAMERA and hint is None  # solve()'s frame
    setup = kept_setup(db, frames[0][1], method, options) if one else None
    if setup is not None and len(frames[0][0]) >= 3:  # its camera was planned and not refused
        plan, deepest = setup.plan, setup.deepest
    else:
        setup = None
        plan, deepest = search_plan(db, [cam for _, cam, _ in frames], method, options.centroid_sigma_px)
        refused = refusal(frames, db, method, t0, options.centroid_sigma_px)
        if refused is not None:
            return refused
        _ensure_warm(db)  # one-off per opened database; not charged to this frame's time limit
        if one and len(frames[0][0]) >= 3:
            # a camera seen for the first time: its set-up now, so this frame takes the path of
            # the camera's later frames (no Observation where the first pass proves it)
            setup = _first_sight(db, frames[0][1], method, options, plan, deepest)
    t0 = time.perf_counter()
    mountings = _mountings or [np.eye(3) if m is None else quat_to_matrix(np.asarray(m, float)) for _, _, m in frames]
    fp: FirstPass | None = None
    arrays = None
    fp_s = 0.0  # the first pass's time when it ran before the observation (counted in identify)
    outcome: ChainOutcome | None = None  # the chain's answer, when it ran in the first pass's call (FRAME_CHAIN)
    chain_back = False  # the chain ran there and handed the frame back to the general loop
    if setup is not None:  # what the first pass asks of the observation, kept with the camera
        n = len(frames[0][0])
        arrays = setup.arrays.get(n)
        if arrays is None:
            arrays = rig_arrays((setup.camera,), _ONE_CAMERA, (frame_rows(n)[1],))
            if len(setup.arrays) < SETUP_SIZES_KEPT:
                setup.arrays[n] = arrays
        if COMPILED_FIRST_PASS and n >= 5:
            # the first pass from the centroids as given: a frame it proves needs no Observation
            # (its vectors are made inside the call: ``vectors`` is 0 and ``identify`` holds them)
            cents, cam = frames[0][0], frames[0][1]
            xy = np.ascontiguousarray(cents.xy, dtype=np.float64)
            flux = np.ascontiguousarray(cents.flux, dtype=np.float64)
            entry = setup.entry[0]
            usual = xy.ndim == 2 and flux.ndim == 1  # the kernels' usual types: their entry points (_entry)
            cs = _frame_chain(setup, n, method, options, t0)
            if cs is not None:  # the first pass and, after its exhaustive miss, the chain (FRAME_CHAIN)
                stage, solved, _, ints, floats = (FRAME_CHAIN if usual else frame_chain_kernel)(
                    xy, flux, float(cam.cx), float(cam.cy), float(cam.f_px), arrays.mounts, arrays.cams, arrays.dist,
                    arrays.rows, arrays.row_off, setup.probes, setup.packed, cs.head, cs.n_tri, cs.tri, cs.tri_ext,
                    cs.static, cs.settle, COMPILED_SETTLE)
            elif entry is not None and usual:  # (first_pass.kernel_entry)
                solved, _, ints, floats = entry(xy, flux, float(cam.cx), float(cam.cy), float(cam.f_px), arrays.mounts,
                                                arrays.cams, arrays.dist, arrays.rows, arrays.row_off, setup.probes,
                                                setup.packed)
            else:
                solved, _, ints, floats = frame_first_pass_kernel(
                    xy, flux, float(cam.cx), float(cam.cy), float(cam.f_px), arrays.mounts, arrays.cams, arrays.dist,
                    arrays.rows, arrays.row_off, setup.probes, setup.packed)
                setup.entry[0] = kernel_entry()
            t2 = time.perf_counter()
            if solved:
                timings["vectors"], timings["identify"] = 0.0, (t2 - t0) * 1e3
                if cs is not None and stage & 15 == STAGE_SETTLED:  # a fallback's answer, finished in the call
                    used, ran = settled_passes(stage, cs)
                    sol = solved_solution(ints, floats, used, tuple(dict.fromkeys(["quad", *ran])), timings)
                    return _timed(sol, timings, t0, t2)
                return _timed(solved_solution(ints, floats, timings_ms=timings), timings, t0, t2)
            if cs is not None and stage & 15 == STAGE_REFUSED:  # refused with no observation made
                refused = refused_chain(stage, ints, cs)
                timings["vectors"], timings["identify"] = 0.0, (t2 - t0) * 1e3
                timings["total"] = (time.perf_counter() - t0) * 1e3
                sparse = isinstance(given, NavDatabaseSet) and 3 <= n <= SPARSE_ADVICE_STARS
                return no_solution(method, ["quad", *refused.tried], refused.trials, t2 > t0 + options.timeout_ms / 1e3,
                                   timings, refused.unprovable, n, sparse_advice((cam,)) if sparse else "")
            if cs is not None and stage == STAGE_CHAIN:  # a proof to finish below, from these vectors
                outcome = unpack_chain(ints, floats, cs, n)
                fp_s = t2 - t0
            else:
                fp, fp_s = unsolved(ints, floats, plan[0][0]), t2 - t0
                chain_back = cs is not None and stage == STAGE_BACK
                if cs is None:  # the chain's arguments for this camera's later frames of this size
                    _frame_chain(setup, n, method, options, None, build=True)
    obs = _observation(frames, mountings) if outcome is None else outcome.observation(frames[0][1], mountings)
    if setup is not None:
        obs.__dict__["_image_probes"] = setup.probes
        obs.__dict__["_kernel_arrays"] = arrays
    t1 = time.perf_counter() - fp_s  # identify, timed from t1, takes in that first pass
    timings["vectors"] = (t1 - t0) * 1e3
    deadline = t0 + options.timeout_ms / 1e3
    found: Verified | None = None
    used, trials, tried = method, 0, []
    sigmas = [options.centroid_sigma_px]
    if options.retry_sigma_factor > 1:
        sigmas.append(options.centroid_sigma_px * options.retry_sigma_factor)
    plain = hint is None and options.epoch is None and options.observer_velocity_km_s is None
    quad_first = bool(plan) and plan[0][1][:1] == ["quad"]
    chain: Chain | None = None
    if outcome is not None:
        chain = outcome.chain
    elif COMPILED_FIRST_PASS and plain and quad_first and len(obs.cameras) == 1 and len(obs) >= 5:
        # auto's first pass in one compiled call (service.core.first_pass); a frame it does not
        # prove goes on below with the search's result in hand (QuadMatcher takes it up)
        if fp is None:
            fp = first_pass(obs, plan[0][0], deepest, sigmas[0], options.match_radius_px, options.max_false_prob)
        if fp.solved:
            t2 = time.perf_counter()
            timings["identify"] = (t2 - t1) * 1e3
            sol = solution_of(*fp.columns, fp.rms_arcsec, fp.sigma_arcsec, fp.false_prob, "quad")
            return _stamped(sol, ["quad"], timings, t0, t2)
        obs.__dict__["_quad_prefetch"] = (plan[0][0], fp.search)
        status, _, _, exhausted = fp.search[0][:4].tolist()
        few = len(obs) <= QUERY_STARS  # (5 or more here)
        if (COMPILED_FALLBACKS and (SMALL_FRAME_FALLBACK_FIRST or not few) and len(sigmas) == 1
                and status == STATUS_NONE and exhausted and not chain_back):
            # the first pass looked up every pattern: the fallbacks in one compiled call too
            chain = fallbacks(obs, plan, fp.trials, FEW_STARS_MAX_TRIALS if few else MANY_STARS_MAX_TRIALS,
                              sigmas[0], options.match_radius_px, options.max_false_prob, options.max_stars,
                              deadline, few, method == "auto" and len(obs) <= FIRST_QUAD_ONLY_STARS)
    # every pass (member of a database set, retry sigma) adds its hypotheses to the trials that
    # the coincidence bound is multiplied by
    misses: list[bool] = []  # per quad pass: did it look up every pattern and prove none?
    unprovable: list[str] = []  # methods skipped: no answer of theirs could pass the bound here
    trial_limit: int | None = None  # set after an exhaustive quad miss (FEW_STARS_MAX_TRIALS, MANY_STARS_MAX_TRIALS)
    small = QUAD_MIN_STARS <= len(obs) <= QUERY_STARS
    sigma = sigmas[0]
    if chain is not None:
        found, used, trials, unprovable = chain.found, chain.method, chain.trials, chain.unprovable
        tried = ["quad", *chain.tried]
        if chain.member is not None:
            db = chain.member
    one_fallback = (SPARSE_FRAME_ONE_MEMBER and method == "auto" and len(obs) < QUAD_MIN_STARS
                    and len(obs.cameras) == 1)
    quad_once = (method == "auto" and QUAD_MIN_STARS <= len(obs) <= FIRST_QUAD_ONLY_STARS
                 and len(obs.cameras) == 1)
    for sigma in sigmas if chain is None else ():
        order = list(plan)
        fallen_back: NavDatabase | None = None  # the member whose fallbacks ran first on this frame
        for i, (member, methods) in enumerate(order):
            if quad_once and i > 0 and methods == ["quad"]:
                continue  # a frame of at most 6 stars: the first member's quad only (FIRST_QUAD_ONLY_STARS)
            if "quad" not in methods:
                if one_fallback and fallen_back is not None and member is not fallen_back:
                    continue  # a 3-4-star frame: the first member's fallbacks only (SPARSE_FRAME_ONE_MEMBER)
                fallen_back = fallen_back or member
            if misses and all(misses) and "quad" not in methods:
                methods = methods[:1]  # the first fallback alone (maxangle; see FEW_STARS_MAX_TRIALS)
                if trial_limit is None:  # over every member's fallback
                    trial_limit = trials + (FEW_STARS_MAX_TRIALS if len(obs) <= QUERY_STARS else MANY_STARS_MAX_TRIALS)
            db = member
            before = trials
            found, used, trials = _identify(obs, db, methods, sigma, options, deadline, hint, trials, tried,
                                            misses, trial_limit, unprovable)
            if found is not None or time.perf_counter() > deadline:
                break
            if SMALL_FRAME_FALLBACK_FIRST and methods == ["quad"] and small and misses and all(misses):
                if trial_limit is not None:
                    trial_limit += trials - before  # the budget is the fallbacks' own (FEW_STARS_MAX_TRIALS)
                fallback_next(order, i)
        if found is not None or time.perf_counter() > deadline:
            break
    t2 = time.perf_counter()
    timings["identify"] = (t2 - t1) * 1e3
    if found is None:
        timings["total"] = (time.perf_counter() - t0) * 1e3
        sparse = isinstance(given, NavDatabaseSet) and 3 <= len(obs) <= SPARSE_ADVICE_STARS
        return no_solution(method, tried, trials, t2 > deadline, timings, unprovable, len(obs),
                           sparse_advice(obs.cameras) if sparse else "")
    if COMPILED_SETTLE and len(obs.cameras) == 1 and options.epoch is None and options.observer_velocity_km_s is None:
        st = settle(obs, db, deepest, found, sigma, options.match_radius_px, options.max_false_prob)
        if st is not None:  # the first pass's own finish, compiled (None: the fit is re-examined below)
            sol = solution_of(*st.columns, st.rms_arcsec, st.sigma_arcsec, st.false_prob, used)
            return _stamped(sol, tried, timings, t0, t2)
    if deepest is not db:
        refined = refine_deeper(obs, db, deepest, found, sigma, options.match_radius_px, options.max_false_prob)
        if refined is not None:
            db, found = deepest, refined
    return _stamped(solution(obs, db, found, used, sigma * obs.pixel_scale_rad, options), tried, timings, t0, t2)


def _timed(sol: Solution, timings: dict[str, float], t0: float, t2: float) -> Solution:
    """``sol``, made with its ``methods_tried`` and this ``timings`` dict, with the stage times
    ``_stamped`` adds (ms; building the answer began at ``t2``, the frame at ``t0``)."""
    now = time.perf_counter()
    timings["attitude"] = (now - t2) * 1e3
    timings["total"] = (now - t0) * 1e3
    return sol


def _stamped(sol: Solution, tried: list[str], timings: dict[str, float], t0: float, t2: float) -> Solution:
    """``sol`` with the methods that ran and the stage times (ms; building the answer began
    at ``t2``, the frame at ``t0``)."""
    object.__setattr__(sol, "methods_tried", tuple(dict.fromkeys(tried)))
    object.__setattr__(sol, "timings_ms", timings)
    return _timed(sol, timings, t0, t2)


_IDENTITY = IDENTITY_MOUNTING  # the one rig_arrays recognises

_ONE_CAMERA = [_IDENTITY]


def _identify(
    obs: Observation, db: NavDatabase, methods: list[str], sigma: float, options: SolveOptions,
    deadline: float, hint: tuple[Quaternion, float] | None, trials: int, tried: list[str] | None = None,
    misses: list[bool] | None = None, trial_limit: int | None = None, unprovable: list[str] | None = None,
) -> tuple[Verified | None, str, int]:
    """One pass of every method at centroid error ``sigma`` (px); ``trials`` hypotheses were
    already tried on this frame (they count in the coincidence bound). Appends the name of each
    method it runs to ``tried``, and to ``unprovable`` each it skips because no answer of it could
    pass the coincidence bound on this frame; stops at ``deadline`` (or once ``trial_limit``
    hypotheses were tried) without starting another method."""
    radius = options.match_radius_px or max(2.5, 3.0 * sigma)
    tol = (3.0 * math.sqrt(2.0) * sigma + 0.5) * obs.pixel_scale_rad
    if len(obs) < Verifier.min_matches:  # only a sparse proof can name so few stars (SPARSE_PROOF_METHODS)
        methods = [name for name in methods if name in SPARSE_PROOF_METHODS]
    elif len(obs) < QUAD_MIN_STARS and len(obs.cameras) == 1:  # quad would return at once
        methods = [name for name in methods if name != "quad"]
    if not methods:
        return None, "", trials  # (a 3-4-star frame's quad passes: ~5 us each for the Verifier alone)
    verifier = Verifier(db, obs, match_radius_px=radius, max_false_prob=options.max_false_prob, trials=trials,
                        deadline=deadline, trial_limit=trial_limit)
    used = methods[-1]
    # a 3-4-star frame too few of whose triangles fit a catalogue triple of this member: what
    # cannot prove it is not searched (SPARSE_SCREEN: one compiled call)
    verdict = (screen(obs.vec, db, tol) if SPARSE_SCREEN and len(obs) <= MAX_SCREENED_STARS
               and len(obs.cameras) == 1 and not SCREENED_METHODS.isdisjoint(methods) else SEARCH)
    for name in methods:
        if name in TRIANGLE_PROOF_METHODS and not verifier.could_prove(3):
            if unprovable is not None:
                unprovable.append(name)
            continue  # no answer of this frame could pass the bound (Verifier.could_prove)
        if tried is not None:
            if tried and (time.perf_counter() > deadline or verifier.over_limit()):
                break
            tried.append(name)
        if verdict == HOPELESS and name in SCREENED_METHODS or verdict == SPARSE_ONLY and name in VERIFIER_ONLY:
            continue
        ctx = SolveContext(obs, verifier, tol, deadline, options.max_stars, sparse_only=verdict == SPARSE_ONLY)
        found = get_matcher(db, name).identify(ctx) or verifier.best_marginal()
        if name == "quad" and misses is not None:
            misses.append(found is None and verifier.exhausted)
        if found is not None and hint is not None and not _near_hint(found.matrix, hint):
            found = None
        if found is not None:
            return found, name, verifier.trials
    return None, used, verifier.trials


def _first_sight(db: NavDatabase | NavDatabaseSet, camera: Camera, method: str, options: SolveOptions,
                 plan: list[tuple[NavDatabase, list[str]]], deepest: NavDatabase) -> CameraSetup | None:
    """The :class:`~.camera_setup.CameraSetup` of a camera seen for the first time (kept on
    ``db``), or None where ``auto``'s compiled first pass does not apply: a distorted camera,
    an epoch or observer velocity to correct for, a plan that does not start with ``quad``."""
    if (not COMPILED_FIRST_PASS or camera.distortion or options.epoch is not None
            or options.observer_velocity_km_s is not None or not plan or plan[0][1][:1] != ["quad"]):
        return None
    static = _static_args(plan[0][0], deepest, camera, options.centroid_sigma_px, options.match_radius_px,
                          options.max_false_prob)
    setup = CameraSetup(camera, options, method, plan, deepest, static, pack(static),
                        camera_probes(camera, IDENTITY_MOUNTING))
    keep_setup(db, setup)
    return setup


def _frame_chain(setup: CameraSetup, n: int, method: str, options: SolveOptions, t0: float | None,
                 build: bool = False) -> ChainSetup | None:
    """The chain's arguments where the pipeline would run it after the first pass's
    exhaustive miss (:mod:`.frame_chain`; a frame of ``n`` stars, its clock started at ``t0``,
    None: no clock to check), if the set-up keeps them, else None (the first pass alone; the
    rest as before). ``build``: make them if not kept (after such a miss)."""
    if not (FRAME_CHAIN_CALL and COMPILED_FALLBACKS and options.retry_sigma_factor <= 1):
        return None
    few = n <= QUERY_STARS
    if not (SMALL_FRAME_FALLBACK_FIRST or not few):
        return None
    if t0 is not None and t0 + options.timeout_ms / 1e3 - time.perf_counter() < MIN_CLOCK_S + FIRST_PASS_CLOCK_S:
        return None  # (the chain does not look at the clock: fallback_pass.MIN_CLOCK_S)
    return chain_setup(setup, n, FEW_STARS_MAX_TRIALS if few else MANY_STARS_MAX_TRIALS,
                       method == "auto" and n <= FIRST_QUAD_ONLY_STARS, build=build)


def _observation(frames: Sequence[tuple[Centroids, Camera, object]], mountings: list[np.ndarray]) -> Observation:
    """The stars of every camera as body vectors, brightest first (see :class:`Observation`)."""
    if len(frames) == 1 and len(frames[0][0]):  # one camera, every frame: no concatenation
        cents, cam, _ = frames[0]
        if cam.distortion:
            order = (-np.asarray(cents.flux)).argsort(kind="stable")
            xy = np.asarray(cents.xy, dtype=np.float64)[order]
            vec, flux = cam.pixel_to_vector(xy), np.asarray(cents.flux, dtype=np.float64)[order]
        else:
            order, xy, vec, flux = brightest_first(np.ascontiguousarray(cents.xy, dtype=np.float64),
                                                   np.ascontiguousarray(cents.flux, dtype=np.float64),
                                                   float(cam.cx), float(cam.cy), float(cam.f_px))
        if mountings[0] is not _IDENTITY and not np.array_equal(mountings[0], _IDENTITY):
            vec = vec @ mountings[0]
        camera, rows, _ = frame_rows(len(order))
        return observation_of(vec, xy, order, camera, (cam,), tuple(mountings), (rows,), flux)
    vecs, xys, idx, cams, fluxes = [], [], [], [], []
    for c, (cents, cam, _) in enumerate(frames):
        if len(cents) == 0:
            continue
        v_cam = cam.pixel_to_vector(cents.xy)
        vecs.append(v_cam @ mountings[c])  # body = M^T cam, for row vectors
        xys.append(cents.xy)
        idx.append(np.arange(len(cents)))
        cams.append(np.full(len(cents), c))
        fluxes.append(cents.flux)
    if not vecs:
        z = np.zeros((0, 3))
        return Observation(z, np.zeros((0, 2)), np.zeros(0, np.int64), np.zeros(0, np.int64),
                           tuple(f[1] for f in frames), tuple(mountings))
    flux = np.concatenate(fluxes)
    order = np.argsort(-flux, kind="stable")
    return Observation(
        np.concatenate(vecs)[order],
        np.concatenate(xys)[order],
        np.concatenate(idx)[order].astype(np.int64),
        np.concatenate(cams)[order].astype(np.int64),
        tuple(f[1] for f in frames),
        tuple(mountings),
        flux=flux[order],
    )


def _near_hint(r: np.ndarray, hint: tuple[Quaternion, float]) -> bool:
    q, radius_deg = hint
    rh = quat_to_matrix(np.asarray(q, dtype=float))
    cosang = float(np.clip(r[2] @ rh[2], -1, 1))
    return math.degrees(math.acos(cosang)) <= radius_deg


def solve_image(
    image: np.ndarray,
    camera: Camera,
    db: NavDatabase | NavDatabaseSet,
    *,
    method: str = "auto",
    hint: tuple[Quaternion, float] | None = None,
    options: SolveOptions = DEFAULT_OPTIONS,
    detect: dict[str, Any] | None = None,
) -> Solution:
    """Detect the stars of a monochrome image, identify them, and attach the FITS WCS.

    ``detect`` passes keyword options to :func:`service.core.centroid.extract`. The image must
    match the camera's size.
    """
    from .centroid import extract

    if image.ndim != 2:
        raise InvalidInputError("image", f"expected a 2-D monochrome image, got shape {image.shape}")
    if image.shape != (camera.height, camera.width):
        raise InvalidInputError(
            "camera", f"image is {image.shape[1]}x{image.shape[0]} px, camera says {camera.width}x{camera.height}"
        )
    t0 = time.perf_counter()
    found = extract(image, **(detect or {}))
    t_detect = (time.perf_counter() - t0) * 1e3
    sol = solve(found.centroids, camera, db, method=method, hint=hint, options=options)
    timings = {"detect": t_detect, **sol.timings_ms}
    timings["total"] = timings.get("total", 0.0) + t_detect
    object.__setattr__(sol, "timings_ms", timings)
    object.__setattr__(sol, "n_detected", len(found))
    rows = np.column_stack([found.centroids.xy, found.centroids.flux]).round(3)
    object.__setattr__(sol, "detected", tuple((float(x), float(y), float(f)) for x, y, f in rows))
    if sol.solved and sol.quaternion is not None:
        fitted = camera if sol.fov_deg is None else replace(  # (the focal length a search fitted)
            camera, f_px=Camera.from_fov(sol.fov_deg, camera.width, camera.height).f_px)
        object.__setattr__(sol, "wcs", tan_wcs(quat_to_matrix(np.asarray(sol.quaternion)), fitted))
    return sol


def _ensure_warm(db: NavDatabase | NavDatabaseSet) -> None:
    """:func:`~service.core.warmup.warm_up` ``db`` once (the first solve on a freshly opened
    database would otherwise spend its time limit loading compiled kernels and building indexes)."""
    if not db.__dict__.get("_warm"):
        from .warmup import warm_up  # (warmup solves through this module)

        warm_up(db)  # marks ``db`` (and a set's members) warm before its own solves


def __getattr__(name: str) -> Any:
    """``warm_up``, which lives in :mod:`service.core.warmup` (it solves through this module),
    is still importable from here."""
    if name == "warm_up":
        from .warmup import warm_up

        return warm_up
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


__all__ = ["DEFAULT_OPTIONS", "SolveOptions", "solve", "solve_image", "solve_rig", "tan_wcs"]
