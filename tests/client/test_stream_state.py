"""The stream's book-keeping: unacknowledged queue, resend-only-unacked, at-most-once delivery."""

import json

import pytest

from client import SkyfixFrameError, SkyfixProtocolError, SolveResult
from client._stream import _StreamState

CAM = {"width": 100, "height": 100, "fov_deg": 10}


def answer(frame_id: object, status: str = "no_solution") -> str:
    return json.dumps({"id": frame_id, "status": status, "method": "m"})


def send(state: _StreamState, gen: int, frame_id: object = None) -> str:
    key, fid, payload = state.prepare({"id": frame_id, "camera": CAM, "centroids": [[1, 2]]})
    state.sent(gen, key)
    return key


def test_assigned_ids_skip_ids_in_use() -> None:
    s = _StreamState()
    send(s, 1, 1)  # the caller's own id 1 ...
    assert send(s, 1) == "2"  # ... so the first assigned one is 2
    assert send(s, 1) == "3"


def test_duplicate_pending_id_is_refused() -> None:
    s = _StreamState()
    send(s, 1, "x")
    with pytest.raises(ValueError):
        send(s, 1, "x")


def test_answers_ack_in_order_and_resend_only_unacked() -> None:
    s = _StreamState()
    for i in range(4):
        send(s, 1, i)
    r = s.take(1, answer(0))
    assert isinstance(r, SolveResult) and r.id == 0
    assert s.unacknowledged() == [1, 2, 3]
    # connection 1 drops; connection 2 gets exactly the unacknowledged frames, in order
    resend = s.reconnected(2)
    assert [json.loads(p)["id"] for _, p in resend] == [1, 2, 3]
    for key, _ in resend:
        s.sent(2, key)
    # an answer still buffered on the old connection arrives late: delivered once ...
    assert s.take(1, answer(1)).id == 1  # type: ignore[union-attr]
    # ... and the new connection's answer to the same frame is a duplicate, dropped
    assert s.take(2, answer(1)) is None and s.duplicates == 1
    assert [s.take(2, answer(i)).id for i in (2, 3)] == [2, 3]  # type: ignore[union-attr]
    assert s.unacknowledged() == []


def test_errors_are_frame_errors_and_ack_the_frame() -> None:
    s = _StreamState()
    send(s, 1, "a")
    err = s.take(1, json.dumps({"id": "a", "code": 422, "detail": "centroids: bad", "field": "centroids"}))
    assert isinstance(err, SkyfixFrameError)
    assert (err.frame_id, err.status, err.field) == ("a", 422, "centroids")
    assert s.unacknowledged() == []


def test_image_frames_are_matched_by_position() -> None:
    s = _StreamState()
    key, fid = s.prepare_image(b"png", "img-1")
    s.sent(1, key)
    r = s.take(1, answer(0))  # the server numbers binary frames itself
    assert isinstance(r, SolveResult) and r.id == "img-1"


def test_mismatched_or_unsolicited_answers() -> None:
    s = _StreamState()
    assert s.take(1, answer(5)) is None and s.unexpected == 1
    send(s, 1, "a")
    with pytest.raises(SkyfixProtocolError):
        s.take(1, answer("b"))
    with pytest.raises(SkyfixProtocolError):
        s.take(1, "not json")
