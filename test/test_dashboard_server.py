"""The dashboard's web server on 127.0.0.1 (no ROS): it serves the page and exactly its assets,
nothing outside them whatever the path; a non-loopback host needs the token (query or cookie)
for the page, the assets and the socket, and a token must be hard to guess; the socket is
refused to a page of another origin; it only pushes, and malformed or oversized messages from
a page are dropped and counted without closing it. Every page gets one shared snapshot, a page
that falls behind gets the latest state instead of a growing queue, a page that stops reading
holds a bounded buffer, and connections are bounded in number and in the time they take to
send a request."""

from __future__ import annotations

import asyncio
import json
import socket

import aiohttp
import pytest

from rls_uncertainty.dashboard.feed import MAX_INBOUND, Feed
from rls_uncertainty.dashboard.hub import Hub, Source
from rls_uncertainty.dashboard.server import TOKEN_COOKIE, asset_table, serving
from rls_uncertainty.dashboard.settings import ServerOptions, check_options
from rls_uncertainty.errors import ConfigError

TOKEN = "s3cret-token-0123456789"


def _run(options: ServerOptions, scenario, hub: Hub | None = None, timeout: float = 60):
    """Serve on a free loopback port as the command does, run ``scenario(base_url, feed, port)``, stop."""

    async def main():
        sock = socket.create_server(("127.0.0.1", 0))
        port = sock.getsockname()[1]
        feed = Feed(hub or Hub(Source("live", "/rls_estimator", domain="25", discovery_range="LOCALHOST")))
        async with serving(feed, options, sock):
            return await scenario(f"http://127.0.0.1:{port}", feed, port)

    return asyncio.run(asyncio.wait_for(main(), timeout))


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
    async def scenario(base, feed, _port):
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
            feed.send(feed.status())
            status = json.loads((await ws.receive(timeout=10)).data)
            await ws.close()
        return first, pong, second, status

    first, pong, second, status = _run(ServerOptions(), scenario)
    assert [m["type"] for m in first] == ["hello", "snapshot", "health"]
    assert first[0]["domain"] == "25" and first[0]["discovery_range"] == "LOCALHOST"
    assert pong == second == {"type": "pong"}
    assert {k: v for k, v in status["socket"].items() if k != "refused"} == {
        "ping": 2, "malformed": 5, "oversized": 1, "lost": 0, "resyncs": 0}




# ------------------------------------------------------------------ token and origin
@pytest.mark.parametrize("token", ["a" * 16, "a" * 64, "ab" * 16, "abcdefghi" * 3, "0123456789012345"])
def test_a_guessable_token_is_refused_saying_what_is_required(token):
    with pytest.raises(ConfigError, match=r"--token: at least 16 printable ASCII characters without spaces, at "
                                          r"least 10 of them different, and 64 bits or more"):
        check_options("127.0.0.1", 0, token)


def test_a_token_of_random_characters_is_accepted():
    import secrets

    for _ in range(200):
        token = secrets.token_urlsafe(24)
        assert check_options("127.0.0.1", 0, token).token == token
    assert check_options("127.0.0.1", 0, TOKEN).token == TOKEN
    assert check_options("0.0.0.0", 0, None).token  # the one generated when none is given passes its own check


def _ws_status(port: int, origin: str | None, host: str | None = None) -> tuple[int, bytes]:
    """The status of a websocket handshake sent as a browser would, with ``Origin``."""
    import base64
    import os

    lines = ["GET /ws HTTP/1.1", f"Host: {host or f'127.0.0.1:{port}'}", "Upgrade: websocket", "Connection: Upgrade",
             f"Sec-WebSocket-Key: {base64.b64encode(os.urandom(16)).decode()}", "Sec-WebSocket-Version: 13"]
    if origin is not None:
        lines.append(f"Origin: {origin}")
    with socket.create_connection(("127.0.0.1", port), timeout=10) as s:
        s.sendall(("\r\n".join(lines) + "\r\n\r\n").encode())
        head = s.recv(4096)
    return int(head.split(b" ", 2)[1]), head


