"""The dashboard's web server (aiohttp): the page, its assets and one read-only websocket.

* Binds to 127.0.0.1 by default. Any other ``--host`` needs a token (generated and printed
  when not given): the page is opened as ``/?token=T``, which sets an HttpOnly, SameSite
  cookie, and every request (assets, the websocket) must carry the token (cookie or query).
  On loopback a given ``--token`` is required the same way; without one, requests whose
  ``Host`` header is not this server's (a DNS-rebinding page) are refused.
* Serves exactly the files of :func:`asset_table` (the page's own files and the plotting
  library's two files), looked up by name: no path from a request ever reaches the file
  system, so nothing outside them can be served.
* The websocket only pushes (:mod:`.hub` messages). Text the page sends is read and dropped:
  ``{"type": "ping"}`` is answered, anything else is counted as malformed, anything longer
  than :data:`MAX_INBOUND` bytes as oversized; binary frames count as malformed.
* A page that cannot keep up gets a fresh snapshot instead of an ever-growing queue.
"""

from __future__ import annotations

import asyncio
import contextlib
import hmac
import json
import socket
import threading
from collections import deque
from collections.abc import Callable
from pathlib import Path
from typing import Any

from aiohttp import WSMsgType, web

from ..errors import ConfigError
from .hub import Hub
from .settings import ServerOptions, is_loopback

__all__ = ["asset_table", "Inbox", "make_app", "serve", "MAX_INBOUND"]

HERE = Path(__file__).resolve().parent
STATIC = HERE / "static"
VENDOR = HERE / "node_modules" / "uplot"
MAX_INBOUND = 1024  # bytes of one message from the page; longer ones are dropped and counted
CLIENT_QUEUE = 256  # messages waiting for one page; beyond, the page is resynchronized
COALESCE_S = 0.005  # items arriving within this of the first are handed to the loop together (Inbox)
TOKEN_COOKIE = "rls_dashboard_token"
_TYPES = {".html": "text/html", ".js": "text/javascript", ".css": "text/css", ".txt": "text/plain"}
_CSP = ("default-src 'none'; script-src 'self'; style-src 'self'; img-src 'self' data:; connect-src 'self'; "
        "base-uri 'none'; form-action 'none'; frame-ancestors 'none'")


def asset_table() -> dict[str, tuple[Path, str]]:
    """Every file the server may send: URL name -> (path, content type)."""
    table = {p.name: (p, _TYPES[p.suffix]) for p in sorted(STATIC.iterdir()) if p.suffix in _TYPES}
    table["uPlot.iife.min.js"] = (VENDOR / "dist" / "uPlot.iife.min.js", _TYPES[".js"])
    table["uPlot.min.css"] = (VENDOR / "dist" / "uPlot.min.css", _TYPES[".css"])
    table["uPlot.LICENSE.txt"] = (VENDOR / "LICENSE", _TYPES[".txt"])
    return table


def check_assets(table: dict[str, tuple[Path, str]]) -> None:
    missing = [str(p) for p, _ in table.values() if not p.is_file()]
    if missing:
        raise ConfigError(f"dashboard assets missing ({', '.join(missing)}): run bash scripts/setup_dashboard.sh "
                          "(it installs uPlot from the npm registry)")


class Inbox:
    """Hands items from other threads (the ROS executor) to the event loop in batches: at most
    ``maxlen`` items waiting (older ones dropped and counted in :attr:`overflow`), and one
    wake-up of the loop per ``coalesce_s`` at most. Waking the loop is a write to its
    self-pipe made from the other thread; waking it for each of the ~1,250 arrays a second of
    six models took a quarter of the dashboard's CPU (benchmarks/dashboard_benchmark.py). The
    node publishes a sample's arrays back to back, so a few milliseconds gather a sample's
    arrays of every model into one batch, one ``samples`` message to the page."""

    def __init__(self, loop: asyncio.AbstractEventLoop, handler: Callable[[list], None],
                 maxlen: int = 200_000, coalesce_s: float = COALESCE_S) -> None:
        self._loop = loop
        self._handler = handler
        self._items: deque = deque(maxlen=maxlen)
        self._lock = threading.Lock()
        self._scheduled = False
        self._coalesce_s = coalesce_s
        self.overflow = 0

    def put(self, item: Any) -> None:
        with self._lock:
            if len(self._items) == self._items.maxlen:
                self.overflow += 1
            self._items.append(item)
            if self._scheduled:
                return
            self._scheduled = True
        with contextlib.suppress(RuntimeError):  # the loop closed while the ROS thread stopped
            self._loop.call_soon_threadsafe(self._loop.call_later, self._coalesce_s, self._drain)

    def _drain(self) -> None:
        with self._lock:
            self._scheduled = False
            items = list(self._items)
            self._items.clear()
        if items:
            self._handler(items)


class _Client:
    def __init__(self, ws: web.WebSocketResponse) -> None:
        self.ws = ws
        self.queue: asyncio.Queue[str] = asyncio.Queue(CLIENT_QUEUE)
        self.resync = False


