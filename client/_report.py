"""Scoring a replay against the recording's truth, and the report it produces.

A frame is *wrong* when the server says ``solved`` and either

* a matched star contradicts the truth: the truth names another HIP for that centroid (and
  ``truth.blends`` does not list the match among the stars merged into it), or says the
  centroid is a false star (``null``); or
* the attitude is off the truth quaternion by more than the bars: cross-boresight error >
  ``cross_boresight_arcsec`` (default 120″ = 2′) or roll error > ``roll_arcsec`` (default
  1800″ = 30′).

Why these bars: a misidentification moves the attitude by a sizeable fraction of the field
(degrees), while a correct one is off by centroid noise and unmodelled distortion. Roll about
the boresight is observed about 1/r̄ times less well than the boresight direction (r̄ = the
stars' mean off-axis angle in radians, ~0.05 for a 10° field). On the 38 real images with
their reference attitudes, correct solutions land within 77″ cross-boresight and 1220″ roll
(obstructed fields with 8-10 stars; from centroids or from the images), and the independent
reference solvers themselves disagree by up to 1.36′ in centre and 0.32° in roll. The bars
sit above both, so "wrong" means wrong, not noisy; accuracy is reported separately as
distributions. Tighten them (``--wrong-arcsec 60``) for simulated frames, whose truth is exact.

Errors are in the camera frame, from ``R_err = R_solved R_truthᵀ`` (see `attitude_error`).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, Literal

from pydantic import BaseModel, Field

from ._attitude import attitude_error
from .models import FrameId, RecordedFrame, SolveResult, Truth

__all__ = ["Distribution", "FrameReport", "ReplayReport", "WrongBars", "percentile"]

Status = Literal["solved", "no_solution", "failed"]
WRONG_CROSS_BORESIGHT_ARCSEC = 120.0
WRONG_ROLL_ARCSEC = 1800.0


def percentile(values: Sequence[float], p: float) -> float | None:
    """The ``p``-th percentile (0-100) with linear interpolation between order statistics
    (numpy's default ``"linear"`` method); None for no values."""
    if not values:
        return None
    xs = sorted(values)
    pos = (len(xs) - 1) * min(max(p, 0.0), 100.0) / 100.0
    lo = math.floor(pos)
    hi = min(lo + 1, len(xs) - 1)
    return xs[lo] + (xs[hi] - xs[lo]) * (pos - lo)


class Distribution(BaseModel):
    """Summary of a sample: count, mean, RMS, percentiles and maximum (None when empty)."""

    n: int = 0
    mean: float | None = None
    rms: float | None = None
    p50: float | None = None
    p90: float | None = None
    p95: float | None = None
    p99: float | None = None
    max: float | None = None

    @classmethod
    def of(cls, values: Sequence[float]) -> Distribution:
        if not values:
            return cls()
        n = len(values)
        return cls(n=n, mean=sum(values) / n, rms=math.sqrt(sum(v * v for v in values) / n),
                   p50=percentile(values, 50), p90=percentile(values, 90), p95=percentile(values, 95),
                   p99=percentile(values, 99), max=max(values))


@dataclass(frozen=True, slots=True)
class WrongBars:
    """When a solved frame counts as wrong (see the module docstring)."""

    cross_boresight_arcsec: float = WRONG_CROSS_BORESIGHT_ARCSEC
    roll_arcsec: float = WRONG_ROLL_ARCSEC


class FrameReport(BaseModel):
    """One replayed frame: what came back, how long it took, how it compares with the truth."""

    index: int = Field(description="Position of the frame in the recording, from 0.")
    id: FrameId = None
    status: Status
    latency_ms: float | None = None
    epoch: str | None = Field(None, description="UTC time of the frame (recording, else wall clock), ISO.")
    method: str | None = None
    n_stars: int = 0
    quaternion: list[float] | None = None
    cross_boresight_arcsec: float | None = None
    roll_arcsec: float | None = Field(None, description="Signed roll error about the boresight, arcsec.")
    hip_checked: int = 0
    hip_wrong: int = 0
    wrong: bool = False
    reasons: list[str] = Field(default_factory=list)
    error: str | None = None


class ReplayReport(BaseModel):
    """Everything a replay measured. ``identification_rate`` = solved / frames (frames that
    failed count against it); latencies are over answered frames."""

    recording: str | None = None
    url: str
    transport: Literal["rest", "ws"]
    rate_hz: float | None = None
    concurrency: int = 1
    frames: int
    solved: int
    no_solution: int
    failed: int
    identification_rate: float
    wrong: int
    wrong_ids: list[FrameId] = Field(default_factory=list)
    wrong_bars_arcsec: dict[str, float] = Field(default_factory=dict)
    with_truth: int = Field(0, description="Solved frames that have a truth quaternion.")
    cross_boresight_arcsec: Distribution = Field(default_factory=Distribution)
    roll_arcsec: Distribution = Field(default_factory=Distribution, description="Of |roll error|.")
    hip_checked: int = 0
    hip_wrong: int = 0
    latency_ms: Distribution = Field(default_factory=Distribution)
    throughput_fps: float = Field(description="Answered frames per second of wall time.")
    wall_s: float
    reconnects: int = 0
    failures: list[dict[str, Any]] = Field(default_factory=list, description="[{id, error}] per failed frame")
    bars: dict[str, Any] = Field(default_factory=dict)
    per_frame: list[FrameReport] = Field(default_factory=list)

    def missed_bars(self, *, min_rate: float | None = None, max_wrong: int | None = None) -> list[str]:
        """Human-readable reasons the run misses the given bars (empty = passed)."""
        reasons = []
        if min_rate is not None and self.identification_rate < min_rate:
            reasons.append(f"identification rate {self.identification_rate:.4f} < --min-rate {min_rate}")
        if max_wrong is not None and self.wrong > max_wrong:
            reasons.append(f"{self.wrong} wrong answers > --max-wrong {max_wrong}")
        return reasons


def score_frame(report: FrameReport, frame: RecordedFrame, result: SolveResult, bars: WrongBars) -> None:
    """Fill the truth comparison of a solved frame into ``report``."""
    truth = frame.truth
    if truth is None or result.status != "solved":
        return
    if truth.hip is not None:
        offsets = _camera_offsets(frame)
        blends = _blends(truth)
        for star in result.stars:
            base = offsets[star.camera] if star.camera < len(offsets) else None
            idx = None if base is None else base + star.centroid
            if idx is None or not 0 <= idx < len(truth.hip):
                continue
            report.hip_checked += 1
            if star.hip != truth.hip[idx] and star.hip not in blends.get(idx, ()):
                report.hip_wrong += 1
        if report.hip_wrong:
            report.reasons.append(f"{report.hip_wrong} of {report.hip_checked} HIP disagree with truth")
    if truth.quaternion is not None and result.quaternion is not None:
        err = attitude_error(result.quaternion, truth.quaternion)
        report.cross_boresight_arcsec = err.cross_boresight_arcsec
        report.roll_arcsec = err.roll_arcsec
        if err.cross_boresight_arcsec > bars.cross_boresight_arcsec:
            report.reasons.append(f"cross-boresight error {err.cross_boresight_arcsec:.1f}\" > "
                                  f"{bars.cross_boresight_arcsec:g}\"")
        if abs(err.roll_arcsec) > bars.roll_arcsec:
            report.reasons.append(f"roll error {abs(err.roll_arcsec):.1f}\" > {bars.roll_arcsec:g}\"")
    report.wrong = bool(report.reasons)


def _blends(truth: Truth) -> dict[int, set[int]]:
    """``truth.blends`` (``{"centroid index": [HIP, ...]}``): stars merged into one centroid;
    a match to any of them is right."""
    raw = (truth.model_extra or {}).get("blends")
    out: dict[int, set[int]] = {}
    if isinstance(raw, dict):
        for key, hips in raw.items():
            try:
                out[int(key)] = {int(h) for h in hips}
            except (TypeError, ValueError):
                continue
    return out


def _camera_offsets(frame: RecordedFrame) -> list[int]:
    """Index of each camera's first centroid in the truth's per-centroid list (a rig's truth
    lists the cameras' centroids one camera after the other)."""
    if frame.cameras is None:
        return [0]
    offsets, total = [], 0
    for cam in frame.cameras:
        offsets.append(total)
        total += len(cam.centroids)
    return offsets


def summarize(per_frame: list[FrameReport], *, wall_s: float, bars: WrongBars, **meta: Any) -> ReplayReport:
    """Aggregate per-frame reports into a `ReplayReport` (``meta``: url, transport, ...)."""
    solved = [f for f in per_frame if f.status == "solved"]
    answered = [f for f in per_frame if f.status != "failed"]
    failed = [f for f in per_frame if f.status == "failed"]
    wrong = [f for f in solved if f.wrong]
    scored = [f for f in solved if f.cross_boresight_arcsec is not None]
    latencies = [f.latency_ms for f in answered if f.latency_ms is not None]
    n = len(per_frame)
    return ReplayReport(
        frames=n,
        solved=len(solved),
        no_solution=sum(f.status == "no_solution" for f in per_frame),
        failed=len(failed),
        identification_rate=len(solved) / n if n else 0.0,
        wrong=len(wrong),
        wrong_ids=[f.id for f in wrong],
        wrong_bars_arcsec={"cross_boresight": bars.cross_boresight_arcsec, "roll": bars.roll_arcsec},
        with_truth=len(scored),
        cross_boresight_arcsec=Distribution.of([f.cross_boresight_arcsec for f in scored
                                                if f.cross_boresight_arcsec is not None]),
        roll_arcsec=Distribution.of([abs(f.roll_arcsec) for f in scored if f.roll_arcsec is not None]),
        hip_checked=sum(f.hip_checked for f in solved),
        hip_wrong=sum(f.hip_wrong for f in solved),
        latency_ms=Distribution.of(latencies),
        throughput_fps=len(answered) / wall_s if wall_s > 0 else 0.0,
        wall_s=wall_s,
        failures=[{"id": f.id, "error": f.error} for f in failed],
        per_frame=per_frame,
        **meta,
    )