def test_the_socket_is_refused_to_a_page_of_another_origin_and_counted():
    """A browser names the page that opens a websocket in Origin: another site's page, a
    sandboxed one ("null") or a look-alike port is refused (403) before anything is sent; the
    dashboard's own page, an origin of --allow-origin, or a client that is not a browser (no
    Origin) is served."""
    options = check_options("127.0.0.1", 0, None, allow_origin=("https://Wall.Example:8443/",))

    async def scenario(_base, feed, port):
        loop = asyncio.get_running_loop()
        got = {}
        for origin in ("http://evil.example", "null", f"http://127.0.0.1:{port + 1}", f"https://127.0.0.1:{port}",
                       f"http://127.0.0.1:{port}", f"http://LOCALHOST:{port}", "https://wall.example:8443", None):
            host = f"localhost:{port}" if origin and "LOCALHOST" in origin else None
            status, head = await loop.run_in_executor(None, _ws_status, port, origin, host)
            got[origin] = status
            assert status == 101 or b"hello" not in head  # a refused page reads nothing
        return got, dict(feed.refused)

    got, refused = _run(options, scenario)
    assert options.allow_origin == ("https://wall.example:8443",)
    assert list(got.values()) == [403, 403, 403, 403, 101, 101, 101, 101]
    assert refused["foreign_origin"] == 4


@pytest.mark.parametrize("value", ["evil.example", "ftp://wall.example", "https://wall.example/page",
                                   "https://user@wall.example", "https://wall.example:99999", "https://"])
def test_an_allowed_origin_must_be_an_origin(value):
    with pytest.raises(ConfigError, match=r"--allow-origin .*scheme://host\[:port\]"):
        check_options("127.0.0.1", 0, None, allow_origin=(value,))


# ------------------------------------------------------------------ what the pages are sent
def _big_hub(samples: int = 20_000) -> Hub:
    """A finished replay's hub with ``samples`` samples of CZ (3 parameters) and Cm (4)."""
    from rls_uncertainty.dashboard.model import Sample

    hub = Hub(Source("replay", "/rls_estimator", replay_dir="/nowhere", replay_file="estimates.csv"))
    for model, n in (("CZ", 3), ("Cm", 4)):
        names = tuple(f"{model}_{i}" for i in range(n))
        hub.add_samples([Sample(model, 1_000_000_000 + 20_000_000 * k, names, tuple(0.1 * k + i for i in range(n)),
                                (0.01,) * n, (0.003,) * n, (1.0,) * n, None) for k in range(samples)])
    hub.replay_finished()
    return hub


async def _read_page(ws) -> tuple[list[dict], int]:
    """A page's messages up to the health message that ends its snapshot, and their bytes."""
    messages, size = [], 0
    while True:
        msg = await ws.receive(timeout=60)
        messages.append(json.loads(msg.data))
        size += len(msg.data)
        if messages[-1]["type"] == "health" and any(m["type"] == "snapshot" for m in messages):
            return messages, size


def test_every_page_gets_the_same_snapshot_built_once_in_bounded_pieces():
    """Ten pages joining a finished replay get the whole display history (equal to the hub's,
    and the counts of samples shown) from one snapshot serialized once and shared, in messages
    of at most FRAME_VALUES numbers; when they leave, the server holds nothing for them."""
    from rls_uncertainty.dashboard.messages import FRAME_VALUES

    hub = _big_hub()

    async def scenario(base, feed, _port):
        async with aiohttp.ClientSession() as s:
            sockets = [await s.ws_connect(base + "/ws", max_msg_size=0) for _ in range(10)]
            pages = await asyncio.gather(*(_read_page(ws) for ws in sockets))
            held = feed.held_bytes
            for ws in sockets:
                await ws.close()
            deadline = asyncio.get_running_loop().time() + 30
            while feed.pages:
                assert asyncio.get_running_loop().time() < deadline
                await asyncio.sleep(0.05)
        return pages, feed.snapshots_built, held, feed.held_bytes

    pages, built, held, after = _run(ServerOptions(), scenario, hub)
    assert built == 1
    first, size = pages[0]
    assert all(p == (first, size) for p in pages)
    assert [m["type"] for m in first[:2]] == ["hello", "snapshot"] and first[-1]["type"] == "health"
    for m in first:
        if m["type"] == "samples":
            assert m["snapshot"] is True
            assert sum(len(c["t"]) * (1 + 4 * len(c["names"])) for c in m["models"].values()) <= FRAME_VALUES
    for (method, model), h in hub.histories.items():
        pieces = [m["models"][model] for m in first if m["type"] == "samples" and model in m["models"]]
        assert [t for p in pieces for t in p["t"]] == h.columns()["t"]
        assert [v for p in pieces for v in p["estimate"][1]] == h.columns()["estimate"][1]
        assert [p.get("count") for p in pieces] == [None] * (len(pieces) - 1) + [hub.counts()[method][model]]
    assert held >= size - 1000 and after == 0


