"""``rls-uncertainty dashboard``: the options checked once, the source (live node or finished
replay) wired to the :class:`.hub.Hub` and the web server, and a clean stop on Ctrl-C or
SIGTERM (browser pages closed, ROS node destroyed, port released)."""

from __future__ import annotations

import asyncio
import signal
import socket
import sys
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from ..ros.environment import discovery_environment
from .feed import Feed
from .hub import Hub, Source
from .model import Sample
from .server import Inbox, asset_table, bind, check_assets, serve
from .settings import ServerOptions, check_options, full_node_name, load_reference

if TYPE_CHECKING:  # annotations only: rclpy and the bag library are imported where they are used
    from .replay_source import ReplaySource
    from .ros_source import RosSource

__all__ = ["DashboardOptions", "dashboard_options", "run", "url_host"]


@dataclass(frozen=True)
class DashboardOptions:
    server: ServerOptions
    node: str
    replay: Path | None
    reference: dict[str, float]


def dashboard_options(server_values: Mapping[str, Any], node: str, replay: str | None = None,
                      reference: str | None = None) -> DashboardOptions:
    """Every option checked (ConfigError naming the one to change) before anything starts;
    ``server_values`` are :class:`.settings.ServerOptions`' fields by name."""
    server = check_options(**server_values)
    check_assets(asset_table())
    return DashboardOptions(server, full_node_name(node), Path(replay) if replay else None,
                            load_reference(reference) if reference else {})


class _Dispatch:
    """Items from a source (live or replay) into the hub, and the hub's messages out. Arrays and
    samples in a row are handed to the hub together (one ``samples`` message per batch)."""

    def __init__(self, hub: Hub, feed: Feed) -> None:
        self.hub = hub
        self.feed = feed

    def __call__(self, items: list[tuple]) -> None:
        arrays: list[tuple] = []
        samples: list[Sample] = []
        for item in items:
            kind = item[0]
            if kind == "array":
                arrays.append(item[1:])
            elif kind == "sample":
                samples.append(item[1])
            else:
                self._flush(arrays, samples)
                self._other(item)
        self._flush(arrays, samples)

    def _other(self, item: tuple) -> None:
        hub, send = self.hub, self.feed.send
        if item[0] == "diagnostics":
            if hub.add_diagnostics(item[1]) is not None:
                if hub.take_reset():
                    send({"type": "reset"})
                send(self.feed.status())
                for message in hub.quality_updates():
                    send(message)
        elif item[0] == "maneuvers":
            send(hub.add_maneuvers(item[1]))
        elif item[0] == "graph":
            if hub.set_graph(item[1]) is not None:
                send(self.feed.status())
        elif item[0] == "replay_done":
            hub.replay_finished(item[1])
            send(self.feed.status())
            for problem in (item[1], hub.refused_text()):
                if problem:
                    print(f"rls-uncertainty dashboard: {hub.source.replay_dir}: {problem}", file=sys.stderr,
                          flush=True)

    def _flush(self, arrays: list[tuple], samples: list[Sample]) -> None:
        if not (arrays or samples):
            return
        before = self.hub.state()["state"]
        for message in [*(self.hub.add_arrays(arrays) if arrays else []),
                        *(self.hub.add_samples(samples) if samples else [])]:
            self.feed.send(message)
        arrays.clear()
        samples.clear()
        if self.hub.state()["state"] != before:  # the first samples: "running" at once, not at the next diagnostics
            self.feed.send(self.feed.status())


async def _main(options: DashboardOptions, hub: Hub, replay: ReplaySource | None, sock: socket.socket) -> None:
    loop = asyncio.get_running_loop()
    stop = asyncio.Event()
    for sig in (signal.SIGINT, signal.SIGTERM):
        loop.add_signal_handler(sig, stop.set)
    feed = Feed(hub)
    dispatch = _Dispatch(hub, feed)
    source: ReplaySource | RosSource
    if replay is not None:
        source = replay
        replay.start(loop.call_soon_threadsafe, dispatch)
    else:
        from .ros_source import RosSource  # noqa: PLC0415 - rclpy only for the live mode

        inbox = Inbox(loop, dispatch)
        source = RosSource(options.node, inbox.put)
        source.start()
    try:
        await serve(feed, options.server, sock, stop, warn=_warn)
    finally:
        source.stop()
    print(f"dashboard stopped: {hub.samples_shown} samples; {_counts(hub, feed)}", file=sys.stderr)


def _warn(text: str) -> None:
    print(f"rls-uncertainty dashboard: {text}", file=sys.stderr, flush=True)


def _counts(hub: Hub, feed: Feed) -> str:
    """What was dropped or refused, for the line printed at exit."""
    def listed(counts: Mapping[str, int]) -> str:
        return ", ".join(f"{k} {v}" for k, v in sorted(counts.items())) or "none"

    refused = {k: v for k, v in hub.refused.items() if v}
    return (f"arrays dropped: {listed(hub.pairing.dropped)}; samples refused: {listed(refused)}; "
            f"from pages: {', '.join(f'{k} {v}' for k, v in feed.inbound.items())}; "
            f"connections refused: {', '.join(f'{k} {v}' for k, v in feed.refused.items())}; "
            f"resyncs {feed.resyncs}; snapshots built {feed.snapshots_built}")


def url_host(host: str) -> str:
    """The host to print in the page's address: ``host`` itself, or for a wildcard address
    (``0.0.0.0``, ``::``: every interface) this machine's name when it resolves, else
    ``127.0.0.1``: an address a browser can open."""
    if host not in ("0.0.0.0", "::", ""):
        return host
    name = socket.gethostname()
    try:
        socket.getaddrinfo(name, None)
    except (OSError, UnicodeError):
        return "127.0.0.1"
    return name or "127.0.0.1"


def run(options: DashboardOptions) -> int:
    """Serve until interrupted. The first line on stdout is ``serving http://HOST:PORT/``
    (:func:`url_host`)."""
    replay = None
    if options.replay is not None:
        from .replay_source import open_replay  # noqa: PLC0415 - the bag library only for replays

        replay = open_replay(options.replay)
        source = Source("replay", replay.node, replay_dir=str(options.replay), reference=options.reference,
                        replay_file=replay.file)
    else:
        source = Source("live", options.node, reference=options.reference, **discovery_environment())
    sock = bind(options.server)
    port = sock.getsockname()[1]
    host = url_host(options.server.host)
    shown = f"[{host}]" if ":" in host else host
    print(f"serving http://{shown}:{port}/", flush=True)
    if options.server.token is not None:
        print(f"token required: open http://{shown}:{port}/?token={options.server.token}", flush=True)
    asyncio.run(_main(options, Hub(source), replay, sock))
    return 0