class Broadcaster:
    """The connected pages: each gets every message in order through its own queue."""

    def __init__(self, hub: Hub) -> None:
        self.hub = hub
        self.clients: set[_Client] = set()
        self.inbound = {"ping": 0, "malformed": 0, "oversized": 0}
        self.resyncs = 0

    def send(self, message: dict | None) -> None:
        if message is None:
            return
        text = json.dumps(message, allow_nan=False, separators=(",", ":"))
        for c in self.clients:
            self._put(c, text)

    def _put(self, c: _Client, text: str) -> None:
        if c.resync:
            return
        try:
            c.queue.put_nowait(text)
        except asyncio.QueueFull:
            # The page fell behind: drop what waits and start it over from a snapshot.
            self.resyncs += 1
            c.resync = True
            while not c.queue.empty():
                c.queue.get_nowait()
            c.queue.put_nowait("")  # wakes the pump, which sends the snapshot

    def welcome(self, c: _Client) -> None:
        c.resync = False
        for message in (self.hub.hello(), self.hub.snapshot(), self.status()):
            c.queue.put_nowait(json.dumps(message, allow_nan=False, separators=(",", ":")))

    def status(self) -> dict:
        return {**self.hub.status(), "socket": {**self.inbound, "resyncs": self.resyncs}}

    def inbound_text(self, c: _Client, data: str) -> None:
        if len(data.encode()) > MAX_INBOUND:
            self.inbound["oversized"] += 1
            return
        try:
            message = json.loads(data)
        except ValueError:
            message = None
        if isinstance(message, dict) and message.get("type") == "ping" and len(message) == 1:
            self.inbound["ping"] += 1
            self._put(c, '{"type":"pong"}')
        else:
            self.inbound["malformed"] += 1

    async def pump(self, c: _Client) -> None:
        """Send ``c``'s queue in order; after a resync, the snapshot."""
        while not c.ws.closed:
            if c.resync:
                self.welcome(c)
            text = await c.queue.get()
            if text:
                await c.ws.send_str(text)


def _allowed_hosts(options: ServerOptions, port: int) -> set[str]:
    names = {options.host, "localhost", "127.0.0.1", "[::1]"} if is_loopback(options.host) else {options.host}
    return {f"{n}:{port}" for n in names} | ({f"[{options.host}]:{port}"} if ":" in options.host else set())


def _authorized(request: web.Request, options: ServerOptions, hosts: set[str]) -> bool:
    if options.token is None:
        return request.host in hosts
    given = request.query.get("token") or request.cookies.get(TOKEN_COOKIE) or ""
    return hmac.compare_digest(given.encode(), options.token.encode())


def make_app(broadcaster: Broadcaster, options: ServerOptions, port: int,
             assets: dict[str, tuple[Path, str]] | None = None) -> web.Application:
    """The routes: ``/`` (the page), ``/static/NAME`` (only the names of ``assets``), ``/ws``."""
    table = asset_table() if assets is None else assets
    hosts = _allowed_hosts(options, port)

    @web.middleware
    async def guard(request: web.Request, handler: Callable) -> web.StreamResponse:
        if not _authorized(request, options, hosts):
            raise web.HTTPForbidden(text="403: token required (open the address the dashboard printed)\n")
        response = await handler(request)
        response.headers.update({"Content-Security-Policy": _CSP, "X-Content-Type-Options": "nosniff",
                                 "Referrer-Policy": "no-referrer", "Cache-Control": "no-store"})
        return response

    def send_file(name: str) -> web.Response:
        path, content_type = table[name]
        return web.Response(body=path.read_bytes(), content_type=content_type)

    async def index(request: web.Request) -> web.Response:
        response = send_file("index.html")
        if options.token is not None and request.query.get("token"):
            response.set_cookie(TOKEN_COOKIE, options.token, httponly=True, samesite="Strict", path="/")
        return response

    async def static(request: web.Request) -> web.Response:
        name = request.match_info["name"]
        if name not in table or name == "index.html":
            raise web.HTTPNotFound()
        return send_file(name)

    async def websocket(request: web.Request) -> web.WebSocketResponse:
        # No per-message compression: deflating each small JSON message cost a tenth of the
        # dashboard's CPU, for ~100 kB/s that any network carries.
        ws = web.WebSocketResponse(max_msg_size=64 * 1024, heartbeat=20.0, compress=False)
        await ws.prepare(request)
        client = _Client(ws)
        broadcaster.clients.add(client)
        broadcaster.welcome(client)
        pump = asyncio.create_task(broadcaster.pump(client))
        try:
            async for msg in ws:
                if msg.type == WSMsgType.TEXT:
                    broadcaster.inbound_text(client, msg.data)
                elif msg.type == WSMsgType.BINARY:
                    broadcaster.inbound["malformed"] += 1
                elif msg.type == WSMsgType.ERROR:  # e.g. beyond max_msg_size: aiohttp closes
                    broadcaster.inbound["oversized"] += 1
        finally:
            broadcaster.clients.discard(client)
            pump.cancel()
        return ws

    app = web.Application(middlewares=[guard], client_max_size=4096)
    app.router.add_get("/", index)
    app.router.add_get("/static/{name}", static)
    app.router.add_get("/ws", websocket)
    return app


def bind(options: ServerOptions) -> socket.socket:
    """The listening socket (port 0: a free one), or ConfigError naming --host/--port."""
    family = socket.AF_INET6 if ":" in options.host else socket.AF_INET
    try:
        return socket.create_server((options.host, options.port), family=family, reuse_port=False)
    except OSError as exc:
        raise ConfigError(f"cannot listen on {options.host}:{options.port} ({exc.strerror}): "
                          "choose another --port or --host") from exc


async def serve(broadcaster: Broadcaster, options: ServerOptions, sock: socket.socket,
                stop: asyncio.Event) -> None:
    """Serve until ``stop`` is set."""
    port = sock.getsockname()[1]
    runner = web.AppRunner(make_app(broadcaster, options, port), handle_signals=False, access_log=None)
    await runner.setup()
    try:
        await web.SockSite(runner, sock).start()
        await stop.wait()
    finally:
        for c in list(broadcaster.clients):
            await c.ws.close()
        await runner.cleanup()
