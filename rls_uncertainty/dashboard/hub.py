"""The dashboard's state and the messages it sends to the page (JSON over the websocket; the
protocol is in docs/dashboard.md). One :class:`Hub` per server, used from the server's event
loop only: the live subscriber and the replay reader hand it arrays, diagnostics and what the
ROS graph shows, and it answers with the messages to push. No ROS import, no web server.

Everything estimated is kept per estimation method (:data:`.model.METHODS`: the time domain's
recursive least squares and the frequency domain's estimator) and model, so the two methods'
results sit side by side without mixing.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Iterable, Iterator, Mapping
from dataclasses import dataclass, field
from typing import Any

from ..datapath.display import RANGE_PAD, RANGE_QUANTILE, TRANSIENT_FRACTION, unit_table
from ..datapath.outputs import FIT_ARRAYS, ArrayKey
from ..ros.health import HealthTracker, StatusTuple, parse_statuses
from .fit import Fit, Identifiability, fit_of, identifiability_of, quality_json
from .flight import FlightHistory
from .messages import FRAME_VALUES, samples_messages, snapshot_messages
from .model import MAX_MODELS, MAX_PARAMETERS, MAX_PENDING, ModelHistory, Pairing, Sample, array_update, refusal

__all__ = ["Source", "Hub", "REFUSED"]

# Why a sample or array was refused, in the words of the page's banner and the log.
REFUSED = {
    "se_not_positive": "a standard error of 0 or less",
    "non_finite": "a value not finite",
    "time_out_of_range": "a time outside 1970-2262",
    "too_many_parameters": f"more than {MAX_PARAMETERS} parameters in a model",
    "too_many_models": f"more than {MAX_MODELS} models of a method",
}


@dataclass(frozen=True)
class Source:
    """What the page is told about where the data comes from: ``mode`` ``live`` or
    ``replay``, the node's full name, and for live mode the ROS domain and discovery range
    (from the environment, as DDS reads them); for replay mode the directory and the file
    read (``estimates.mcap``, or the CSV files: ``estimates.csv`` and/or
    ``estimates_frequency.csv``)."""

    mode: str
    node: str
    domain: str = ""
    discovery_range: str = ""
    static_peers: str = ""
    replay_dir: str = ""
    reference: Mapping[str, float] = field(default_factory=dict)
    replay_file: str = ""


class Hub:
    """Pairs arrays into samples, keeps each model's history and the node's health, and
    builds the page's messages. ``clock`` gives wall time in ns (for the latency fields)."""

    def __init__(self, source: Source, clock: Callable[[], int] = time.time_ns, capacity: int | None = None) -> None:
        self.source = source
        self.pairing = Pairing()
        self.histories: dict[tuple[str, str], ModelHistory] = {}  # by (method, model)
        self.fits: dict[tuple[str, str], Fit] = {}
        self.tables: dict[tuple[str, str], Identifiability] = {}
        self._quality_sent: dict[tuple[str, str], dict] = {}
        self.replay_done = False
        self.replay_error = ""
        self.health = HealthTracker()
        self.node_present: bool | None = None  # None: not looked yet
        # Whether discovery has ever shown the node: its samples can arrive before its name
        # does (a busy machine), which is not a node lost.
        self.node_seen = False
        self._samples_by: dict[tuple[str, str], int] = {}  # complete samples per (method, model)
        self._models: dict[str, set[str]] = {}  # by method: the models admitted (at most MAX_MODELS)
        self.refused: dict[str, int] = {}  # complete samples not shown, by reason (REFUSED)
        self.history_resets = 0
        self._node_resets: int | None = None  # the node's resets.<reason> counters' sum, last seen
        self._reset_pending = False
        self._capacity = capacity
        self._clock = clock
        self.flight = FlightHistory()  # the node's maneuver history (~/maneuvers)

    # ------------------------------------------------------------------ inputs
    def add_arrays(self, arrays: Iterable[tuple[ArrayKey, Any, int | None]]) -> list[dict]:
        """Feed ``(key, Float64MultiArray, published_ns)`` tuples (rclpy, rosbags or
        :mod:`...cdr` messages; None for a payload that could not be decoded); the messages of
        what they completed: ``samples`` per method, ``quality`` per model whose fit or
        identifiability came. Arrays of a model beyond the first :data:`.model.MAX_MODELS` of
        their method, or of more than :data:`.model.MAX_PARAMETERS` parameters, are dropped and
        counted before they are paired."""
        done: dict[tuple[str, str], list[Sample]] = {}
        changed: list[tuple[str, str]] = []
        for key, msg, published_ns in arrays:
            if msg is None:
                self.pairing.count("undecodable")
                continue
            if not self._admit_model(key.method, key.model):
                self.pairing.count("too_many_models")
                continue
            try:
                if key.suffix in FIT_ARRAYS:
                    changed.append(self._add_fit(key, msg))
                    continue
                update = array_update(key, msg, published_ns)
            except ValueError:
                self.pairing.count("bad_layout")
                continue
            if len(update.names) > MAX_PARAMETERS:
                self.pairing.count("too_many_parameters")
                continue
            s = self.pairing.add(update)
            if s is not None:
                self._collect(done, s)
        return self._samples_messages(done) + [self._quality(k) for k in dict.fromkeys(changed)]

    def add_samples(self, samples: Iterable[Sample]) -> list[dict]:
        """Feed complete samples (a replay's CSV files); their ``samples`` messages."""
        done: dict[tuple[str, str], list[Sample]] = {}
        for s in samples:
            if self._admit_model(s.method, s.model):
                self._collect(done, s)
            else:
                self._refuse("too_many_models")
        return self._samples_messages(done)

    def _collect(self, done: dict[tuple[str, str], list[Sample]], s: Sample) -> None:
        """Store ``s`` and list it among the samples to send; a restarted history sends only
        what came after the restart (the page restarts too)."""
        kept = self._store(s)
        if kept:
            run = done.setdefault((s.method, s.model), [])
            if kept == "restart":
                run.clear()
            run.append(s)

    def _admit_model(self, method: str, model: str) -> bool:
        models = self._models.setdefault(method, set())
        if model in models:
            return True
        if len(models) >= MAX_MODELS:
            return False
        models.add(model)
        return True

    def _refuse(self, reason: str) -> None:
        self.refused[reason] = self.refused.get(reason, 0) + 1

    def _samples_messages(self, done: Mapping[tuple[str, str], list[Sample]]) -> list[dict]:
        out = []
        for method in dict.fromkeys(m for m, _ in done):
            runs = [(model, ss, self._samples_by[(method, model)]) for (m, model), ss in done.items()
                    if m == method and ss]
            out.extend(samples_messages(method, runs, self._clock()))
        return out

    def _add_fit(self, key: ArrayKey, msg: Any) -> tuple[str, str]:
        """Keep the newest ``fit`` or ``identifiability`` of a model (ValueError: bad layout)."""
        which = (key.method, key.model)
        if key.suffix == "fit":
            self.fits[which] = fit_of(msg)
        else:
            table = identifiability_of(msg)
            if len(table.names) > MAX_PARAMETERS:
                raise ValueError(f"identifiability: {len(table.names)} parameters")
            self.tables[which] = table
        return which

    def _quality(self, which: tuple[str, str]) -> dict:
        method, model = which
        health = self.health.latest
        message = quality_json(method, model, self.fits.get(which), self.tables.get(which),
                               health.models.get(model) if health is not None else None)
        self._quality_sent[which] = message
        return message

    def quality_updates(self) -> list[dict]:
        """The ``quality`` messages that the newest ``/diagnostics`` changed (the node's text
        decides one case of :func:`.fit.reasons`)."""
        out = []
        for which, sent in list(self._quality_sent.items()):
            message = self._quality(which)
            if message != sent:
                out.append(message)
        return out

    def _store(self, s: Sample) -> str:
        """Keep ``s`` in its model's history: ``"kept"``, ``"restart"`` (its history started
        over with it), or ``""``: refused (:func:`.model.refusal`), or dropped as a sample
        completed after a newer one (a late partner array among the newest
        :data:`.model.MAX_PENDING` samples: a late joiner's burst of kept samples), or a
        duplicate; each counted."""
        reason = refusal(s)
        if reason:
            self._refuse(reason)
            return ""
        which = (s.method, s.model)
        h = self.histories.get(which)
        if h is not None and h.names == s.names and h.last_stamp is not None and s.stamp_ns <= h.last_stamp:
            floor = h.stamp_from_end(MAX_PENDING)
            if floor is not None and s.stamp_ns >= floor:
                self.pairing.count("out_of_order")
                return ""
        kept = "kept"
        if h is None or h.names != s.names or (h.last_stamp is not None and s.stamp_ns <= h.last_stamp):
            # A new model, another set of parameters, or time going back further than the
            # pairing window (a looped replay): the display history restarts for this model
            # (the page does the same when it sees the time go back).
            if h is not None:
                self.history_resets += 1
                kept = "restart"
            h = self.histories[which] = (ModelHistory(s.names) if self._capacity is None
                                         else ModelHistory(s.names, self._capacity))
        h.append(s)
        self._samples_by[which] = self._samples_by.get(which, 0) + 1
        return kept

    @property
    def samples_total(self) -> int:
        """Complete samples received, of every model and method."""
        return sum(self._samples_by.values())

    @property
    def samples_shown(self) -> int:
        """The node's samples the page has received: those of its model and method received
        most (every model and method of a sample is one sample, as the node counts them)."""
        return max(self._samples_by.values(), default=0)

    def add_maneuvers(self, text: str) -> dict | None:
        """Feed one ``~/maneuvers`` history (JSON text); the ``flight`` message when it changed
        what the page shows (:mod:`.flight`)."""
        return self.flight.update(text)

    def replay_finished(self, error: str = "") -> dict:
        """The replay file has been read (to its end, or up to ``error``); the ``health`` message."""
        self.replay_done, self.replay_error = True, error
        return self.status()

    def add_diagnostics(self, statuses: Iterable[StatusTuple]) -> dict | None:
        """Feed one ``/diagnostics`` array; the ``health`` message when it held the node's report."""
        parsed = parse_statuses(statuses, self.source.node)
        if parsed is None:
            return None
        resets = sum(int(v) for k, v in parsed.samples.items()
                     if (k.startswith("resets.") or k == "resets_other_count") and v.isdigit())
        if self._node_resets is not None and resets > self._node_resets:
            self._clear()
        self._node_resets = resets
        self.health.update(parsed)
        return self.status()

    def take_reset(self) -> bool:
        """Whether the node reset since this was last asked: the page then clears its panels."""
        reset, self._reset_pending = self._reset_pending, False
        return reset

    def _clear(self) -> None:
        """The node reset (its ``resets.<reason>`` counters grew): what it showed is gone, the
        display histories, fits and identifiability start over with its next samples."""
        self.histories.clear()
        self.fits.clear()
        self.tables.clear()
        self._quality_sent.clear()
        self.history_resets += 1
        self._reset_pending = True

    def set_graph(self, node_present: bool) -> dict | None:
        """What discovery shows; the ``health`` message when it changed."""
        if node_present == self.node_present:
            return None
        self.node_present = node_present
        self.node_seen = self.node_seen or node_present
        return self.status()

    # ------------------------------------------------------------------ page messages
    def hello(self) -> dict:
        s = self.source
        return {"type": "hello", "mode": s.mode, "node": s.node, "domain": s.domain,
                "discovery_range": s.discovery_range, "static_peers": s.static_peers,
                "replay_dir": s.replay_dir, "reference": dict(s.reference), "units": unit_table(),
                "range": {"quantile": RANGE_QUANTILE, "pad": RANGE_PAD, "transient": TRANSIENT_FRACTION}}

    def snapshot_messages(self, max_values: int = FRAME_VALUES) -> Iterator[dict]:
        """The page's state from scratch (:func:`.messages.snapshot_messages`): every method's
        display histories and every model's latest quality, in pieces."""
        yield from snapshot_messages(self.histories, self._samples_by, list(self._quality_sent.values()), max_values)
        if self.flight.message is not None:
            yield self.flight.message

    def counts(self) -> dict[str, dict[str, int]]:
        """Samples shown per method and model (the ``count`` of the ``samples`` messages)."""
        out: dict[str, dict[str, int]] = {}
        for (method, model), n in self._samples_by.items():
            out.setdefault(method, {})[model] = n
        return out

    def state(self) -> dict:
        """What the page says above the panels: ``no_node``, ``waiting_diagnostics``,
        ``no_samples``, ``running``, ``node_lost`` (samples were shown, the node is gone), or
        ``replay_reading``, ``replay`` (read to its end), ``replay_error``, with the text that
        explains it."""
        s = self.source
        health = self.health.latest
        if s.mode == "replay":
            state = "replay_error" if self.replay_error else "replay" if self.replay_done else "replay_reading"
            return {"state": state, "text": self._replay_text()}
        peers = f", ROS_STATIC_PEERS={s.static_peers}" if s.static_peers else ""
        where = f"ROS_DOMAIN_ID={s.domain} (ROS_AUTOMATIC_DISCOVERY_RANGE={s.discovery_range}{peers})"
        if self.node_present is False and self.node_seen and self.samples_total:
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
            used = health.samples.get("samples_used", "0")
            if used not in ("", "0"):  # it published before this dashboard joined
                return {"state": "no_samples",
                        "text": f"Node {s.node} has used {used} samples, none received here yet: its outputs do not "
                                "keep samples for late joiners (volatile), so the page starts with its next sample."}
            text = (f"Node {s.node} has published no sample yet: {health.samples_message}; "
                    f"inputs: {health.inputs_message}")
            not_ready = [f"{m}: {v.get('message', '')}" for m, v in health.models.items() if v.get("ready") != "True"]
            if not_ready:
                text += "; " + "; ".join(not_ready)
            return {"state": "no_samples", "text": text}
        return {"state": "running", "text": f"{s.node}: {self.samples_shown} samples received{self._refused_note()}"}

    def refused_text(self) -> str:
        """``N samples refused (REASON N, ...)``, or empty when none was."""
        if not self.refused:
            return ""
        total = sum(self.refused.values())
        reasons = ", ".join(f"{REFUSED.get(k, k)}: {n}" for k, n in sorted(self.refused.items()))
        return f"{total} sample{'s' if total != 1 else ''} refused, not drawn ({reasons})"

    def _refused_note(self) -> str:
        text = self.refused_text()
        return f"; {text}" if text else ""

    def _replay_text(self) -> str:
        s = self.source
        where = f"{s.replay_dir}/{s.replay_file}"
        if self.replay_error:
            return f"replay {where}: {self.samples_shown} samples{self._refused_note()}, then {self.replay_error}"
        if not self.replay_done:
            return f"reading replay {where}: {self.samples_shown} samples so far{self._refused_note()}"
        text = f"replay of {s.replay_dir}: {self.samples_shown} samples{self._refused_note()}"
        if s.replay_file.endswith(".csv"):
            text += (f" from {s.replay_file} (no estimates.mcap: no fit, identifiability or input health, which "
                     "rls-uncertainty replay writes into estimates.mcap)")
        return text

    def status(self) -> dict:
        health = self.health.latest
        return {"type": "health", **self.state(), "node_present": self.node_present,
                "health": health.as_json() if health is not None else None,
                "dropped": dict(self.pairing.dropped), "refused": dict(self.refused),
                "history_resets": self.history_resets}
