"""CCSDS AEM (ADM v2, KVN): layout, quaternion convention, ordering."""

import io
import math
import re
from datetime import UTC, datetime, timedelta

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from client import AemRecord, format_aem, quaternion_to_ccsds, write_aem
from client._attitude import quat_normalize, quat_to_matrix

T0 = datetime(2026, 3, 1, 12, 0, 0, tzinfo=UTC)
unit = st.tuples(*[st.floats(-1, 1, allow_nan=False)] * 4).filter(lambda q: sum(c * c for c in q) > 0.01)


def ccsds_attitude_matrix(q1: float, q2: float, q3: float, qc: float) -> np.ndarray:
    """ADM's A(q): components in frame A -> components in frame B (Shuster's convention)."""
    e = np.array([q1, q2, q3])
    ex = np.array([[0, -e[2], e[1]], [e[2], 0, -e[0]], [-e[1], e[0], 0]])
    return (qc * qc - e @ e) * np.eye(3) + 2 * np.outer(e, e) - 2 * qc * ex


@given(unit)
def test_ccsds_quaternion_maps_icrf_components_to_camera(q: tuple[float, ...]) -> None:
    qn = quat_normalize(q)
    a = ccsds_attitude_matrix(*quaternion_to_ccsds(qn))
    np.testing.assert_allclose(a, quat_to_matrix(qn), atol=1e-12)


def test_brief_convention() -> None:
    w, x, y, z = 0.42622616, 0.0643827, 0.63256896, -0.64346146
    assert quaternion_to_ccsds((w, x, y, z)) == pytest.approx((-x, -y, -z, w), abs=1e-7)


def parse(text: str) -> tuple[dict[str, str], list[list[str]]]:
    keys, data, in_data = {}, [], False
    for line in text.splitlines():
        if line == "DATA_START":
            in_data = True
        elif line == "DATA_STOP":
            in_data = False
        elif in_data and line and not line.startswith("COMMENT"):
            data.append(line.split())
        elif "=" in line:
            k, v = line.split("=", 1)
            keys[k.strip()] = v.strip()
    return keys, data


def test_message_layout_and_order() -> None:
    q = (0.5, 0.5, -0.5, 0.5)
    # out of order, and a repeated epoch (the first one wins)
    recs = [AemRecord(T0 + timedelta(seconds=2), q), AemRecord(T0, q),
            AemRecord(T0 + timedelta(seconds=1), q), AemRecord(T0, (1.0, 0.0, 0.0, 0.0))]
    text = format_aem(recs, object_name="RIG-1", object_id="2026-001A", ref_frame_b="ST_1",
                      creation_date=T0, comments=["two\nlines"])
    lines = text.splitlines()
    assert lines[0].split() == ["CCSDS_AEM_VERS", "=", "2.0"]
    order = [lines.index(k) for k in ("META_START", "META_STOP", "DATA_START", "DATA_STOP")]
    assert order == sorted(order)
    assert "COMMENT two" in lines and "COMMENT lines" in lines
    keys, data = parse(text)
    assert keys["OBJECT_NAME"] == "RIG-1" and keys["OBJECT_ID"] == "2026-001A"
    assert keys["REF_FRAME_A"] == "ICRF" and keys["REF_FRAME_B"] == "ST_1"
    assert keys["TIME_SYSTEM"] == "UTC" and keys["ATTITUDE_TYPE"] == "QUATERNION"
    assert keys["START_TIME"] == "2026-03-01T12:00:00.000000"
    assert keys["STOP_TIME"] == "2026-03-01T12:00:02.000000"
    assert "ATTITUDE_DIR" not in keys and "QUATERNION_TYPE" not in keys  # ADM v1 only
    assert [row[0] for row in data] == ["2026-03-01T12:00:00.000000", "2026-03-01T12:00:01.000000",
                                        "2026-03-01T12:00:02.000000"]
    assert [float(v) for v in data[0][1:]] == pytest.approx([-0.5, 0.5, -0.5, 0.5])
    assert all(re.fullmatch(r"[ -~]*", line) for line in lines)  # printable ASCII


def test_sign_is_continuous_and_starts_with_positive_qc() -> None:
    recs = [AemRecord(T0 + timedelta(seconds=i), (math.cos(a), 0.0, 0.0, math.sin(a)))
            for i, a in enumerate([0.0, 1.2, 2.4, 3.6, 4.8, -1.0])]  # QC changes sign along the way
    _, data = parse(format_aem(recs))
    qs = [np.array([float(v) for v in row[1:]]) for row in data]
    assert qs[0][3] >= 0
    assert all(a @ b >= 0 for a, b in zip(qs, qs[1:], strict=False))


def test_write_to_path_and_file(tmp_path) -> None:  # type: ignore[no-untyped-def]
    recs = [AemRecord(T0, (1.0, 0.0, 0.0, 0.0))]
    assert write_aem(tmp_path / "a.aem", recs, object_id="X") == 1
    buf = io.StringIO()
    write_aem(buf, recs, object_id="X", creation_date=T0)
    assert (tmp_path / "a.aem").read_text().startswith("CCSDS_AEM_VERS")
    assert "DATA_STOP" in buf.getvalue()


def test_refuses_empty_and_bad_values() -> None:
    with pytest.raises(ValueError):
        format_aem([])
    with pytest.raises(ValueError):
        format_aem([AemRecord(T0, (1.0, 0, 0, 0))], object_name="A = B")