def test_a_page_that_falls_behind_gets_the_latest_state_not_a_growing_queue():
    """Messages are kept once, for every page, in a log of bounded size. A page that has not
    taken what it was sent when the log moves past it skips what it missed: its next messages
    are a new snapshot (the latest state), then what follows it."""
    from rls_uncertainty.dashboard.feed import Page

    async def main():
        hub = _big_hub(50)
        feed = Feed(hub, log_bytes=2000)
        slow, fast = Page(None), Page(None)  # type: ignore[arg-type]
        for page in (slow, fast):
            feed.join(page)
        taken = {id(slow): [], id(fast): []}

        def take(page):
            while (frame := feed.next_frame(page)) is not None:
                taken[id(page)].append(json.loads(frame))

        take(fast)
        take(slow)
        first = feed.snapshots_built
        snapshot_size = feed.held_bytes  # the one snapshot both took; the log is empty
        for k in range(200):
            feed.send({"type": "health", "k": k})
            take(fast)
            assert feed.held_bytes <= 2000 + 200 + snapshot_size
        take(slow)
        return taken[id(slow)], taken[id(fast)], first, feed

    slow, fast, first, feed = asyncio.run(main())
    assert [m.get("k") for m in fast if m["type"] == "health" and "k" in m] == list(range(200))  # kept up: all
    resync = [i for i, m in enumerate(slow) if m["type"] == "hello"]
    assert len(resync) == 2 and feed.resyncs == 1 and first == 1 and feed.snapshots_built == 2
    after = slow[resync[1]:]
    assert [m["type"] for m in after[:2]] == ["hello", "snapshot"]
    assert [m["k"] for m in after if "k" in m] == []  # the latest state only: no k of the 200 replayed
    assert len(slow) < len(fast)


def test_a_page_that_never_reads_holds_a_bounded_buffer_and_nothing_once_gone():
    """Pages whose connection takes nothing (a socket never read) get at most a few hundred kB
    written each, whatever the snapshot's size (about 10 MB here); a reading page meanwhile
    gets its whole snapshot; when they go, their buffers go with them."""
    hub = _big_hub()
    bound = 512 * 1024

    async def scenario(base, feed, port):
        loop = asyncio.get_running_loop()
        stalled = []
        for _ in range(5):
            s = socket.socket()
            s.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
            s.connect(("127.0.0.1", port))
            s.sendall(b"GET /ws HTTP/1.1\r\nHost: 127.0.0.1:%d\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n"
                      b"Sec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\nSec-WebSocket-Version: 13\r\n\r\n" % port)
            stalled.append(s)
        deadline = loop.time() + 60
        sizes: list[int] = []
        while True:  # until every stalled page's writer waits for its connection (no growth for 1 s)
            await asyncio.sleep(1.0)
            now = sorted(p.buffered for p in feed.pages)
            if len(now) == 5 and now == sizes and min(now) > 0:
                break
            sizes = now
            assert loop.time() < deadline, sizes
        async with aiohttp.ClientSession() as session:
            ws = await session.ws_connect(base + "/ws", max_msg_size=0)
            messages, _ = await _read_page(ws)
            await ws.close()
        for s in stalled:
            s.close()
        while feed.pages:
            assert loop.time() < deadline + 30
            await asyncio.sleep(0.05)
        return sizes, messages, feed.held_bytes

    sizes, messages, held = _run(ServerOptions(), scenario, hub, timeout=180)
    assert max(sizes) <= bound, sizes
    assert sum(len(m["models"]["CZ"]["t"]) for m in messages if m["type"] == "samples" and "CZ" in m["models"]) \
        == hub.histories[("time", "CZ")].size
    assert held == 0


