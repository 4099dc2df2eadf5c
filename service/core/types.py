"""Small value types that flow between the engine's stages.

Conventions (see docs/conventions.md): pixel x = column, y = row, the centre of the top-left
pixel is (0, 0); quaternions are scalar first ``[w, x, y, z]`` and rotate ICRS vectors into the
camera (or body) frame, ``v_cam = R(q) v_icrs``.
"""

from __future__ import annotations

import dataclasses
import enum
import functools
import math
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field
from typing import Any, NamedTuple, overload

import numpy as np
from numpy.typing import NDArray

from .errors import InvalidInputError

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]


class SolveStatus(str, enum.Enum):
    """Outcome of one solve: expected failure is a value, not an exception."""

    SOLVED = "solved"
    NO_SOLUTION = "no_solution"


class NoSolutionReason(str, enum.Enum):
    """Why a solve answered ``no_solution`` (machine-readable; ``Solution.message`` says it in words).

    ``too_few_stars``: fewer than 3 centroids, refused before any method runs; or so few for the
    camera that every method able to run was skipped, since even with every star paired no answer
    of theirs could pass the coincidence bound (``message`` names them).
    ``camera_outside_database``: no member of the database serves the camera's field, refused
    before any method runs. ``no_pattern_match``: the methods ran to the end and no catalogue
    pattern matched the frame's. ``not_proven``: candidates were checked, none was proven beyond
    the coincidence bound. ``time_limit``: the time limit ended the search first.
    """

    TOO_FEW_STARS = "too_few_stars"
    CAMERA_OUTSIDE_DATABASE = "camera_outside_database"
    NO_PATTERN_MATCH = "no_pattern_match"
    NOT_PROVEN = "not_proven"
    TIME_LIMIT = "time_limit"


@dataclass(frozen=True, slots=True)
class Centroids:
    """Star centroids of one camera frame.

    Attributes
    ----------
    xy : (N, 2) float64
        Pixel positions ``(x, y)``: x = column, y = row, origin the centre of the top-left pixel.
    flux : (N,) float64
        Integrated brightness (any linear unit); larger is brighter. Used for ordering only.
    """

    xy: FloatArray
    flux: FloatArray

    @classmethod
    def from_list(cls, rows: Any, *, field_name: str = "centroids") -> Centroids:
        """Build from ``[[x, y], ...]`` or ``[[x, y, flux], ...]``; rows without flux get
        flux decreasing with their index (the list is taken as brightest first)."""
        try:
            arr = np.asarray(rows, dtype=np.float64)
        except (TypeError, ValueError):  # ragged: rows of 2 and of 3 values mixed, or not numbers
            raise InvalidInputError(field_name, "expected a list of [x, y] or [x, y, flux] rows, "
                                                "all of the same length") from None
        if arr.size == 0:
            return cls(np.zeros((0, 2)), np.zeros(0))
        if arr.ndim != 2 or arr.shape[1] not in (2, 3):
            raise InvalidInputError(field_name, "expected a list of [x, y] or [x, y, flux] rows")
        if not np.all(np.isfinite(arr)):
            raise InvalidInputError(field_name, "values must be finite numbers")
        xy = np.ascontiguousarray(arr[:, :2])
        flux = arr[:, 2].copy() if arr.shape[1] == 3 else np.arange(len(arr), 0, -1, dtype=np.float64)
        return cls(xy, flux)

    def __len__(self) -> int:
        return int(self.xy.shape[0])

    def brightest_order(self) -> IntArray:
        """Indices sorted by decreasing flux (stable)."""
        return np.argsort(-self.flux, kind="stable").astype(np.int64)


class StarMatch(NamedTuple):
    """One identified star: an input centroid paired with a catalogue star (a named tuple: an
    answer holds dozens, built on every frame)."""

    centroid: int
    hip: int
    ra_deg: float
    dec_deg: float
    mag: float
    residual_arcsec: float
    camera: int = 0


_star_match = functools.partial(tuple.__new__, StarMatch)
"""``StarMatch`` of a row tuple without the named tuple's Python-level ``__new__`` (what its
``_make`` does; ~3x cheaper)."""


