"""Report math: percentiles, scoring against truth, aggregation, bars."""

import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from client import FrameReport, RecordedFrame, SolveResult, WrongBars
from client._attitude import quat_mul
from client._report import percentile, score_frame, summarize

ARCSEC = math.pi / 180 / 3600
CAM = {"width": 100, "height": 100, "fov_deg": 10}
TRUTH_Q = (0.5, 0.5, 0.5, 0.5)


@given(st.lists(st.floats(-1e6, 1e6, allow_nan=False), min_size=1, max_size=50), st.floats(0, 100))
def test_percentile_matches_numpy(values: list[float], p: float) -> None:
    assert percentile(values, p) == pytest.approx(float(np.percentile(values, p)), rel=1e-9, abs=1e-6)


def test_percentile_empty() -> None:
    assert percentile([], 50) is None


def rotated(arcsec_about_x: float, arcsec_about_z: float = 0.0) -> list[float]:
    def about(axis: int, a: float) -> tuple[float, float, float, float]:
        v = [0.0, 0.0, 0.0]
        v[axis] = math.sin(a * ARCSEC / 2)
        return (math.cos(a * ARCSEC / 2), v[0], v[1], v[2])
    return list(quat_mul(about(0, arcsec_about_x), quat_mul(about(2, arcsec_about_z), TRUTH_Q)))


def frame(hip: list[int | None]) -> RecordedFrame:
    return RecordedFrame.model_validate({"id": "f", "camera": CAM, "centroids": [[1, 1]] * len(hip),
                                         "truth": {"quaternion": list(TRUTH_Q), "hip": hip}})


def result(q: list[float], stars: list[tuple[int, int]]) -> SolveResult:
    return SolveResult.model_validate({
        "status": "solved", "quaternion": q, "method": "pyramid",
        "stars": [{"centroid": c, "hip": h, "ra_deg": 0, "dec_deg": 0, "mag": 5, "residual_arcsec": 1}
                  for c, h in stars]})


def scored(q: list[float], stars: list[tuple[int, int]], hip: list[int | None],
           bars: WrongBars | None = None) -> FrameReport:
    rep = FrameReport(index=0, id="f", status="solved")
    score_frame(rep, frame(hip), result(q, stars), bars or WrongBars())
    return rep


def test_correct_frame() -> None:
    rep = scored(rotated(10, 100), [(0, 11), (1, 22)], [11, 22, None])
    assert not rep.wrong and rep.hip_checked == 2 and rep.hip_wrong == 0
    assert rep.cross_boresight_arcsec == pytest.approx(10, abs=1e-6)
    assert rep.roll_arcsec == pytest.approx(100, abs=1e-6)


@pytest.mark.parametrize(("stars", "hip"), [([(0, 99)], [11]), ([(1, 5)], [11, None])])
def test_hip_disagreement_or_false_star_is_wrong(stars: list[tuple[int, int]], hip: list[int | None]) -> None:
    rep = scored(rotated(0), stars, hip)
    assert rep.wrong and rep.hip_wrong == 1 and "HIP" in rep.reasons[0]


def test_a_match_to_any_member_of_a_blend_is_right() -> None:
    f = RecordedFrame.model_validate({"id": "f", "camera": CAM, "centroids": [[1, 1], [2, 2]],
                                      "truth": {"hip": [11, 22], "blends": {"1": [22, 23]}}})
    rep = FrameReport(index=0, status="solved")
    score_frame(rep, f, result(list(TRUTH_Q), [(0, 11), (1, 23)]), WrongBars())
    assert rep.hip_checked == 2 and rep.hip_wrong == 0 and not rep.wrong
    rep = FrameReport(index=0, status="solved")
    score_frame(rep, f, result(list(TRUTH_Q), [(0, 23)]), WrongBars())
    assert rep.wrong


def test_attitude_bars() -> None:
    assert scored(rotated(121), [], [None]).wrong
    assert not scored(rotated(119), [], [None]).wrong
    assert scored(rotated(0, 1801), [], [None]).wrong
    assert not scored(rotated(0, -1799), [], [None]).wrong
    assert scored(rotated(61), [], [None], WrongBars(cross_boresight_arcsec=60)).wrong


def test_rig_truth_lists_cameras_in_order() -> None:
    f = RecordedFrame.model_validate({"id": 1, "cameras": [{"camera": CAM, "centroids": [[1, 1], [2, 2]]},
                                                           {"camera": CAM, "centroids": [[3, 3]]}],
                                      "truth": {"hip": [1, 2, 3]}})
    r = SolveResult.model_validate({"status": "solved", "method": "m", "quaternion": [1, 0, 0, 0], "stars": [
        {"centroid": 0, "camera": 1, "hip": 3, "ra_deg": 0, "dec_deg": 0, "mag": 1, "residual_arcsec": 0},
        {"centroid": 1, "camera": 0, "hip": 2, "ra_deg": 0, "dec_deg": 0, "mag": 1, "residual_arcsec": 0}]})
    rep = FrameReport(index=0, status="solved")
    score_frame(rep, f, r, WrongBars())
    assert rep.hip_checked == 2 and not rep.wrong


def test_summary_and_bars() -> None:
    frames = [
        FrameReport(index=0, id="a", status="solved", latency_ms=10, cross_boresight_arcsec=5,
                    roll_arcsec=-50),
        FrameReport(index=1, id="b", status="solved", latency_ms=20, cross_boresight_arcsec=500,
                    roll_arcsec=10, wrong=True, reasons=["x"]),
        FrameReport(index=2, id="c", status="no_solution", latency_ms=30),
        FrameReport(index=3, id="d", status="failed", error="ConnectError"),
    ]
    rep = summarize(frames, wall_s=2.0, bars=WrongBars(), url="u", transport="rest")
    assert (rep.frames, rep.solved, rep.no_solution, rep.failed, rep.wrong) == (4, 2, 1, 1, 1)
    assert rep.identification_rate == 0.5 and rep.wrong_ids == ["b"]
    assert rep.latency_ms.n == 3 and rep.latency_ms.p50 == 20
    assert rep.roll_arcsec.max == 50  # |roll|
    assert rep.throughput_fps == 1.5
    assert rep.failures == [{"id": "d", "error": "ConnectError"}]
    assert rep.missed_bars(min_rate=0.5, max_wrong=1) == []
    assert len(rep.missed_bars(min_rate=0.6, max_wrong=0)) == 2
