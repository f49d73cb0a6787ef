"""The dashboard's state and the messages it sends to the page (JSON over the websocket; the
protocol is in docs/dashboard.md). One :class:`Hub` per server, used from the server's event
loop only: the live subscriber and the replay reader hand it arrays, diagnostics and what the
ROS graph shows, and it answers with the messages to push. No ROS import, no web server.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass, field
from typing import Any

from .health import HealthTracker, StatusTuple, parse_statuses
from .model import ModelHistory, Pairing, Sample, array_update, sample_columns

__all__ = ["Source", "Hub"]


@dataclass(frozen=True)
class Source:
    """What the page is told about where the data comes from: ``mode`` ``live`` or
    ``replay``, the node's full name, and for live mode the ROS domain and discovery range
    (from the environment, as DDS reads them); for replay mode the directory."""

    mode: str
    node: str
    domain: str = ""
    discovery_range: str = ""
    static_peers: str = ""
    replay_dir: str = ""
    reference: Mapping[str, float] = field(default_factory=dict)


class Hub:
    """Pairs arrays into samples, keeps each model's history and the node's health, and
    builds the page's messages. ``clock`` gives wall time in ns (for the latency fields)."""

    def __init__(self, source: Source, clock: Callable[[], int] = time.time_ns, capacity: int | None = None) -> None:
        self.source = source
        self.pairing = Pairing()
        self.histories: dict[str, ModelHistory] = {}
        self.health = HealthTracker()
        self.node_present: bool | None = None  # None: not looked yet
        self.samples_total = 0
        self.history_resets = 0
        self._capacity = capacity
        self._clock = clock

    # ------------------------------------------------------------------ inputs
    def add_arrays(self, arrays: Iterable[tuple[str, str, Any, int | None]]) -> dict | None:
        """Feed ``(model, suffix, Float64MultiArray, published_ns)`` tuples (rclpy or rosbags
        messages); the ``samples`` message of the samples they completed (or None)."""
        done: dict[str, list[Sample]] = {}
        for model, suffix, msg, published_ns in arrays:
            try:
                update = array_update(model, suffix, msg, published_ns)
            except ValueError:
                self.pairing.count("bad_layout")
                continue
            s = self.pairing.add(update)
            if s is not None:
                self._store(s)
                done.setdefault(s.model, []).append(s)
        if not done:
            return None
        published = [s.published_ns for ss in done.values() for s in ss if s.published_ns is not None]
        return {"type": "samples", "models": {m: sample_columns(ss) for m, ss in done.items()},
                "published_ns": max(published) if published else None, "sent_ns": self._clock()}

    def _store(self, s: Sample) -> None:
        h = self.histories.get(s.model)
        if h is None or h.names != s.names or (h.last_stamp is not None and s.stamp_ns <= h.last_stamp):
            # A new model, another set of parameters, or time going back (a node reset, a
            # looped replay): the display history restarts for this model (the page does the
            # same when it sees the time go back).
            if h is not None:
                self.history_resets += 1
            h = self.histories[s.model] = (ModelHistory(s.names) if self._capacity is None
                                           else ModelHistory(s.names, self._capacity))
        h.append(s)
        self.samples_total += 1

    def add_diagnostics(self, statuses: Iterable[StatusTuple]) -> dict | None:
        """Feed one ``/diagnostics`` array; the ``health`` message when it held the node's report."""
        parsed = parse_statuses(statuses, self.source.node)
        if parsed is None:
            return None
        self.health.update(parsed)
        return self.status()

    def set_graph(self, node_present: bool) -> dict | None:
        """What discovery shows; the ``health`` message when it changed."""
        if node_present == self.node_present:
            return None
        self.node_present = node_present
        return self.status()

    # ------------------------------------------------------------------ page messages
    def hello(self) -> dict:
        s = self.source
        return {"type": "hello", "mode": s.mode, "node": s.node, "domain": s.domain,
                "discovery_range": s.discovery_range, "static_peers": s.static_peers,
                "replay_dir": s.replay_dir, "reference": dict(s.reference)}

    def snapshot(self) -> dict:
        return {"type": "snapshot", "models": {m: h.columns() for m, h in self.histories.items()}}

    def state(self) -> dict:
        """What the page says above the panels: ``no_node``, ``waiting_diagnostics``,
        ``no_samples``, ``running``, ``node_lost`` (samples were shown, the node is gone) or
        ``replay``, with the text that explains it."""
        s = self.source
        health = self.health.latest
        if s.mode == "replay":
            return {"state": "replay", "text": f"replay of {s.replay_dir}: {self.samples_total} samples"}
        peers = f", ROS_STATIC_PEERS={s.static_peers}" if s.static_peers else ""
        where = f"ROS_DOMAIN_ID={s.domain} (ROS_AUTOMATIC_DISCOVERY_RANGE={s.discovery_range}{peers})"
        if self.node_present is False and self.samples_total:
            return {"state": "node_lost", "text": f"Node {s.node} is no longer seen on {where}: the values shown are "
                                                  "its last ones."}
        if not self.node_present and not self.samples_total:
            text = (f"No node {s.node} seen on {where}. Start the estimator node with the same domain and discovery "
                    "range, or start this dashboard with the node's.")
            return {"state": "no_node", "text": text}
        if not self.samples_total:
            if health is None:
                return {"state": "waiting_diagnostics",
                        "text": f"Node {s.node} is running; no sample yet, waiting for its /diagnostics."}
            text = (f"Node {s.node} has published no sample yet: {health.samples_message}; "
                    f"inputs: {health.inputs_message}")
            not_ready = [f"{m}: {v.get('message', '')}" for m, v in health.models.items() if v.get("ready") != "True"]
            if not_ready:
                text += "; " + "; ".join(not_ready)
            return {"state": "no_samples", "text": text}
        return {"state": "running", "text": f"{s.node}: {self.samples_total} samples received"}

    def status(self) -> dict:
        health = self.health.latest
        return {"type": "health", **self.state(), "node_present": self.node_present,
                "health": health.as_json() if health is not None else None,
                "dropped": dict(self.pairing.dropped), "history_resets": self.history_resets}
