"""What every identification method provides, and the context it solves in."""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Protocol, runtime_checkable

import numpy as np

from ..catalog import StarTable
from ..navdb.reader import NavDatabase
from ..verify import Observation, Verified, Verifier
from ._pairs import PairLimits, SharedPairs

Progress = Callable[[str, float], None]


@dataclass
class SolveContext:
    """Everything a matcher needs for one frame.

    Attributes
    ----------
    obs : Observation
        The frame's stars, brightest first, as body-frame unit vectors.
    verifier : Verifier
        Proves or refuses hypotheses.
    tol_rad : float
        Tolerance on an inter-star angle, radians (from the centroid noise).
    deadline : float
        ``time.perf_counter()`` value after which the matcher gives up.
    max_stars : int
        How many of the brightest stars a matcher may combine into patterns.
    sparse_only : bool
        Only a proof naming fewer stars than the verifier pairs (``triangle``'s unique-triangle
        proof) could name this frame: the pipeline's screen of a 3-4-star frame found too few
        of its triangles fitting a catalogue triple for the verifier's (:mod:`~..sparse_screen`).
    """

    obs: Observation
    verifier: Verifier
    tol_rad: float
    deadline: float
    max_stars: int = 12
    sparse_only: bool = False

    def expired(self) -> bool:
        """Out of time or of hypotheses (the verifier's ``trial_limit``), or a marginal answer
        has had its chance to be beaten."""
        return time.perf_counter() > self.deadline or self.verifier.settled() or self.verifier.over_limit()


class Matcher(Protocol):
    """A method's solver over one opened database."""

    def identify(self, ctx: SolveContext) -> Verified | None:
        """Propose hypotheses to ``ctx.verifier`` until one is proven; None if none is."""
        ...


class Method(Protocol):
    """An identification method: builds its tables, and makes a matcher over them."""

    name: str
    summary: str

    def build_tables(
        self, stars: StarTable, config: Any, params: dict[str, Any], progress: Progress
    ) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
        """Arrays to store under the method's group, and the parameters used."""
        ...

    def matcher(self, db: NavDatabase) -> Matcher:
        """A matcher over the method's tables in ``db``."""
        ...


@runtime_checkable
class PairMethod(Method, Protocol):
    """A method that reads the shared star-pair table (the database's ``pairs/`` group).

    The builder asks every such method for its :meth:`pair_limits`, builds one table covering
    them all, stores it once and passes it to ``build_tables(..., shared=...)``; the reader
    hands each method its rows of it as ``db.tables[name]["pairs"]`` and ``["angles"]``.
    Methods without ``pair_limits`` are built as before (``build_tables`` without ``shared``).
    """

    def pair_limits(self, config: Any, params: dict[str, Any]) -> PairLimits:
        """Separations the method needs from the pair table, degrees."""
        ...

    def build_tables(
        self, stars: StarTable, config: Any, params: dict[str, Any], progress: Progress,
        *, shared: SharedPairs | None = None,
    ) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
        """The method's own arrays (derived from ``shared``'s rows within its limits) and the
        parameters used; ``shared`` is required."""
        ...