def _star_dict(centroid: int, hip: int, ra_deg: float, dec_deg: float, mag: float, residual_arcsec: float,
               camera: int = 0) -> dict[str, Any]:
    """One identified star in the wire format (the fields of :class:`StarMatch`)."""
    return {"centroid": centroid, "camera": camera, "hip": hip, "ra_deg": ra_deg, "dec_deg": dec_deg, "mag": mag,
            "residual_arcsec": residual_arcsec}


class MatchedStars(Sequence[StarMatch]):
    """The identified stars of an answer: a read-only sequence of :class:`StarMatch`, kept as
    columns and made into tuples on first read.

    An answer names a few dozen stars; making them Python tuples costs about as much as the
    compiled search that found them (~7 us for 25 stars), and a caller that reads only the
    attitude never needs them. Reading, iterating, comparing, hashing and pickling behave as
    for the tuple it stands for (it pickles as that tuple).

    Parameters
    ----------
    columns : sequence of 7 columns
        ``centroid, hip, ra_deg, dec_deg, mag, residual_arcsec, camera`` (arrays or lists of
        equal length), in :class:`StarMatch`'s field order.
    """

    __slots__ = ("_columns", "_rows", "_packed")

    def __init__(self, *columns: Any) -> None:
        self._columns = columns
        self._rows: tuple[StarMatch, ...] | None = None
        self._packed: tuple[np.ndarray, np.ndarray, int, int] | None = None

    @classmethod
    def packed(cls, ints: np.ndarray, floats: np.ndarray, i0: int, f0: int) -> MatchedStars:
        """The stars of :func:`~.solution.answer_columns`' arrays held from ``ints[i0:]`` and
        ``floats[f0 + 7:]`` (after the answer's 7 head numbers), their columns sliced only when
        read: a proven frame's answer is made without the seven slices (~2 us; an answer whose
        stars are never read, as in a batch that writes only the attitude, never makes them)."""
        self = object.__new__(cls)
        self._columns = ()
        self._rows = None
        self._packed = (ints, floats, i0, f0)
        return self

    def _cols(self) -> tuple[Any, ...]:
        """The seven columns (unpacked on first use)."""
        if self._packed is not None:
            ints, floats, i0, f0 = self._packed
            n = (len(ints) - i0) // 3
            f = f0 + 7
            self._columns = (ints[i0:i0 + n], ints[i0 + n:i0 + 2 * n], floats[f:f + n], floats[f + n:f + 2 * n],
                             floats[f + 2 * n:f + 3 * n], floats[f + 3 * n:], ints[i0 + 2 * n:])
            self._packed = None
        return self._columns

    def _tuple(self) -> tuple[StarMatch, ...]:
        if self._rows is None:
            cols = [c.tolist() if isinstance(c, np.ndarray) else c for c in self._cols()]
            self._rows = tuple(map(_star_match, zip(*cols, strict=True)))
            self._columns = ()
        return self._rows

    def __len__(self) -> int:
        if self._rows is not None:
            return len(self._rows)
        if self._packed is not None:
            return (len(self._packed[0]) - self._packed[2]) // 3
        return len(self._columns[0])

    def as_dicts(self) -> list[dict[str, Any]]:
        """The stars as the wire format's dicts, straight from the columns when no tuple was
        made yet."""
        if self._rows is not None:
            return [_star_dict(*s) for s in self._rows]
        cols = [c.tolist() if isinstance(c, np.ndarray) else c for c in self._cols()]
        return list(map(_star_dict, *cols))

    def column(self, name: str) -> list[Any]:
        """One field of :class:`StarMatch` for every star, as a list (from the columns when no
        tuple was made yet: scoring reads three fields of every answer)."""
        i = StarMatch._fields.index(name)
        if self._rows is None:
            col = self._cols()[i]
            return col.tolist() if isinstance(col, np.ndarray) else list(col)
        return [s[i] for s in self._rows]

    @overload
    def __getitem__(self, i: int) -> StarMatch: ...
    @overload
    def __getitem__(self, i: slice) -> tuple[StarMatch, ...]: ...
    def __getitem__(self, i: int | slice) -> StarMatch | tuple[StarMatch, ...]:
        return self._tuple()[i]

    def __iter__(self) -> Iterator[StarMatch]:
        return iter(self._tuple())

    def __eq__(self, other: object) -> bool:
        if isinstance(other, MatchedStars):
            other = other._tuple()
        return self._tuple() == other if isinstance(other, tuple) else NotImplemented

    def __hash__(self) -> int:
        return hash(self._tuple())

    def __repr__(self) -> str:
        return repr(self._tuple())

    def __reduce__(self) -> tuple[Any, ...]:
        return tuple, (self._tuple(),)


