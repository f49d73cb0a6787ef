"""The dashboard's web server (aiohttp): the page, its assets and one read-only websocket.

* Binds to 127.0.0.1 by default. Any other ``--host`` needs a token (generated and printed
  when not given): the page is opened as ``/?token=T``, which sets an HttpOnly, SameSite
  cookie, and every request (assets, the websocket) must carry the token (cookie or query).
  On loopback a given ``--token`` is required the same way; without one, requests whose
  ``Host`` header is not this server's (a DNS-rebinding page) are refused.
* The websocket is refused (403, counted) to a page of another origin: a browser names the
  page that opens a websocket in ``Origin``, and only this server's own (``http://`` + the
  ``Host`` it was asked by) or one of ``--allow-origin`` may read the estimates. A client that
  is not a browser sends no ``Origin`` and is let through (the token, when set, still applies).
* Serves exactly the files of :func:`asset_table` (the page's own files and the plotting
  library's two files), looked up by name: no path from a request ever reaches the file
  system, so nothing outside them can be served.
* The websocket only pushes (:mod:`.feed`: shared messages, bounded per page). Text the page
  sends is read and dropped: ``{"type": "ping"}`` is answered, anything else is counted as
  malformed, anything longer than :data:`.feed.MAX_INBOUND` bytes as oversized; binary
  frames count as malformed.
* Connections are bounded in number and must send their request in time (:mod:`.guard`).
"""

from __future__ import annotations

import asyncio
import contextlib
import hmac
import socket
import threading
from collections import deque
from collections.abc import AsyncIterator, Callable
from pathlib import Path
from typing import Any

from aiohttp import WSMsgType, web

from ..errors import ConfigError
from .feed import Feed, Page
from .guard import ConnectionGuard, connection_limit
from .settings import ServerOptions, is_loopback

__all__ = ["asset_table", "check_assets", "Inbox", "make_app", "bind", "serving", "serve"]

HERE = Path(__file__).resolve().parent
STATIC = HERE / "static"
VENDOR = HERE / "node_modules" / "uplot"
HEARTBEAT_S = 20.0  # a websocket that answers no ping within half of this is closed
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


def _allowed_hosts(options: ServerOptions, port: int) -> set[str]:
    names = {options.host, "localhost", "127.0.0.1", "[::1]"} if is_loopback(options.host) else {options.host}
    return {f"{n}:{port}" for n in names} | ({f"[{options.host}]:{port}"} if ":" in options.host else set())


def _authorized(request: web.Request, options: ServerOptions, hosts: set[str]) -> bool:
    if options.token is None:
        return request.host in hosts
    given = request.query.get("token") or request.cookies.get(TOKEN_COOKIE) or ""
    return hmac.compare_digest(given.encode(), options.token.encode())


def same_origin(request: web.Request, options: ServerOptions) -> bool:
    """Whether a websocket request may be served: no ``Origin`` (not a browser), this server's
    own origin, or one of ``--allow-origin``."""
    origin = request.headers.get("Origin")
    if origin is None:
        return True
    origin = origin.strip().lower()
    return origin == f"{request.scheme}://{request.host}".lower() or origin in options.allow_origin


def make_app(feed: Feed, options: ServerOptions, port: int,
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
        if not same_origin(request, options):
            feed.refused["foreign_origin"] += 1
            raise web.HTTPForbidden(text="403: a page of another origin may not read the dashboard (see its "
                                         "--allow-origin)\n")
        # No per-message compression: deflating each small JSON message cost a tenth of the
        # dashboard's CPU, for ~100 kB/s that any network carries.
        ws = web.WebSocketResponse(max_msg_size=64 * 1024, heartbeat=HEARTBEAT_S, compress=False)
        await ws.prepare(request)
        page = Page(ws, request.transport)
        feed.join(page)
        pump = asyncio.create_task(feed.pump(page))
        try:
            async for msg in ws:
                if msg.type == WSMsgType.TEXT:
                    feed.inbound_text(page, msg.data)
                elif msg.type == WSMsgType.BINARY:
                    feed.inbound["malformed"] += 1
                elif msg.type == WSMsgType.ERROR:  # beyond max_msg_size (aiohttp closes), or the heartbeat
                    feed.count_error(ws)
        finally:
            feed.leave(page)
            pump.cancel()
            if page.buffered and request.transport is not None:
                request.transport.abort()  # a page that stopped reading: drop what it did not take, now
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


@contextlib.asynccontextmanager
async def serving(feed: Feed, options: ServerOptions, sock: socket.socket,
                  warn: Callable[[str], None] = print) -> AsyncIterator[ConnectionGuard]:
    """Serve on ``sock`` behind a :class:`.guard.ConnectionGuard` while inside the block; on
    leaving it, every page is closed and the port released."""
    port = sock.getsockname()[1]
    runner = web.AppRunner(make_app(feed, options, port), handle_signals=False, access_log=None,
                           keepalive_timeout=options.header_timeout)
    await runner.setup()
    limit, why = connection_limit(options.max_connections)
    if why:
        warn(why)
    assert runner.server is not None
    guard = ConnectionGuard(runner.server, limit, options.header_timeout, feed.refused)
    server = await asyncio.get_running_loop().create_server(guard, sock=sock)
    try:
        yield guard
    finally:
        server.close()
        await asyncio.gather(*(asyncio.wait_for(page.ws.close(), 2.0) for page in list(feed.pages)),
                             return_exceptions=True)
        await runner.cleanup()


async def serve(feed: Feed, options: ServerOptions, sock: socket.socket, stop: asyncio.Event,
                warn: Callable[[str], None] = print) -> None:
    """Serve until ``stop`` is set."""
    async with serving(feed, options, sock, warn):
        await stop.wait()
