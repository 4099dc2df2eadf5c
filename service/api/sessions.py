"""Named stream sessions: ``WS /v1/stream?session=NAME`` publishes each reply; viewers watch it.

A viewer (``WS /v1/sessions/{name}/watch``) gets every published frame and its reply through its
own bounded queue that drops the oldest entry when the viewer falls behind, so a slow or stalled
viewer never slows the stream that publishes. With no viewer, publishing is one dict lookup.
"""

from __future__ import annotations

import asyncio
import json
import re
from collections import deque
from collections.abc import Awaitable, Callable
from typing import Annotated

from fastapi import APIRouter, Path, Query, WebSocket, WebSocketDisconnect

from .deps import API_KEY_HEADER, SettingsDep, key_ok

SESSION_NAME = re.compile(r"^[A-Za-z0-9._-]{1,64}$")
"""Allowed session names: 1-64 letters, digits, '.', '_' or '-'."""

Handler = Callable[[str | None, bytes | None], Awaitable[str]]
"""A stream's message handler: (text, binary) -> reply text."""

Published = tuple[int, str | None, str]
"""(the frame's number in its session, its text message or None for an image, the reply JSON)."""

VIEWER_QUEUE = 256
"""Replies a viewer may lag behind before its oldest ones are dropped."""


class Viewer:
    """One watcher's bounded queue (drop-oldest) and the number of replies it lost."""

    def __init__(self, maxlen: int = VIEWER_QUEUE) -> None:
        self.queue: deque[Published] = deque(maxlen=maxlen)
        self.dropped = 0
        self._ready = asyncio.Event()

    def put(self, item: Published) -> None:
        if len(self.queue) == self.queue.maxlen:
            self.dropped += 1
        self.queue.append(item)  # a full deque drops its oldest entry
        self._ready.set()

    async def get(self) -> Published:
        while not self.queue:
            self._ready.clear()
            await self._ready.wait()
        return self.queue.popleft()


class SessionHub:
    """Viewers by session name, and frames published to each watched session (one hub per worker
    process); ``seq`` counts a session's frames since its first current viewer came."""

    def __init__(self) -> None:
        self.viewers: dict[str, set[Viewer]] = {}
        self.published: dict[str, int] = {}

    def publish(self, name: str, request: str | None, reply: str) -> None:
        """Hand a frame (its text message, None for an image) and its reply (JSON) to every viewer of
        ``name``; never waits and never parses (viewers format their own messages). Without a viewer
        nothing is kept: a stream may use any number of names."""
        viewers = self.viewers.get(name)
        if not viewers:
            return
        seq = self.published[name] = self.published[name] + 1
        for viewer in viewers:
            viewer.put((seq, request, reply))

    def subscribe(self, name: str, maxlen: int = VIEWER_QUEUE) -> Viewer:
        viewer = Viewer(maxlen)
        self.viewers.setdefault(name, set()).add(viewer)
        self.published.setdefault(name, 0)
        return viewer

    def unsubscribe(self, name: str, viewer: Viewer) -> None:
        group = self.viewers.get(name)
        if group is not None:
            group.discard(viewer)
            if not group:
                del self.viewers[name]
                del self.published[name]


def publishing(handle: Handler, hub: SessionHub, name: str) -> Handler:
    """``handle`` that also publishes each reply to session ``name``'s viewers."""

    async def handle_and_publish(text: str | None, data: bytes | None) -> str:
        reply = await handle(text, data)
        hub.publish(name, text, reply)
        return reply

    return handle_and_publish


def get_hub(ws: WebSocket) -> SessionHub:
    """The app's hub (made on first use)."""
    state = ws.app.state
    hub = getattr(state, "sessions", None)
    if hub is None:
        hub = state.sessions = SessionHub()
    return hub


router = APIRouter(prefix="/v1", tags=["stream"])


@router.websocket("/sessions/{name}/watch")
async def watch(
    ws: WebSocket, settings: SettingsDep,
    name: Annotated[str, Path(pattern=SESSION_NAME.pattern,
                              description="Session name, as in /v1/stream?session=.")],
    api_key: Annotated[str | None, Query(description="For clients that cannot send X-API-Key.")] = None,
) -> None:
    """Every frame of stream session ``name`` from now on, one text message each (drop-oldest when slow).

    Each message is ``{"seq": N, "dropped": D, "frame": F, "result": R}``: ``N`` counts the session's
    frames in this worker, ``D`` the messages this viewer lost by falling behind, ``F`` the frame's text
    message as a JSON string (null for an image frame) and ``R`` the reply (``SolveResult``,
    ``StreamAck`` or ``StreamError``).
    """
    if not key_ok(settings, ws.headers.get(API_KEY_HEADER) or api_key):
        await ws.close(code=1008, reason="missing or wrong API key")
        return
    await ws.accept()
    hub = get_hub(ws)
    viewer = hub.subscribe(name)
    closed = asyncio.create_task(_until_closed(ws))
    try:
        while not closed.done():
            getter = asyncio.create_task(viewer.get())
            done, _ = await asyncio.wait({getter, closed}, return_when=asyncio.FIRST_COMPLETED)
            if getter not in done:
                getter.cancel()
                break
            seq, request, reply = getter.result()
            await ws.send_text(viewer_message(seq, request, reply, viewer.dropped))
    except (WebSocketDisconnect, RuntimeError):
        pass
    finally:
        hub.unsubscribe(name, viewer)
        closed.cancel()


def viewer_message(seq: int, request: str | None, reply: str, dropped: int = 0) -> str:
    """The watch message for one published frame (``reply`` is JSON already)."""
    frame = "null" if request is None else json.dumps(request)
    return f'{{"seq":{seq},"dropped":{dropped},"frame":{frame},"result":{reply}}}'


async def _until_closed(ws: WebSocket) -> None:
    """Read (and ignore) what the viewer sends until it disconnects."""
    try:
        while True:
            msg = await ws.receive()
            if msg["type"] == "websocket.disconnect":
                return
    except (WebSocketDisconnect, RuntimeError):
        return