@dataclass(frozen=True, slots=True)
class Solution:
    """Result of one solve.

    ``quaternion`` rotates ICRS into the camera frame (or the body frame of a rig), scalar
    first. ``ra_deg``/``dec_deg`` are the boresight (+z) direction; ``roll_deg`` is the position
    angle of image-up (-y) at the boresight, from north through east, in [0, 360).
    ``method`` is the method that produced the answer (for ``no_solution``: the last one tried,
    or the requested name if none ran); ``methods_tried`` the methods that actually ran, in order;
    ``reason`` and ``message`` say why there is no solution (None when solved).
    """

    status: SolveStatus
    method: str
    quaternion: tuple[float, float, float, float] | None = None
    ra_deg: float | None = None
    dec_deg: float | None = None
    roll_deg: float | None = None
    stars: Sequence[StarMatch] = ()
    """The identified stars by camera, then centroid index (a :class:`MatchedStars` when solved)."""
    rms_arcsec: float | None = None
    false_match_probability: float | None = None
    attitude_sigma_arcsec: tuple[float, float, float] | None = None
    timings_ms: dict[str, float] = field(default_factory=dict)
    wcs: dict[str, Any] | None = None
    n_detected: int | None = None
    detected: tuple[tuple[float, float, float], ...] | None = None
    reason: NoSolutionReason | None = None
    methods_tried: tuple[str, ...] = ()
    message: str | None = None
    fov_deg: float | None = None
    """The horizontal field (deg) of the camera the answer was fitted with, when the solve searched
    focal lengths (``SolveOptions.fov_max_error_deg``); None otherwise."""

    @property
    def solved(self) -> bool:
        return self.status is SolveStatus.SOLVED

    def to_dict(self, frame_id: Any = None) -> dict[str, Any]:
        """The result schema shared by the CLI and the API (JSON-ready)."""

        def num(v: float | None) -> float | None:
            return None if v is None or not math.isfinite(v) else float(v)

        return {
            "id": frame_id,
            "status": self.status.value,
            "quaternion": None if self.quaternion is None else [float(v) for v in self.quaternion],
            "ra_deg": num(self.ra_deg),
            "dec_deg": num(self.dec_deg),
            "roll_deg": num(self.roll_deg),
            "stars": self.stars.as_dicts() if isinstance(self.stars, MatchedStars)
            else [_star_dict(*s) for s in self.stars],
            "rms_arcsec": num(self.rms_arcsec),
            "false_match_probability": num(self.false_match_probability),
            "attitude_sigma_arcsec": None
            if self.attitude_sigma_arcsec is None
            else [float(v) for v in self.attitude_sigma_arcsec],
            "method": self.method,
            "methods_tried": list(self.methods_tried),
            "reason": None if self.reason is None else self.reason.value,
            "message": self.message,
            "timings_ms": {k: float(v) for k, v in self.timings_ms.items()},
            **({"wcs": self.wcs} if self.wcs is not None else {}),
            **({"fov_deg": num(self.fov_deg)} if self.fov_deg is not None else {}),
            **({"n_detected": self.n_detected} if self.n_detected is not None else {}),
            **({"centroids": [list(c) for c in self.detected]} if self.detected is not None else {}),
        }