# ------------------------------------------------------------------ connections
def test_connections_beyond_the_limit_are_closed_at_once_and_counted():
    options = check_options("127.0.0.1", 0, None, max_connections=3, header_timeout=60.0)

    async def scenario(_base, feed, port):
        loop = asyncio.get_running_loop()
        held = [await asyncio.open_connection("127.0.0.1", port) for _ in range(3)]
        deadline = loop.time() + 30
        extra = [await asyncio.open_connection("127.0.0.1", port) for _ in range(4)]
        for reader, _ in extra:  # closed by the server without a byte
            assert await asyncio.wait_for(reader.read(), max(0.1, deadline - loop.time())) == b""
        refused = dict(feed.refused)
        for _, writer in held + extra:
            writer.close()
        while True:  # slots are free again once the held connections are gone
            try:
                status, _ = await _raw(port, "/")
                break
            except IndexError:  # refused: closed without an answer
                assert loop.time() < deadline
                await asyncio.sleep(0.05)
        return refused, status

    refused, status = _run(options, scenario)
    assert refused["connection_limit"] == 4 and status == 200


def test_a_request_not_complete_in_time_is_closed_and_counted_and_others_are_served():
    """Half-open requests (a head without its blank line, or nothing at all) are closed once
    --header-timeout has passed; a complete request meanwhile is served."""
    options = check_options("127.0.0.1", 0, None, header_timeout=0.5)

    async def scenario(_base, feed, port):
        half = []  # the writers kept: a StreamWriter closes its connection when collected
        for data in (b"GET / HTTP/1.1\r\nHost: 127.0.0.1\r\n", b"", b"GET / HT"):
            reader, writer = await asyncio.open_connection("127.0.0.1", port)
            writer.write(data)
            half.append((reader, writer))
        status, _ = await _raw(port, "/")
        closed = [await asyncio.wait_for(r.read(), 30) for r, _w in half]
        for _r, w in half:
            w.close()
        return status, closed, dict(feed.refused)

    status, closed, refused = _run(options, scenario)
    assert status == 200 and closed == [b"", b"", b""] and refused["header_timeout"] == 3


def test_a_wildcard_host_prints_an_address_a_browser_can_open():
    """``--host 0.0.0.0`` (or ``::``) listens on every interface; the address printed is this
    machine's name when it resolves, else 127.0.0.1; never the wildcard itself."""
    import socket

    from rls_uncertainty.dashboard.app import url_host

    name = socket.gethostname()
    try:
        socket.getaddrinfo(name, None)
        expected = name or "127.0.0.1"
    except OSError:
        expected = "127.0.0.1"
    for wildcard in ("0.0.0.0", "::"):
        assert url_host(wildcard) == expected
    assert url_host("192.168.1.5") == "192.168.1.5" and url_host("127.0.0.1") == "127.0.0.1"


def test_the_dashboard_on_every_interface_prints_a_url_that_serves_the_page(tmp_path):
    """`rls-uncertainty dashboard --host 0.0.0.0`: its first lines name a host other than the
    wildcard, and the printed token URL serves the page."""
    import subprocess
    import sys
    import urllib.request

    from rls_uncertainty.ros.player import stop_process

    command = [sys.executable, "-m", "rls_uncertainty.cli", "dashboard", "--host", "0.0.0.0", "--port", "0",
               "--node", "/nobody_here/rls_estimator"]
    proc = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        serving, token = proc.stdout.readline(), proc.stdout.readline()
        assert serving.startswith("serving http://") and "0.0.0.0" not in serving, serving
        url = token.split("open ", 1)[1].strip()
        assert "0.0.0.0" not in url and "?token=" in url, token
        with urllib.request.urlopen(url, timeout=30) as response:
            assert response.status == 200 and b"rls_uncertainty control room" in response.read()
    finally:
        stop_process(proc, 30)
