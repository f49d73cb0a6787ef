"""The dashboard's web server on 127.0.0.1 (no ROS): it serves the page and exactly its assets,
nothing outside them whatever the path; a non-loopback host needs the token (query or cookie)
for the page, the assets and the socket; the socket only pushes, and malformed or oversized
messages from a page are dropped and counted without closing it."""

from __future__ import annotations

import asyncio
import json
import socket

import aiohttp
import pytest

from rls_uncertainty.dashboard.hub import Hub, Source
from rls_uncertainty.dashboard.server import (
    MAX_INBOUND,
    TOKEN_COOKIE,
    Broadcaster,
    asset_table,
    make_app,
)
from rls_uncertainty.dashboard.settings import ServerOptions, check_options
from rls_uncertainty.errors import ConfigError

TOKEN = "s3cret-token-0123456789"


def _run(options: ServerOptions, scenario):
    """Start the app on a free loopback port, run ``scenario(base_url, broadcaster, port)``, stop."""

    async def main():
        from aiohttp import web

        sock = socket.create_server(("127.0.0.1", 0))
        port = sock.getsockname()[1]
        broadcaster = Broadcaster(Hub(Source("live", "/rls_estimator", domain="25", discovery_range="LOCALHOST")))
        runner = web.AppRunner(make_app(broadcaster, options, port), access_log=None)
        await runner.setup()
        await web.SockSite(runner, sock).start()
        try:
            return await scenario(f"http://127.0.0.1:{port}", broadcaster, port)
        finally:
            for c in list(broadcaster.clients):
                await c.ws.close()
            await runner.cleanup()

    return asyncio.run(asyncio.wait_for(main(), 60))


async def _raw(port: int, target: str, host: str | None = None) -> tuple[int, bytes]:
    """A GET with the request target sent exactly as given (no client-side normalization)."""
    reader, writer = await asyncio.open_connection("127.0.0.1", port)
    writer.write(f"GET {target} HTTP/1.1\r\nHost: {host or f'127.0.0.1:{port}'}\r\nConnection: close\r\n\r\n".encode())
    await writer.drain()
    data = await reader.read()
    writer.close()
    status = int(data.split(b" ", 2)[1])
    return status, data.partition(b"\r\n\r\n")[2]


def test_the_page_and_each_asset_are_served_with_a_strict_content_policy():
    table = asset_table()

    async def scenario(base, _b, _port):
        async with aiohttp.ClientSession() as s:
            async with s.get(base + "/") as r:
                assert r.status == 200 and r.content_type == "text/html"
                assert "default-src 'none'" in r.headers["Content-Security-Policy"]
                assert r.headers["X-Content-Type-Options"] == "nosniff"
                page = await r.text()
            for name, (path, ctype) in table.items():
                if name == "index.html":
                    continue
                async with s.get(f"{base}/static/{name}") as r:
                    assert r.status == 200 and r.content_type == ctype
                    assert await r.read() == path.read_bytes()
            async with s.post(base + "/") as r:
                assert r.status == 405  # read only
        return page

    page = _run(ServerOptions(), scenario)
    assert 'src="static/uPlot.iife.min.js"' in page and 'src="static/app.js"' in page
    assert "http" not in page.replace("http-equiv", "")  # nothing from another host


@pytest.mark.parametrize("target", [
    "/static/../server.py", "/static/..%2fserver.py", "/static/%2e%2e/%2e%2e/errors.py", "/static/..%5cserver.py",
    "/static//etc/passwd", "/static/%2fetc%2fpasswd", "/../../../../etc/passwd",
    "/static/node_modules/uplot/package.json", "/static/index.html/../../app.py", "/static/.", "/static/",
    "/%2e%2e/rls_uncertainty/cli.py", "/ws/../static/app.js", "/static/uPlot.iife.min.js%00.txt",
    "/static/app.js?../../server.py",
])
def test_no_file_outside_the_page_assets_is_ever_served(target):
    secrets_on_disk = [b"root:", b"import ", b"def ", b'"name": "uplot"']

    async def scenario(_base, _b, port):
        return await _raw(port, target)

    status, body = _run(ServerOptions(), scenario)
    if target == "/static/app.js?../../server.py":  # a query string is not part of the path
        assert status == 200
        return
    assert status in (400, 403, 404), (target, status)
    assert not any(s in body for s in secrets_on_disk), (target, body[:200])