_SOLUTION_SLOTS = {f.name: Solution.__dict__[f.name].__set__ for f in dataclasses.fields(Solution)}
"""Each :class:`Solution` field's slot setter (:func:`solved_solution_of` writes through them)."""
_SOLUTION_FIELDS = ("status", "method", "quaternion", "ra_deg", "dec_deg", "roll_deg", "stars", "rms_arcsec",
                    "false_match_probability", "attitude_sigma_arcsec", "timings_ms", "wcs", "n_detected", "detected",
                    "reason", "methods_tried", "message", "fov_deg")
if tuple(f.name for f in dataclasses.fields(Solution)) != _SOLUTION_FIELDS:  # solved_solution_of sets them by name
    raise AssertionError("Solution's fields changed: update solved_solution_of")
(_set_status, _set_method, _set_quaternion, _set_ra, _set_dec, _set_roll, _set_stars, _set_rms, _set_prob, _set_sigma,
 _set_timings, _set_wcs, _set_n_detected, _set_detected, _set_reason, _set_tried, _set_message,
 _set_fov) = (_SOLUTION_SLOTS[name] for name in _SOLUTION_FIELDS)


def refused_solution_of(method: str, reason: NoSolutionReason, methods_tried: tuple[str, ...], message: str,
                        timings_ms: dict[str, float]) -> Solution:
    """``Solution(SolveStatus.NO_SOLUTION, method, reason=..., methods_tried=..., message=...,
    timings_ms=...)``, the other fields at their defaults, made through the slots as
    :func:`solved_solution_of` makes a proof's (a searched frame's refusal: a quarter of seed
    002's frames at 2 false stars; 4.5 -> ~2.4 us with the setters bound to module names).
    ``tests/core/test_types.py`` checks it equals the dataclass's own."""
    sol = object.__new__(Solution)
    _set_status(sol, SolveStatus.NO_SOLUTION)
    _set_method(sol, method)
    _set_quaternion(sol, None)
    _set_ra(sol, None)
    _set_dec(sol, None)
    _set_roll(sol, None)
    _set_stars(sol, ())
    _set_rms(sol, None)
    _set_prob(sol, None)
    _set_sigma(sol, None)
    _set_timings(sol, timings_ms)
    _set_wcs(sol, None)
    _set_n_detected(sol, None)
    _set_detected(sol, None)
    _set_reason(sol, reason)
    _set_tried(sol, methods_tried)
    _set_message(sol, message)
    _set_fov(sol, None)
    return sol


def solved_solution_of(method: str, quaternion: tuple[float, float, float, float], ra_deg: float, dec_deg: float,
                       roll_deg: float, stars: Sequence[StarMatch], rms_arcsec: float, false_match_probability: float,
                       attitude_sigma_arcsec: tuple[float, float, float], methods_tried: tuple[str, ...] = (),
                       timings_ms: dict[str, float] | None = None) -> Solution:
    """``Solution(SolveStatus.SOLVED, method, quaternion=..., ...)``, the other fields at their
    defaults, made through the slots: the frozen dataclass's ``__init__`` sets each of its 18
    fields with ``object.__setattr__``, 3.4 us against 1.5 here (``/work/s30/sol_init.py``), on
    every solved frame; each slot's setter bound to a module name, 2.4 us against 3.3 through a
    dict of them (``/work/s40/soltime.py``, a slower machine). ``tests/core/test_types.py`` checks
    it equals the dataclass's own."""
    sol = object.__new__(Solution)
    _set_status(sol, SolveStatus.SOLVED)
    _set_method(sol, method)
    _set_quaternion(sol, quaternion)
    _set_ra(sol, ra_deg)
    _set_dec(sol, dec_deg)
    _set_roll(sol, roll_deg)
    _set_stars(sol, stars)
    _set_rms(sol, rms_arcsec)
    _set_prob(sol, false_match_probability)
    _set_sigma(sol, attitude_sigma_arcsec)
    _set_timings(sol, {} if timings_ms is None else timings_ms)
    _set_wcs(sol, None)
    _set_n_detected(sol, None)
    _set_detected(sol, None)
    _set_reason(sol, None)
    _set_tried(sol, methods_tried)
    _set_message(sol, None)
    _set_fov(sol, None)
    return sol
