"""Named stream sessions: ``/v1/stream?session=NAME`` publishes, ``/v1/sessions/NAME/watch`` relays."""

from __future__ import annotations

import asyncio
import json

import pytest
from websockets.exceptions import ConnectionClosed
from websockets.sync.client import connect

from service.api.sessions import SessionHub, Viewer, viewer_message
from service.core.sim import SimFrame

from .conftest import LiveServer, rows


def test_a_slow_viewer_loses_its_oldest_frames_and_never_blocks_the_publisher() -> None:
    hub = SessionHub()
    slow = hub.subscribe("rig-1", maxlen=4)
    for i in range(10):
        hub.publish("rig-1", f'{{"n": {i}}}', f'{{"id": {i}}}')  # returns at once: nobody reads
    assert slow.dropped == 6
    got = [asyncio.run(slow.get()) for _ in range(4)]
    assert [seq for seq, _, _ in got] == [7, 8, 9, 10]
    assert got[-1][2] == '{"id": 9}'
    hub.unsubscribe("rig-1", slow)
    hub.publish("rig-1", None, "{}")  # no viewer: nothing is kept
    assert hub.viewers == {} and hub.published == {}


def test_a_viewer_message_is_json_even_for_a_frame_that_was_not() -> None:
    msg = json.loads(viewer_message(3, '{"broken": ', '{"id": 2, "code": 400}', dropped=1))
    assert msg == {"seq": 3, "dropped": 1, "frame": '{"broken": ', "result": {"id": 2, "code": 400}}
    assert json.loads(viewer_message(1, None, "{}"))["frame"] is None


def test_viewer_queue_wakes_a_waiting_reader() -> None:
    async def run() -> tuple[int, str | None, str]:
        v = Viewer(maxlen=2)
        task = asyncio.create_task(v.get())
        await asyncio.sleep(0)
        v.put((1, None, "{}"))
        return await asyncio.wait_for(task, 1)

    assert asyncio.run(run()) == (1, None, "{}")


def test_a_viewer_sees_every_frame_of_its_session_with_the_reply(server: LiveServer, frames: list[SimFrame]) -> None:
    watch = server.url.replace("http", "ws", 1) + "/v1/sessions/test-rig/watch"
    other = server.url.replace("http", "ws", 1) + "/v1/sessions/elsewhere/watch"
    with connect(watch) as viewer, connect(other) as bystander, connect(server.ws_url + "?session=test-rig") as rig:
        sent, replies = [], []
        for frame in frames[:5]:
            text = json.dumps({"camera": "tetra3", "centroids": rows(frame)})
            rig.send(text)
            replies.append(json.loads(rig.recv(timeout=30)))
            sent.append(text)
        got = [json.loads(viewer.recv(timeout=10)) for _ in sent]
        assert [g["frame"] for g in got] == sent
        assert [g["result"] for g in got] == replies
        assert [g["dropped"] for g in got] == [0] * 5
        assert got[-1]["seq"] - got[0]["seq"] == 4
        with pytest.raises(TimeoutError):
            bystander.recv(timeout=0.3)


@pytest.mark.parametrize("name", ["has space", "x" * 65, "semi;colon"])
def test_a_bad_session_name_is_refused(server: LiveServer, name: str) -> None:
    from urllib.parse import quote

    # like every bad query parameter: accepted, then closed with 1008 and a reason naming it
    with connect(server.ws_url + "?session=" + quote(name)) as ws, pytest.raises(ConnectionClosed) as closed:
        ws.recv(timeout=10)
    assert closed.value.rcvd is not None and closed.value.rcvd.code == 1008
    assert "session" in closed.value.rcvd.reason