def test_loopback_without_token_refuses_a_foreign_host_header():
    async def scenario(_base, _b, port):
        return [(await _raw(port, "/", host))[0] for host in (f"127.0.0.1:{port}", f"localhost:{port}",
                                                             "evil.example:80", f"evil.example:{port}")]

    assert _run(ServerOptions(), scenario) == [200, 200, 403, 403]


def test_a_token_is_required_for_the_page_the_assets_and_the_socket():
    async def scenario(base, _b, _port):
        got = {}
        # unsafe=True: aiohttp's client keeps cookies of IP-address hosts only then (a browser does).
        async with aiohttp.ClientSession(cookie_jar=aiohttp.CookieJar(unsafe=True)) as s:
            for path in ("/", "/static/app.js", f"/?token={TOKEN[:-1]}x"):
                async with s.get(base + path) as r:
                    got[path] = r.status
            with pytest.raises(aiohttp.WSServerHandshakeError):
                await s.ws_connect(base + "/ws")
            async with s.get(f"{base}/?token={TOKEN}") as r:
                got["with token"] = r.status
                assert TOKEN_COOKIE in r.cookies and r.cookies[TOKEN_COOKIE]["httponly"]
            async with s.get(base + "/static/app.js") as r:  # the cookie now
                got["asset with cookie"] = r.status
            ws = await s.ws_connect(base + "/ws")
            got["socket"] = json.loads((await ws.receive(timeout=10)).data)["type"]
            await ws.close()
        return got

    got = _run(check_options("127.0.0.1", 0, TOKEN), scenario)
    assert got == {"/": 403, "/static/app.js": 403, f"/?token={TOKEN[:-1]}x": 403, "with token": 200,
                   "asset with cookie": 200, "socket": "hello"}


def test_a_host_other_than_loopback_gets_a_generated_token_and_bad_options_are_named():
    options = check_options("0.0.0.0", 8080, None)
    assert options.token is not None and len(options.token) >= 16
    assert check_options("127.0.0.1", 8080, None).token is None
    assert check_options("::1", 0, None).token is None
    for args, word in ((("example.com", 80, None), "--host"), (("127.0.0.1", 70000, None), "--port"),
                       (("127.0.0.1", 80, "short"), "--token")):
        with pytest.raises(ConfigError, match=word):
            check_options(*args)


def test_the_socket_pushes_state_and_drops_and_counts_what_a_page_sends():
    async def scenario(base, broadcaster, _port):
        async with aiohttp.ClientSession() as s:
            ws = await s.ws_connect(base + "/ws")
            first = [json.loads((await ws.receive(timeout=10)).data) for _ in range(3)]
            await ws.send_str('{"type":"ping"}')
            pong = json.loads((await ws.receive(timeout=10)).data)
            for text in ("not json", '{"type":"enable"}', '{"type":"ping","x":1}', "[1]"):
                await ws.send_str(text)
            await ws.send_str('{"type":"ping","pad":"' + "x" * MAX_INBOUND + '"}')
            await ws.send_bytes(b"\x00\x01")
            await ws.send_str('{"type":"ping"}')  # still connected: answered
            second = json.loads((await ws.receive(timeout=10)).data)
            broadcaster.send(broadcaster.status())
            status = json.loads((await ws.receive(timeout=10)).data)
            await ws.close()
        return first, pong, second, status

    first, pong, second, status = _run(ServerOptions(), scenario)
    assert [m["type"] for m in first] == ["hello", "snapshot", "health"]
    assert first[0]["domain"] == "25" and first[0]["discovery_range"] == "LOCALHOST"
    assert pong == second == {"type": "pong"}
    assert status["socket"] == {"ping": 2, "malformed": 5, "oversized": 1, "resyncs": 0}


def test_a_page_that_falls_behind_is_resynchronized_from_a_snapshot_not_queued_without_bound():
    from rls_uncertainty.dashboard.server import CLIENT_QUEUE, _Client

    async def main():
        hub = Hub(Source("live", "/rls_estimator"))
        b = Broadcaster(hub)

        class _Closed:
            closed = False

        c = _Client(_Closed())  # type: ignore[arg-type]
        b.clients.add(c)
        for k in range(CLIENT_QUEUE + 10):
            b.send({"type": "samples", "k": k})
        assert c.resync and b.resyncs == 1 and c.queue.qsize() == 1  # only the wake-up left
        b.welcome(c)
        texts = [c.queue.get_nowait() for _ in range(c.queue.qsize())]
        return [json.loads(t)["type"] for t in texts if t]

    types = asyncio.run(main())
    assert types == ["hello", "snapshot", "health"]
