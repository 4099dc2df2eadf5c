"""Scoring a solution against known truth (simulated frames, reference solutions)."""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from .attitude import ARCSEC_PER_RAD, quat_to_matrix
from .types import Solution

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
    the angle between the two boresights, roll the rotation about the boresight.
    """
    e = quat_to_matrix(np.asarray(q_est, float)) @ quat_to_matrix(np.asarray(q_true, float)).T
    cross = math.acos(max(-1.0, min(1.0, float(e[2, 2])))) * ARCSEC_PER_RAD
    roll = math.atan2(float(e[1, 0] - e[0, 1]), float(e[0, 0] + e[1, 1])) * ARCSEC_PER_RAD
    return cross, abs(roll)


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
        for s in solution.stars:
            if s.camera == camera and 0 <= s.centroid < n:
                want = truth_hip[s.centroid]
                if want is not None and s.hip == want and want >= 0:
                    continue  # the common case, without building the set below
                ok = {int(h) for h in (blends or {}).get(s.centroid, ())}
                if want is not None and int(want) >= 0:
                    ok.add(int(want))
                wrong += int(s.hip not in ok)
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
    offsets = np.cumsum([0, *sizes[:-1]]).tolist()
    return all(score(sol, truth.get("quaternion"), None if hips is None else hips[o:],  # type: ignore[arg-type,index]
                     camera=c, blends={k - o: v for k, v in blends.items() if k >= o}).correct
               for c, o in enumerate(offsets))
