"""Scoring a solution against known truth (simulated frames, reference solutions)."""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from itertools import accumulate

from .attitude import ARCSEC_PER_RAD
from .types import MatchedStars, Solution

WRONG_BORESIGHT_ARCSEC = 360.0
"""Without per-star truth, a solved frame is wrong when its boresight is off by more than this."""


@dataclass(frozen=True, slots=True)
class Score:
    """How a solve compares with the truth.

    ``correct`` is None when the frame was not solved. ``wrong_stars`` counts matched
    centroids whose HIP differs from the truth (a false star matched to anything is wrong).
    """

    solved: bool
    correct: bool | None
    wrong_stars: int
    cross_boresight_arcsec: float | None
    roll_arcsec: float | None


def attitude_error(q_est: Sequence[float], q_true: Sequence[float]) -> tuple[float, float]:
    """Cross-boresight and roll error (arcsec) between two ICRS -> camera quaternions.

    The error rotation ``E = R_est R_true^T`` is taken in the camera frame: cross-boresight is
    the angle between the two boresights, roll the rotation about the boresight. Computed from
    the error quaternion ``q_est * conj(q_true)`` in Python floats (every solved frame of a
    recording with truth is scored: numpy's 3 x 3 products cost ~10x more).
    """
    w1, x1, y1, z1 = (float(v) for v in q_est)
    w2, x2, y2, z2 = (float(v) for v in q_true)
    n = math.sqrt((w1 * w1 + x1 * x1 + y1 * y1 + z1 * z1) * (w2 * w2 + x2 * x2 + y2 * y2 + z2 * z2))
    # Hamilton product q_est * conj(q_true), normalised
    w = (w1 * w2 + x1 * x2 + y1 * y2 + z1 * z2) / n
    x = (-w1 * x2 + x1 * w2 - y1 * z2 + z1 * y2) / n
    y = (-w1 * y2 + x1 * z2 + y1 * w2 - z1 * x2) / n
    z = (-w1 * z2 - x1 * y2 + y1 * x2 + z1 * w2) / n
    # E[2, 2] = 1 - 2 (x^2 + y^2) is the cosine between the boresights: the half-angle's sine
    # is sqrt(x^2 + y^2) (exact near zero, where acos of E[2, 2] loses ~0.003")
    cross = 2.0 * math.asin(min(1.0, math.sqrt(x * x + y * y))) * ARCSEC_PER_RAD
    roll = math.atan2(2.0 * w * z, w * w - z * z)  # (E[1,0] - E[0,1]) / 2, (E[0,0] + E[1,1]) / 2
    return cross, abs(roll) * ARCSEC_PER_RAD


def score(solution: Solution, truth_quaternion: Sequence[float] | None,
          truth_hip: Sequence[int | None] | None = None, *, camera: int = 0,
          blends: Mapping[int, Sequence[int]] | None = None) -> Score:
    """Compare ``solution`` with the truth of its frame (single camera unless ``camera``).

    ``blends`` maps a centroid index to every HIP blended into that centroid: a match to any
    of them is right (a database may keep a double the camera could not split, or merge it).
    """
    if not solution.solved or solution.quaternion is None:
        return Score(False, None, 0, None, None)
    cross = roll = None
    if truth_quaternion is not None:
        cross, roll = attitude_error(solution.quaternion, truth_quaternion)
    wrong = 0
    if truth_hip is not None:
        n = len(truth_hip)
        stars = solution.stars
        rows = (zip(stars.column("centroid"), stars.column("hip"), stars.column("camera"), strict=True)
                if isinstance(stars, MatchedStars) else ((s.centroid, s.hip, s.camera) for s in stars))
        for centroid, hip, cam in rows:
            if cam == camera and 0 <= centroid < n:
                want = truth_hip[centroid]
                if want is not None and hip == want and want >= 0:
                    continue  # the common case, without building the set below
                ok = {int(h) for h in (blends or {}).get(centroid, ())}
                if want is not None and int(want) >= 0:
                    ok.add(int(want))
                wrong += int(hip not in ok)
        correct = wrong == 0
    else:
        correct = cross is None or cross <= WRONG_BORESIGHT_ARCSEC
    return Score(True, correct, wrong, cross, roll)


def correct_against_record(rec: Mapping[str, object], sol: Solution) -> bool | None:
    """Whether a solved frame agrees with its recording's ``truth`` (the README's JSON Lines
    format; a rig's truth lists every camera's HIPs one camera after the other). None when the
    frame is not solved or the record holds no truth."""
    truth = rec.get("truth") or {}
    if not sol.solved or not isinstance(truth, Mapping) or not truth:
        return None
    blends = {int(k): v for k, v in (truth.get("blends") or {}).items()}  # type: ignore[union-attr]
    cams = rec.get("cameras")
    sizes = [len(c.get("centroids", [])) for c in cams] if isinstance(cams, list) and cams else [0]
    hips = truth.get("hip")
    offsets = list(accumulate(sizes[:-1], initial=0))
    return all(score(sol, truth.get("quaternion"), None if hips is None else hips[o:],  # type: ignore[arg-type,index]
                     camera=c, blends={k - o: v for k, v in blends.items() if k >= o}).correct
               for c, o in enumerate(offsets))
