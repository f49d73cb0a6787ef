"""What every connected page is sent, with memory bounded whatever the pages do.

* Each message of the hub is serialized once, for every page: :class:`Feed` keeps the newest
  ones in one shared log of at most :data:`LOG_BYTES`, and each page has only a cursor into it.
* A page that joins, or falls further behind than the log holds, gets the *latest* state
  instead of what it missed: one shared snapshot (:meth:`.hub.Hub.snapshot_messages`, in
  pieces of at most :data:`.messages.FRAME_VALUES` numbers), serialized once and sent to every
  page that needs it until the log no longer holds what follows it. Intermediate messages are
  dropped for that page, never queued without bound.
* A page is written a message only when its connection has taken the previous ones (the
  websocket writer waits while the connection's buffer is over its high-water mark), so what
  one page has not read is at most that buffer plus one message: a page that stops reading
  costs a few hundred kB until the websocket heartbeat closes it, and nothing once it is gone.
* When no page is connected nothing is kept: no log, no snapshot.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
from collections import deque
from dataclasses import dataclass
from typing import Any

from aiohttp import web

from .hub import Hub

__all__ = ["Feed", "Page", "Snapshot", "LOG_BYTES", "MAX_INBOUND", "encode"]

LOG_BYTES = 8 * 1024 * 1024  # serialized messages kept for pages that are behind
MAX_INBOUND = 1024  # bytes of one message from the page; longer ones are dropped and counted
_PONG = '{"type":"pong"}'


def encode(message: dict) -> str:
    """A message as the page reads it: compact JSON, ASCII (the hub never holds NaN). Kept as
    text, one byte a character; the websocket writer encodes one message at a time."""
    return json.dumps(message, allow_nan=False, separators=(",", ":"))


@dataclass(frozen=True)
class Snapshot:
    """The page's state after the feed's message ``seq``: hello, the snapshot's pieces, health."""

    seq: int
    frames: tuple[str, ...]

    @property
    def size(self) -> int:
        return sum(len(f) for f in self.frames)


class Page:
    """One connected page: where it is in the log (``cursor``: the next message's number; 0
    before its first snapshot), the snapshot it is being sent, if any, and its own replies."""

    def __init__(self, ws: web.WebSocketResponse, transport: asyncio.BaseTransport | None = None) -> None:
        self.ws = ws
        self.transport = transport
        self.cursor = 0
        self.snapshot: Snapshot | None = None
        self.part = 0
        self.replies: deque[str] = deque(maxlen=4)  # pongs; a page that pings faster loses some
        self.wake = asyncio.Event()

    @property
    def buffered(self) -> int:
        """Bytes written for this page that its connection has not taken yet."""
        t = self.transport
        return t.get_write_buffer_size() if isinstance(t, asyncio.WriteTransport) else 0


class Feed:
    """The connected pages and what they are sent (module docstring)."""

    def __init__(self, hub: Hub, log_bytes: int = LOG_BYTES) -> None:
        self.hub = hub
        self.pages: set[Page] = set()
        self.inbound = {"ping": 0, "malformed": 0, "oversized": 0, "lost": 0}
        # Connections refused: a foreign Origin, over the connection limit, no request in time.
        self.refused = {"foreign_origin": 0, "connection_limit": 0, "header_timeout": 0}
        self.resyncs = 0  # pages that fell behind the log and got the latest snapshot instead
        self.snapshots_built = 0
        self.seq = 0  # the number of the newest message
        self._log_bytes_max = log_bytes
        self._log: deque[str] = deque()
        self._log_bytes = 0
        self._first = 1  # the number of the log's oldest message
        self._snapshot: Snapshot | None = None

    # ------------------------------------------------------------------ messages in
    def send(self, message: dict | None) -> None:
        """Add a hub message for every page (serialized once); kept only while a page needs it."""
        if message is None:
            return
        self.seq += 1
        if not self.pages:
            self._forget()
            return
        frame = encode(message)
        self._log.append(frame)
        self._log_bytes += len(frame)
        while self._log_bytes > self._log_bytes_max and len(self._log) > 1:
            self._log_bytes -= len(self._log.popleft())
            self._first += 1
        if self._snapshot is not None and self._snapshot.seq + 1 < self._first:
            self._snapshot = None
        for page in self.pages:
            if page.snapshot is not None and page.snapshot.seq + 1 < self._first:
                page.snapshot = None  # what follows it is gone: it starts over from a newer one
            page.wake.set()

    def _forget(self) -> None:
        self._log.clear()
        self._log_bytes = 0
        self._first = self.seq + 1
        self._snapshot = None

    def status(self) -> dict:
        """The hub's ``health`` message with the socket's counts."""
        return {**self.hub.status(), "socket": {**self.inbound, "resyncs": self.resyncs, "refused": dict(self.refused)}}

    @property
    def held_bytes(self) -> int:
        """Bytes of serialized messages held for the pages: the log and the current snapshot."""
        return self._log_bytes + (self._snapshot.size if self._snapshot is not None else 0)

    # ------------------------------------------------------------------ pages
    def join(self, page: Page) -> None:
        self.pages.add(page)

    def leave(self, page: Page) -> None:
        self.pages.discard(page)
        page.snapshot = None
        if not self.pages:
            self._forget()

    def inbound_text(self, page: Page, data: str) -> None:
        """Text from a page: ``{"type": "ping"}`` is answered; anything else is dropped and counted."""
        if len(data.encode()) > MAX_INBOUND:
            self.inbound["oversized"] += 1
            return
        try:
            message = json.loads(data)
        except ValueError:
            message = None
        if isinstance(message, dict) and message.get("type") == "ping" and len(message) == 1:
            self.inbound["ping"] += 1
            page.replies.append(_PONG)
            page.wake.set()
        else:
            self.inbound["malformed"] += 1

    def next_frame(self, page: Page) -> str | None:
        """The next message for ``page``, or None when it has everything."""
        if page.replies:
            return page.replies.popleft()
        if page.snapshot is None and (page.cursor == 0 or page.cursor < self._first):
            if page.cursor:
                self.resyncs += 1
            page.snapshot, page.part = self._current_snapshot(), 0
            page.cursor = page.snapshot.seq + 1
        if page.snapshot is not None:
            frame = page.snapshot.frames[page.part]
            page.part += 1
            if page.part == len(page.snapshot.frames):
                page.snapshot = None
            return frame
        if page.cursor <= self.seq:
            frame = self._log[page.cursor - self._first]
            page.cursor += 1
            return frame
        return None

    def _current_snapshot(self) -> Snapshot:
        """The shared snapshot: built when there is none that the log can continue."""
        if self._snapshot is None:
            frames = [encode(self.hub.hello())]
            frames.extend(encode(m) for m in self.hub.snapshot_messages())
            frames.append(encode(self.status()))
            self._snapshot = Snapshot(self.seq, tuple(frames))
            self.snapshots_built += 1
        return self._snapshot

    async def pump(self, page: Page) -> None:
        """Write ``page`` its messages in order, each once the connection took the previous."""
        with contextlib.suppress(ConnectionError, RuntimeError):
            while not page.ws.closed:
                frame = self.next_frame(page)
                if frame is None:
                    page.wake.clear()
                    await page.wake.wait()
                    continue
                await page.ws.send_str(frame)

    def count_error(self, ws: Any) -> None:
        """A websocket error: a message over the size limit (1009), or a connection lost."""
        exc = ws.exception()
        code = getattr(exc, "code", None)
        self.inbound["oversized" if code == 1009 else "lost"] += 1
