"""The connections in front of the web server: at most a given number at once, and each must
send its first request's head within a timeout.

:class:`ConnectionGuard` wraps the web server's protocol factory (aiohttp's ``Server``): a
connection beyond the limit is closed as soon as it is accepted, and one whose first request
head (up to its blank line) has not arrived within the timeout is closed then: a client that
opens connections and never finishes a request (or sends it a byte at a time) holds at most
``limit`` of them, each for at most the timeout, and the server never runs out of file
descriptors (:func:`connection_limit` keeps the limit under the process's). Later requests on a
kept-alive connection are bounded by the web server's keep-alive timeout, set to the same
value; a websocket, once open, by its heartbeat. Each closing is counted in ``counts``
(``connection_limit``, ``header_timeout``).
"""

from __future__ import annotations

import asyncio
import resource
from collections.abc import Callable
from typing import Any

__all__ = ["ConnectionGuard", "connection_limit", "RESERVED_FDS"]

RESERVED_FDS = 128  # descriptors kept for the rest of the process (DDS sockets, files, the event loop)
_END = b"\r\n\r\n"


def connection_limit(wanted: int) -> tuple[int, str]:
    """``wanted`` connections, raising the process's soft descriptor limit toward its hard one
    if it is needed; fewer when the hard limit is lower (with the reason to print, else empty)."""
    soft, hard = resource.getrlimit(resource.RLIMIT_NOFILE)
    need = wanted + RESERVED_FDS
    if soft != resource.RLIM_INFINITY and soft < need:
        target = need if hard == resource.RLIM_INFINITY else min(need, hard)
        try:
            resource.setrlimit(resource.RLIMIT_NOFILE, (target, hard))
            soft = target
        except (ValueError, OSError):
            pass
    if soft == resource.RLIM_INFINITY or soft >= need:
        return wanted, ""
    limit = max(1, soft - RESERVED_FDS)
    return limit, (f"--max-connections {wanted} lowered to {limit}: this process may open {soft} files "
                   f"(ulimit -n), {RESERVED_FDS} of them kept for the rest")


class ConnectionGuard:
    """A protocol factory for ``loop.create_server`` around ``factory`` (module docstring)."""

    def __init__(self, factory: Callable[[], asyncio.Protocol], limit: int, timeout: float,
                 counts: dict[str, int]) -> None:
        self._factory = factory
        self.limit = limit
        self.timeout = timeout
        self.counts = counts
        self.open = 0

    def __call__(self) -> asyncio.Protocol:
        return _Guarded(self)


class _Guarded(asyncio.Protocol):
    """One connection: counted, timed until its first request head is complete, then handed
    through to the web server's protocol unchanged."""

    def __init__(self, guard: ConnectionGuard) -> None:
        self._guard = guard
        self._inner: asyncio.Protocol | None = None
        self._transport: asyncio.Transport | None = None
        self._timer: asyncio.TimerHandle | None = None
        self._tail = b""

    def connection_made(self, transport: Any) -> None:
        g = self._guard
        if g.open >= g.limit:
            g.counts["connection_limit"] += 1
            transport.abort()
            return
        g.open += 1
        self._transport = transport
        self._timer = asyncio.get_running_loop().call_later(g.timeout, self._expire)
        self._inner = g._factory()
        self._inner.connection_made(transport)

    def _expire(self) -> None:
        self._timer = None
        if self._transport is not None:
            self._guard.counts["header_timeout"] += 1
            self._transport.abort()

    def data_received(self, data: bytes) -> None:
        if self._inner is None:
            return
        if self._timer is not None:
            seen = self._tail + data
            if _END in seen:
                self._timer.cancel()
                self._timer = None
            else:
                self._tail = seen[-(len(_END) - 1):]
        self._inner.data_received(data)

    def eof_received(self) -> bool | None:
        return self._inner.eof_received() if self._inner is not None else None

    def pause_writing(self) -> None:
        if self._inner is not None:
            self._inner.pause_writing()

    def resume_writing(self) -> None:
        if self._inner is not None:
            self._inner.resume_writing()

    def connection_lost(self, exc: Exception | None) -> None:
        if self._inner is None:
            return
        if self._timer is not None:
            self._timer.cancel()
            self._timer = None
        self._guard.open -= 1
        self._transport = None
        inner, self._inner = self._inner, None
        inner.connection_lost(exc)
