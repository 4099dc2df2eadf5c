"""``auto``'s first pass as one compiled call: body vectors in, the fitted attitude out.

For a frame of one camera whose search plan starts with ``quad``, the steps that
:func:`service.core.pipeline.solve_rig` otherwise takes through four compiled calls and the
Python between them run in one (:func:`first_pass_kernel`):

1. the ``quad`` search on the plan's first member (:func:`~.methods.quad_kernel.quad_search`:
   patterns, lookup, screen, pairing, near-miss test, coincidence bound); when it ends with
   marginal answers only, the likeliest if they all agree (:func:`~.verify.marginal_choice`,
   ``Verifier.best_marginal``'s own choice: ~3.5% of seed 000's and 001's frames, 12% of seed
   002's);
2. when the plan's deepest member is another one, the answer re-verified against its deeper
   star table (what ``deeper.refine_deeper`` does with :func:`~.answer.recheck`), unless no
   unpaired star lies near one of its stars (:func:`~.check_kernel.could_pair_more`);
3. the answer's checks: close doubles named, implausible pairs dropped
   (:func:`~.answer.answer_kernel`);
4. the final fit: Wahba refit if the pairs changed, residuals, RMS and the pooled 1-sigma
   (:func:`~.attitude.estimate`); where a pair lies past the match radius under it, the stars
   paired again from it and checked again (:func:`~.answer.repair_kernel`), and fitted again.

Python converts the input (:func:`~service.core.pipeline._observation`) and builds the answer;
for a camera whose set-up is kept (:mod:`~service.core.camera_setup`) the call takes the
centroids as given and sorts them and makes their vectors itself
(:func:`frame_first_pass_kernel`), so a frame it proves needs no observation at all.
The journey is one-way: a frame ``quad`` does not prove comes back with the search's own
result, which the usual path takes up without searching again (``prefetch``), so nothing is
done twice; so does an answer whose fit's own noise is over 2.5 declared sigma, for the
general path's ``trimmed_basin`` to re-examine. Every answer is the one the four-call path
gives; ``tests/core/test_first_pass.py`` compares them frame by frame.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, NamedTuple

import numpy as np
from numba import njit

from ._entry import EntryCall, plain, sole_entry
from .answer import FIELD_MARGIN_DEG, answer_kernel, repair_kernel, star_mags
from .attitude import ARCSEC_PER_RAD, PRIOR_DOF, _fit_stats, pooled_sigma, wahba_kernel
from .camera import brightest_first
from .check_kernel import DEEPER_REACH, could_pair_more, pairable_count, recheck_could_pass, recheck_pairs
from .hidden import hidden_neighbours
from .methods import get_matcher
from .methods.quad import MAX_CHECKS, MAX_PROBES, QUERY_STARS, QuadMatcher
from .methods.quad_kernel import STATUS_FOUND, STATUS_MARGINAL, pack_search, quad_search
from .navdb.reader import NavDatabase
from .packed import Packed, pack
from .solution import answer_columns, star_hips
from .star_index import field_grid, star_vec64
from .trimmed import MIN_PAIRS as TRIM_MIN_PAIRS
from .trimmed import MIN_SIGMA_PX, SUSPECT_SIGMA, _robust_sigma_px
from .types import MatchedStars, Solution, solved_solution_of
from .verify import NEAR_MARGIN_DEG, Observation, Verified, Verifier, _image_probes, marginal_choice


@dataclass(frozen=True)
class Deeper:
    """The deeper member's arrays for step 2 (built once per pair of members).

    Attributes
    ----------
    rows : (S,) int64
        The deeper member's row of each star of the searched member (-1: not there).
    star_vec : (D, 3) float64
        The deeper member's star vectors (ICRS).
    """

    rows: np.ndarray
    star_vec: np.ndarray


def deeper_arrays(shallow: NavDatabase, deep: NavDatabase) -> Deeper:
    """:class:`Deeper` for re-verifying answers of ``shallow`` against ``deep`` (cached on
    ``shallow``)."""
    cache = shallow.__dict__.setdefault("_deeper", {})
    key = id(deep)
    got = cache.get(key)
    if got is None or got[0] is not deep:
        hip_s = np.asarray(shallow.stars.hip)
        hip_d = np.asarray(deep.stars.hip)
        order = np.argsort(hip_d, kind="stable")
        pos = np.minimum(np.searchsorted(hip_d[order], hip_s), len(hip_d) - 1)
        rows = order[pos]
        rows = np.where(hip_d[rows] == hip_s, rows, -1).astype(np.int64)
        got = cache[key] = (deep, Deeper(rows, star_vec64(deep)))
    return got[1]


class FirstPass(NamedTuple):
    """What :func:`first_pass` found.

    ``search`` is the ``quad`` search's own result as two arrays
    (:func:`~.methods.quad_kernel.unpack_search` makes it ``quad_search``'s tuple;
    ``search[0][:4]`` holds its status, trials, patterns and whether it looked up every
    pattern); when ``solved`` the other fields hold the answer: observed and catalogue rows (of ``db``),
    the ICRS -> camera matrix, the false-match bound, and the fit's residuals (arcsec, per pair),
    RMS (arcsec) and 1-sigma about x, y, z (arcsec); ``columns`` everything the answer reports
    (:func:`~.solution.solution_of` makes it a ``Solution``).
    """

    search: tuple[Any, ...]
    solved: bool
    db: NavDatabase
    obs_rows: np.ndarray
    cat_rows: np.ndarray
    matrix: np.ndarray
    false_prob: float
    residuals_arcsec: np.ndarray
    rms_arcsec: float
    sigma_arcsec: tuple[float, float, float]
    trials: int
    columns: tuple[np.ndarray, np.ndarray] | None = None
    """When solved: what the answer reports (:func:`~.solution.answer_columns`), made in the call."""


def first_pass(obs: Observation, member: NavDatabase, deepest: NavDatabase, sigma_px: float,
               match_radius_px: float | None, max_false_prob: float, static: tuple[Any, ...] | None = None
               ) -> FirstPass:
    """``auto``'s first pass on a one-camera observation: ``quad`` on ``member``, the answer
    re-verified against ``deepest`` (if another member), checked and fitted, in one compiled
    call. ``sigma_px``: the declared centroid error (px, per axis); ``static``: the call's
    :func:`_static_args` for these, if the caller keeps them."""
    k = obs.kernel_arrays
    if static is None:
        static = _static_args(member, deepest, obs.cameras[0], sigma_px, match_radius_px, max_false_prob)
    flux = obs.flux if obs.flux is not None else _NO_FLUX
    probes = _image_probes(obs)
    solved, used_deep, ints, floats = first_pass_kernel(obs.vec, obs.xy, flux, obs.flux is not None, k.mounts,
                                                        k.cams, k.dist, k.rows, k.row_off, obs.index, probes,
                                                        *static)
    if not solved:
        return unsolved(ints, floats, member)
    return _solved(ints, floats, deepest if used_deep else member)


def unsolved(ints: np.ndarray, floats: np.ndarray, member: NavDatabase) -> FirstPass:
    """The :class:`FirstPass` of a search the call did not prove (its packed result in hand)."""
    return FirstPass((ints, floats), False, member, _NO_ROWS, _NO_ROWS, floats[:9].reshape(3, 3), 1.0, _NO_RES, 0.0,
                     (0.0, 0.0, 0.0), int(ints[1]))


def solved_solution(ints: np.ndarray, floats: np.ndarray, method: str = "quad",
                    methods_tried: tuple[str, ...] = ("quad",), timings_ms: dict[str, float] | None = None) -> Solution:
    """The :class:`~.types.Solution` of a proven first pass (or of a fallback's answer settled
    in the same call, named ``method``), straight from the arrays :func:`settle_kernel` packs
    (what ``solution_of(*fp.columns, ...)`` gives, without the :class:`FirstPass` between, and
    without slicing the stars' columns: :meth:`~.types.MatchedStars.packed`)."""
    n = int(ints[1])
    prob, rms, sd0, sd1, sd2 = floats[9:14].tolist()
    f0 = 14 + n  # the answer's floats: its 7 head numbers, then the stars' columns (solution.answer_columns)
    q0, q1, q2, q3, ra, dec, roll = floats[f0:f0 + 7].tolist()
    return solved_solution_of(method, (q0, q1, q2, q3), ra, dec, roll, MatchedStars.packed(ints, floats, 2 + 2 * n, f0),
                              rms, prob, (sd0, sd1, sd2), methods_tried, timings_ms)


@njit(cache=True, nogil=True)
def frame_first_pass_kernel(xy_in, flux_in, cx, cy, f_px, mounts, cams, dist, rows, row_off, probes, static):
    """:func:`first_pass_kernel` on a pinhole camera's centroids as given (px, fluxes): the
    stars sorted brightest first and turned into unit vectors here
    (:func:`~.camera.brightest_first`), so a frame the pass proves needs no
    :class:`~.verify.Observation`. ``static``: :func:`_static_args` as one
    :class:`~.packed.Packed` (handed over as one pointer, not ~60 arrays)."""
    order, xy, vec, flux = brightest_first(xy_in, flux_in, cx, cy, f_px)
    return first_pass_kernel(vec, xy, flux, True, mounts, cams, dist, rows, row_off, order, probes, *static.args)


def kernel_entry() -> Any:
    """:func:`frame_first_pass_kernel`'s compiled entry point (``entry(xy, flux, cx, cy, f_px,
    mounts, cams, dist, rows, row_off, probes, packed)``), or None unless the kernel holds
    exactly one compiled signature.

    Asked after a call through the dispatcher: that call's argument types are then the one
    signature's, and the same set-up's later frames (the same static arguments, the centroids as
    C-contiguous float64 arrays of 2 and 1 dimensions) have them too. The entry skips the
    dispatcher's typing of the arguments (numba unboxes them, checking each array's dtype but
    not its dimensions: the caller checks those), 2-9 us a frame when the static arguments were
    ~60 of them (``/work/s27/dispatch.py``; they are one :class:`~.packed.Packed` since session 35).
    Kept once taken: iterating the dispatcher's dict of overloads costs ~40 us, a camera's first
    sight's whole Python budget again (each real image is one)."""
    if len(frame_first_pass_kernel.overloads) != 1:
        return None
    if _ENTRY[0] is None:  # (the one signature compiled or loaded is the first: overloads only grow)
        _ENTRY[0] = sole_entry(frame_first_pass_kernel)
    return _ENTRY[0]


_ENTRY: list[Any] = [None]


def _solved(ints: np.ndarray, floats: np.ndarray, db: NavDatabase) -> FirstPass:
    """A solved :class:`FirstPass` from the arrays :func:`settle_kernel` packs (rows of ``db``)."""
    trials, n = ints[:2].tolist()
    prob, rms, sd0, sd1, sd2 = floats[9:14].tolist()
    return FirstPass(_SOLVED_SEARCH, True, db, ints[2:2 + n], ints[2 + n:2 + 2 * n], floats[:9].reshape(3, 3), prob,
                     floats[14:14 + n], rms, (sd0, sd1, sd2), trials, (ints[2 + 2 * n:], floats[14 + n:]))


STATIC_CACHE_SIZE = 64


class _MemberArrays(NamedTuple):
    """The first pass's arguments that depend on the two members alone (none on the camera or
    the options), gathered once per member pair: a camera seen for the first time (each real
    image brings its own) then costs its own numbers and a few tuple joins, not a dozen
    lookups."""

    deepest: NavDatabase
    star_vec: np.ndarray
    deep: tuple[Any, ...]
    """has_deep, the deeper member's rows of this member's stars and its star vectors."""
    mags: tuple[np.ndarray, np.ndarray]
    ids: tuple[Any, ...]
    """Both members' HIP numbers and hidden neighbours, in the kernel's order."""


def _member_arrays(member: NavDatabase, deepest: NavDatabase) -> _MemberArrays:
    """:class:`_MemberArrays` for ``member`` refined against ``deepest`` (kept on ``member``)."""
    kept = member.__dict__.setdefault("_first_pass_arrays", {})
    got = kept.get(id(deepest))
    if got is not None and got.deepest is deepest:
        return got
    has_deep = deepest is not member
    deep = deeper_arrays(member, deepest) if has_deep else _NO_DEEPER
    got = kept[id(deepest)] = _MemberArrays(
        deepest, star_vec64(member), (has_deep, deep.rows, deep.star_vec), (star_mags(member), star_mags(deepest)),
        (star_hips(member), star_hips(deepest), *hidden_neighbours(member), *hidden_neighbours(deepest)))
    return got


def _static_args(member: NavDatabase, deepest: NavDatabase, cam: Any, sigma_px: float,
                 match_radius_px: float | None, max_false_prob: float) -> tuple[Any, ...]:
    """The kernel's arguments that depend only on the databases, the camera and the options,
    kept per member (every frame of a camera passes the same; building them costs ~5 us)."""
    scale = cam.pixel_scale_rad
    diagonal = cam.diagonal_fov_deg
    key = (id(deepest), diagonal, scale, sigma_px, match_radius_px, max_false_prob)
    cache = member.__dict__.setdefault("_first_pass_args", {})
    got = cache.get(key)
    if got is not None and got[0] is deepest:
        return got[1]
    qm: QuadMatcher = get_matcher(member, "quad")
    settle = _settle_kept(member, deepest, key)
    star_vec, near_chord, radius = settle[:3]
    near = field_grid(member, diagonal / 2 + NEAR_MARGIN_DEG).kernel_args()
    tol = (3.0 * math.sqrt(2.0) * sigma_px + 0.5) * scale
    static = ((QUERY_STARS, tol, qm.patterns, qm.table, qm.spill, qm.ratio_bin, qm.edge_bin, qm.edge_max, star_vec)
              + tuple(qm.screen) + near
              + (near_chord, radius, scale, float(max_false_prob), float(Verifier.strong_false_prob),
                 int(Verifier.confirm_patterns), int(Verifier.screen_stars), MAX_PROBES, MAX_CHECKS)
              + settle[4:-1] + (3.0 * radius * scale, settle[-1]))
    if len(cache) >= STATIC_CACHE_SIZE:
        cache.clear()
    cache[key] = (deepest, static)
    return static


def _settle_args(member: NavDatabase, deepest: NavDatabase, cam: Any, sigma_px: float,
                 match_radius_px: float | None, max_false_prob: float) -> tuple[Any, ...]:
    """:func:`settle_kernel`'s arguments from ``star_vec`` on (the member's, the deepest's and the
    options'), kept per member as :func:`_static_args` keeps its own."""
    return _settle_kept(member, deepest, _settle_key(deepest, cam, sigma_px, match_radius_px, max_false_prob))


def _settle_key(deepest: NavDatabase, cam: Any, sigma_px: float, match_radius_px: float | None,
                max_false_prob: float) -> tuple[Any, ...]:
    """What :func:`_settle_args` depends on, as :func:`_settle_kept`'s key."""
    return (id(deepest), cam.diagonal_fov_deg, cam.pixel_scale_rad, sigma_px, match_radius_px, max_false_prob)


def _settle_kept(member: NavDatabase, deepest: NavDatabase, key: tuple[Any, ...]) -> tuple[Any, ...]:
    """:func:`_settle_args` by its key, ``(id(deepest), diagonal deg, pixel scale rad, sigma_px,
    match_radius_px, max_false_prob)``: :func:`_static_args` has made it already (a camera seen
    for the first time computed its field and scale twice, and the key)."""
    return _settle_entry(member, deepest, key)[1]


def _settle_entry(member: NavDatabase, deepest: NavDatabase, key: tuple[Any, ...]) -> list[Any]:
    """``[deepest, args, packed]`` kept under :func:`_settle_kept`'s key (``packed``: ``args``
    as one :class:`~.packed.Packed`, None until :func:`_settle_packed` asks)."""
    cache = member.__dict__.setdefault("_settle_args", {})
    got = cache.get(key)
    if got is not None and got[0] is deepest:
        return got
    got = [deepest, _settle_from(member, deepest, _member_arrays(member, deepest), *key[1:]), None]
    if len(cache) >= STATIC_CACHE_SIZE:
        cache.clear()
    cache[key] = got
    return got


def _settle_packed(member: NavDatabase, deepest: NavDatabase, cam: Any, sigma_px: float,
                   match_radius_px: float | None, max_false_prob: float) -> Packed:
    """:func:`_settle_args` as one :class:`~.packed.Packed` (kept beside them), as
    :func:`packed_settle_kernel` takes them."""
    got = _settle_entry(member, deepest, _settle_key(deepest, cam, sigma_px, match_radius_px, max_false_prob))
    if got[2] is None:
        got[2] = pack(got[1])
    return got[2]


def _settle_from(member: NavDatabase, deepest: NavDatabase, arrays: _MemberArrays, diagonal: float, scale: float,
                 sigma_px: float, match_radius_px: float | None, max_false_prob: float) -> tuple[Any, ...]:
    """:func:`_settle_args`' tuple, made anew for a camera of this diagonal (deg) and pixel
    scale (rad)."""
    radius = match_radius_px or max(2.5, 3.0 * sigma_px)
    sigma_rad = sigma_px * scale
    answer_radius = match_radius_px or max(2.5, 3.0 * sigma_rad / scale)  # as finish.solution has it
    near_deg = diagonal / 2 + NEAR_MARGIN_DEG
    field_deg = diagonal / 2 + FIELD_MARGIN_DEG
    near_chord = 2 * math.sin(math.radians(near_deg) / 2)
    field_chord = 2 * math.sin(math.radians(field_deg) / 2)
    deep_near = field_grid(deepest, near_deg).kernel_args() if arrays.deep[0] else _NO_GRID
    strong = min(max_false_prob, Verifier.strong_false_prob)
    return ((arrays.star_vec, near_chord, float(radius), float(scale)) + arrays.deep + deep_near + (float(strong),)
            + field_grid(member, field_deg).kernel_args() + arrays.mags
            + (field_chord, float(answer_radius), float(sigma_px), float(sigma_rad), PRIOR_DOF) + arrays.ids
            + (SUSPECT_SIGMA * max(float(sigma_px), MIN_SIGMA_PX),))


def settle(obs: Observation, member: NavDatabase, deepest: NavDatabase, found: Verified, sigma_px: float,
           match_radius_px: float | None, max_false_prob: float) -> FirstPass | None:
    """The answer of ``found``, proven on ``member`` by a method other than the first pass
    (one camera, no epoch or aberration), as the first pass finishes its own: re-verified
    against ``deepest``, checked and fitted in one compiled call (:func:`settle_kernel`). None
    where the general path must re-examine the fit (``trimmed_basin``)."""
    k = obs.kernel_arrays
    flux = obs.flux if obs.flux is not None else _NO_FLUX
    head = (obs.vec, obs.xy, flux, obs.flux is not None, k.mounts, k.cams, k.dist, k.rows, k.row_off, obs.index,
            np.array(found.obs, np.int64), np.array(found.cat, np.int64), np.array(found.matrix, np.float64),
            float(found.false_prob), int(found.n_trials))
    if plain(obs.vec, obs.xy, flux, obs.index):  # the usual types: the entry point (_entry), one pointer to hand over
        ok, used_deep, ints, floats = _SETTLE(*head, _settle_packed(member, deepest, obs.cameras[0], sigma_px,
                                                                    match_radius_px, max_false_prob))
    else:
        ok, used_deep, ints, floats = settle_kernel(
            *head, *_settle_args(member, deepest, obs.cameras[0], sigma_px, match_radius_px, max_false_prob))
    if not ok:
        return None
    return _solved(ints, floats, deepest if used_deep else member)


_NO_FLUX = np.zeros(0)
_NO_ROWS = np.zeros(0, np.int64)
_NO_RES = np.zeros(0)
_SOLVED_SEARCH = (STATUS_FOUND,)
"""A solved first pass's ``search``: only its status is kept (the answer holds the rest)."""
_NO_DEEPER = Deeper(np.zeros(0, np.int64), np.zeros((0, 3)))
_NO_DEEPER.star_vec.flags.writeable = False  # as star_vec64's: one compiled signature, deeper member or not
_NO_GRID = (1.0, 1, np.zeros(1, np.int64), np.zeros(2, np.int64), np.zeros(0, np.int64), np.zeros(1, np.int64))


@njit(cache=True, nogil=True)
def first_pass_kernel(obs_vec, obs_xy, flux, has_flux, mounts, cams, dist, rows, row_off, obs_index, probes, n_use, tol,
                      patterns, table, spill,
                      ratio_bin, edge_bin, edge_max, star_vec, s_cell, s_side, s_keys, s_starts, s_stars, s_columns,
                      g_cell, g_side, g_keys, g_starts, g_stars, g_columns, near_chord, radius_px, pixel_scale,
                      max_false_prob, strong_false_prob, confirm_patterns, screen_stars, max_probes, max_checks,
                      has_deep, deep_rows, d_vec, d_cell, d_side, d_keys, d_starts, d_stars, d_columns, strong,
                      a_cell, a_side, a_keys, a_starts, a_stars, a_columns, mag, d_mag, field_chord,
                      answer_radius, sigma_px, sigma_rad, prior_dof, hip, d_hip, hidden, hidden_lim, d_hidden,
                      d_hidden_lim, agree_limit, suspect_px):
    """The first pass (see the module's docstring). Returns ``(solved, used_deep, ints, floats)``:
    when solved ``ints`` = trials, n, the n observed rows, the n catalogue rows, then
    :func:`~.solution.answer_columns`' ints, and ``floats`` = the matrix (9, row-major),
    false-match bound, RMS (arcsec), 1-sigma x, y, z (arcsec), the n residuals (arcsec), then
    its floats; otherwise the search's result as :func:`~.methods.quad_kernel.pack_search` packs it."""
    search = quad_search(obs_vec, obs_xy, n_use, tol, patterns, table, spill, ratio_bin, edge_bin, edge_max, star_vec,
                         s_cell, s_side, s_keys, s_starts, s_stars, s_columns, g_cell, g_side, g_keys, g_starts,
                         g_stars, g_columns, near_chord, mounts, cams, dist, rows, row_off, radius_px, pixel_scale,
                         max_false_prob, strong_false_prob, confirm_patterns, screen_stars, np.int64(0), max_probes,
                         max_checks)
    m_obs, m_cat, r, prob, trials = search[3], search[4], search[5], search[6], search[7]
    if search[0] == STATUS_MARGINAL:  # Verifier.best_marginal: the likeliest, if all agree
        k = marginal_choice(search[10], search[11], search[12], search[13], search[14], probes, agree_limit)
        if k >= 0:
            lo, hi = search[12][k], search[12][k + 1]
            m_obs, m_cat, r, prob = search[13][lo:hi].copy(), search[14][lo:hi].copy(), search[10][k].copy(), \
                search[11][k]
            trials = search[15][k]
    elif search[0] != STATUS_FOUND:
        k = -1
    else:
        k = 0
    if k < 0:
        ints, floats = pack_search(search)
        return False, False, ints, floats
    ok, used_deep, ints, floats = settle_kernel(
        obs_vec, obs_xy, flux, has_flux, mounts, cams, dist, rows, row_off, obs_index, m_obs, m_cat, r, prob, trials,
        star_vec, near_chord, radius_px, pixel_scale, has_deep, deep_rows, d_vec, d_cell, d_side, d_keys, d_starts,
        d_stars, d_columns, strong, a_cell, a_side, a_keys, a_starts, a_stars, a_columns, mag, d_mag, field_chord,
        answer_radius, sigma_px, sigma_rad, prior_dof, hip, d_hip, hidden, hidden_lim, d_hidden, d_hidden_lim,
        suspect_px)
    if not ok:
        ints, floats = pack_search(search)  # a fit the general path re-examines (trimmed_basin)
        return False, False, ints, floats
    return True, used_deep, ints, floats


@njit(cache=True, nogil=True)
def settle_kernel(obs_vec, obs_xy, flux, has_flux, mounts, cams, dist, rows, row_off, obs_index, m_obs, m_cat, r, prob,
                  trials, star_vec, near_chord, radius_px, pixel_scale, has_deep, deep_rows, d_vec, d_cell, d_side,
                  d_keys, d_starts, d_stars, d_columns, strong, a_cell, a_side, a_keys, a_starts, a_stars, a_columns,
                  mag, d_mag, field_chord, answer_radius, sigma_px, sigma_rad, prior_dof, hip, d_hip, hidden,
                  hidden_lim, d_hidden, d_hidden_lim, suspect_px):
    """From a proven identification (observed rows ``m_obs`` are catalogue rows ``m_cat`` of the
    searched member, attitude ``r``, bound ``prob`` after ``trials`` hypotheses) to the answer:
    steps 2-4 of the module's docstring. Returns ``(ok, used_deep, ints, floats)`` packed as
    :func:`first_pass_kernel`'s solved answer; ``ok`` False for a fit the general path must
    re-examine (``trimmed_basin``: its own noise over ``suspect_px``)."""
    used_deep = False
    vec, cell, side, keys, starts, stars, columns, mags, hid, hid_lim = star_vec, a_cell, a_side, a_keys, a_starts, \
        a_stars, a_columns, mag, hidden, hidden_lim
    if has_deep and could_pair_more(obs_vec, m_obs, r, DEEPER_REACH * radius_px * pixel_scale, d_cell, d_side,
                                     d_keys, d_starts, d_stars, d_vec, d_columns):
        # deeper.refine_deeper: the stars the deeper member holds are the hypothesis
        n_known = np.int64(0)  # (a literal 0 gave recheck_could_pass a second signature)
        for c in m_cat:
            if deep_rows[c] >= 0:
                n_known += 1
        if n_known >= 3:
            k_obs = np.empty(n_known, np.int64)
            k_cat = np.empty(n_known, np.int64)
            j = 0
            for i in range(len(m_cat)):
                if deep_rows[m_cat[i]] >= 0:
                    k_obs[j] = m_obs[i]
                    k_cat[j] = deep_rows[m_cat[i]]
                    j += 1
            n_pairable = pairable_count(obs_vec, k_obs, r, DEEPER_REACH * radius_px * pixel_scale, d_cell, d_side,
                                        d_keys, d_starts, d_stars, d_vec, d_columns)
            # run only where a recheck could name more stars with a strong bound (~15 us each)
            if recheck_could_pass(len(obs_vec), n_known, n_pairable, len(m_obs), radius_px, cams[0, 3] * cams[0, 4],
                                  trials, strong):
                ok, d_obs, d_cat, d_r, d_prob = recheck_pairs(
                    obs_vec, obs_xy, d_vec, k_obs, k_cat, d_cell, d_side, d_keys, d_starts, d_stars, d_columns,
                    near_chord, mounts, cams, dist, rows, row_off, radius_px, pixel_scale, trials)
                if ok and d_prob <= strong and len(d_obs) > len(m_obs):
                    m_obs, m_cat, r, prob, used_deep = d_obs, d_cat, d_r, d_prob, True
                    vec, cell, side, keys, starts, stars, columns, mags, hid, hid_lim = d_vec, d_cell, d_side, \
                        d_keys, d_starts, d_stars, d_columns, d_mag, d_hidden, d_hidden_lim
    if len(m_obs) >= TRIM_MIN_PAIRS and _robust_sigma_px(obs_vec, vec, m_obs, m_cat, r, pixel_scale) > suspect_px:
        return False, False, np.zeros(0, np.int64), np.zeros(0)
    m_obs, m_cat, moved = answer_kernel(obs_xy, flux, has_flux, m_obs, m_cat, r, vec, mags, cell, side, keys, starts,
                                        stars, columns, field_chord, mounts[0], cams[0], dist[0], answer_radius,
                                        sigma_px, hid, hid_lim)
    o = obs_vec[m_obs]
    ref = vec[m_cat]
    if moved:
        r = wahba_kernel(o, ref, np.ones(len(m_obs)))
    res, rms, sd = _fit_stats(o, ref, r, -1.0)
    if len(m_obs) >= 3 and res.max() > answer_radius * pixel_scale * ARCSEC_PER_RAD:
        # a pair past the match radius under the final fit: paired again from it (answer.repair_kernel)
        m_obs, m_cat, grew = repair_kernel(obs_vec, obs_xy, flux, has_flux, m_obs, m_cat, r, vec, mags, cell, side,
                                           keys, starts, stars, columns, field_chord, mounts, cams, dist, rows,
                                           row_off, radius_px, answer_radius, sigma_px, hid, hid_lim)
        if grew:
            o = obs_vec[m_obs]
            ref = vec[m_cat]
            r = wahba_kernel(o, ref, np.ones(len(m_obs)))
            res, rms, sd = _fit_stats(o, ref, r, -1.0)
    sd = pooled_sigma(res, sd, sigma_rad, prior_dof)
    a_ints, a_floats = answer_columns(r, ref, obs_index[m_obs], m_cat, mags, d_hip if used_deep else hip, res)
    n = len(m_obs)
    ints = np.empty(2 + 2 * n + len(a_ints), np.int64)
    ints[0], ints[1] = trials, n
    ints[2:2 + n] = m_obs
    ints[2 + n:2 + 2 * n] = m_cat
    ints[2 + 2 * n:] = a_ints
    floats = np.empty(14 + n + len(a_floats))
    floats[:9] = r.ravel()
    floats[9], floats[10] = prob, rms
    floats[11:14] = sd
    floats[14:14 + n] = res
    floats[14 + n:] = a_floats
    return True, used_deep, ints, floats


@njit(cache=True, nogil=True)
def packed_settle_kernel(obs_vec, obs_xy, flux, has_flux, mounts, cams, dist, rows, row_off, obs_index, m_obs, m_cat,
                         r, prob, trials, static):
    """:func:`settle_kernel` with the arguments from ``star_vec`` on as one :class:`~.packed.Packed`."""
    return settle_kernel(obs_vec, obs_xy, flux, has_flux, mounts, cams, dist, rows, row_off, obs_index, m_obs, m_cat,
                         r, prob, trials, *static.args)


_SETTLE = EntryCall(packed_settle_kernel)
"""``settle_kernel`` past the dispatcher once its signature is known (:mod:`._entry`)."""
