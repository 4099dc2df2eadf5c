"""A time limit on receiving a request's headers (slowloris), at the HTTP protocol level.

uvicorn times out idle keep-alive connections, but not a request whose headers arrive one byte
at a time, nor a connection that sends nothing: each such client holds a socket and a file
descriptor forever. ``HeaderTimeoutProtocol`` is uvicorn's httptools protocol with one timer:
started when a connection opens and when a request begins, stopped when the request's headers
are complete; when it fires the client gets ``408 Request Timeout`` and the connection is
closed (a lingering close: the server's side first, then the socket once the client closes or
``LINGER_S`` has passed). ``skyfix serve`` passes this class as uvicorn's ``http`` protocol; the limit is
``SKYFIX_HEADER_TIMEOUT_S`` (read from the environment when the first connection is made).
"""

from __future__ import annotations

import asyncio
import os

from uvicorn.protocols.http.httptools_impl import HttpToolsProtocol

DEFAULT_TIMEOUT_S = 10.0
LINGER_S = 2.0
"""After a 408, what the client still sends is read and dropped for at most this long."""
_RESPONSE = (b"HTTP/1.1 408 Request Timeout\r\ncontent-type: application/json\r\nconnection: close\r\n"
             b"content-length: 67\r\n\r\n"
             b'{"detail":"request headers not received in time","field":"headers"}')


def header_timeout_s() -> float:
    """``SKYFIX_HEADER_TIMEOUT_S`` (validated by the settings at start), default 10 s."""
    return float(os.environ.get("SKYFIX_HEADER_TIMEOUT_S") or DEFAULT_TIMEOUT_S)


class HeaderTimeoutProtocol(HttpToolsProtocol):
    """httptools HTTP/1.1 with a deadline for each request's headers."""

    timeout_s: float | None = None
    _timer: asyncio.TimerHandle | None = None
    _lingering = False

    def connection_made(self, transport: asyncio.Transport) -> None:  # type: ignore[override]
        super().connection_made(transport)
        self._arm()

    def on_message_begin(self) -> None:
        super().on_message_begin()
        self._arm()

    def on_headers_complete(self) -> None:
        self._disarm()
        super().on_headers_complete()

    def connection_lost(self, exc: Exception | None) -> None:
        self._disarm()
        super().connection_lost(exc)

    def _arm(self) -> None:
        self._disarm()
        if HeaderTimeoutProtocol.timeout_s is None:
            HeaderTimeoutProtocol.timeout_s = header_timeout_s()
        self._timer = self.loop.call_later(HeaderTimeoutProtocol.timeout_s, self._expired)

    def _disarm(self) -> None:
        if self._timer is not None:
            self._timer.cancel()
            self._timer = None

    def data_received(self, data: bytes) -> None:
        if self._lingering:  # after the 408: read and drop (see _expired)
            return
        super().data_received(data)

    def _expired(self) -> None:
        self._timer = None
        if self.transport.is_closing():
            return
        if self.cycle is None or self.cycle.response_complete:  # nothing of ours is being written
            self.transport.write(_RESPONSE)
        if not self.transport.can_write_eof():
            self.transport.close()
            return
        # a lingering close: closing a socket whose client is still sending makes the kernel
        # answer with a reset, which can destroy the 408 before the client reads it (a CI run
        # saw "connection reset by peer"); send the answer and our FIN, drop what still arrives,
        # and close after LINGER_S or when the client does
        self._lingering = True
        self.transport.write_eof()
        self._timer = self.loop.call_later(LINGER_S, self.transport.close)
