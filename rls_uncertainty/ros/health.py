"""The node's ``/diagnostics`` read back for display: input streams, samples and model fit
(:mod:`..diagnostics` writes them; its docstring and docs/node.md "Diagnostics" list the keys). Used
by the dashboard and by ``rls-uncertainty status``. No ROS import: a status is handed in as
``(name, level, message, {key: value})``.

Recent rejections by reason. The node reports, per stream, the cumulative
``rejected.<reason>`` counts and the recent total ``recent.rejected`` over its
``recent_window_s``. :class:`HealthTracker` keeps the cumulative counts of earlier reports and
gives per reason the increase over the same window, so an operator sees *which* reasons are
recent, not only how many.
"""

from __future__ import annotations

import time
from collections import deque
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass, field
from typing import Any

from ..datapath.diagnostics import status_prefix

__all__ = ["statuses_of", "StatusTuple", "StreamHealth", "NodeHealth", "parse_statuses", "HealthTracker", "LEVELS"]

# (name, level 0..3, message, key-values) of one diagnostic_msgs/DiagnosticStatus.
StatusTuple = tuple[str, int, str, Mapping[str, str]]
LEVELS = {0: "OK", 1: "WARN", 2: "ERROR", 3: "STALE"}
_STREAM_FIELDS = ("required", "publishers", "rate_hz", "age_s", "received", "accepted", "expired", "missing",
                  "recent.rejected", "recent.missing", "recent.expired")


@dataclass(frozen=True)
class StreamHealth:
    """One input stream as the node reports it (values as the node wrote them) plus its
    cumulative rejections by reason and those of the recent window."""

    name: str
    values: Mapping[str, str]
    rejected: Mapping[str, int]
    recent_reasons: Mapping[str, int] = field(default_factory=dict)

    def get(self, key: str, default: str = "") -> str:
        return self.values.get(key, default)


@dataclass(frozen=True)
class NodeHealth:
    """One ``/diagnostics`` report of the node: levels and messages of its ``inputs`` and
    ``samples`` statuses, the streams, the samples' key-values and each model's key-values
    (with ``level`` and ``message``)."""

    inputs_level: int
    inputs_message: str
    window_s: float
    streams: tuple[StreamHealth, ...]
    samples_message: str
    samples: Mapping[str, str]
    models: Mapping[str, Mapping[str, str]]

    def as_json(self) -> dict:
        return {
            "inputs": {"level": self.inputs_level, "message": self.inputs_message, "window_s": self.window_s,
                       "streams": [{"name": s.name, **s.values, "rejected": dict(s.rejected),
                                    "recent_reasons": dict(s.recent_reasons)} for s in self.streams]},
            "samples": {"message": self.samples_message, **self.samples},
            "models": {m: dict(v) for m, v in self.models.items()},
        }


def _level(level: Any) -> int:
    return int.from_bytes(level, "little") if isinstance(level, bytes) else int(level)


def statuses_of(msg: Any) -> list[tuple[str, int, str, dict[str, str]]]:
    """A ``diagnostic_msgs/DiagnosticArray`` (rclpy's or rosbags': read by field name) as
    status tuples."""
    return [(s.name, _level(s.level), s.message, {kv.key: kv.value for kv in s.values}) for s in msg.status]


def _int(text: str) -> int:
    try:
        return int(text)
    except ValueError:
        return 0


def _streams(values: Mapping[str, str]) -> tuple[StreamHealth, ...]:
    fields: dict[str, dict[str, str]] = {}
    rejected: dict[str, dict[str, int]] = {}
    for key, value in values.items():
        stream, dot, rest = key.partition(".")
        if not dot:
            continue
        if rest.startswith(("rejected.", "rejected_other_")):
            reason = rest.partition(".")[2] if rest.startswith("rejected.") else rest
            if rest == "rejected_other_reasons":
                continue  # the number of reasons not shown, not a count of messages
            rejected.setdefault(stream, {})[reason] = _int(value)
        elif rest in _STREAM_FIELDS:
            fields.setdefault(stream, {})[rest] = value
    return tuple(StreamHealth(name, fields[name], rejected.get(name, {})) for name in fields)


def parse_statuses(statuses: Iterable[StatusTuple], node: str) -> NodeHealth | None:
    """The report of ``node`` (its fully qualified name) among ``statuses``: those named
    ``"<prefix>: ..."`` (:func:`..diagnostics.status_prefix`: the bare name in the root
    namespace, the full name under one), or None when the array holds no ``inputs`` status of
    that node."""
    prefix = f"{status_prefix(node)}: "
    inputs = samples = None
    models: dict[str, dict[str, str]] = {}
    for name, level, message, values in statuses:
        if not name.startswith(prefix):
            continue
        what = name[len(prefix):]
        if what == "inputs":
            inputs = (level, message, dict(values))
        elif what == "samples":
            samples = (message, dict(values))
        elif what.startswith("model "):
            models[what[6:]] = {**values, "level": str(level), "message": message}
    if inputs is None:
        return None
    level, message, values = inputs
    try:
        window = float(values.get("recent_window_s", "nan"))
    except ValueError:
        window = float("nan")
    samples_message, samples_values = samples if samples is not None else ("", {})
    return NodeHealth(level, message, window, _streams(values), samples_message, samples_values, models)


class HealthTracker:
    """Per-reason recent rejections from successive reports (see the module docstring). The
    window is the node's ``recent_window_s``; history is bounded to the reports inside it."""

    def __init__(self, clock: Callable[[], float] = time.monotonic, max_reports: int = 3600) -> None:
        self._clock = clock
        self._history: deque[tuple[float, dict[str, dict[str, int]], dict[str, dict[str, int]]]] = deque(
            maxlen=max_reports)
        self.latest: NodeHealth | None = None
        self.received_at: float | None = None

    def update(self, health: NodeHealth) -> NodeHealth:
        now = self._clock()
        window = health.window_s if health.window_s > 0 else 10.0  # NaN compares false
        history = self._history
        while len(history) > 1 and history[1][0] <= now - window:
            history.popleft()
        # The baseline is the newest report at least a window old. While none is (the first
        # window after the dashboard started), it is the oldest report, whose own recent
        # reasons still count; before any report, the node's recent count decides.
        base = history[0] if history else None
        streams = []
        for s in health.streams:
            recent_total = _int(s.get("recent.rejected", "0"))
            if recent_total == 0:
                recent: dict[str, int] = {}
            elif base is None:
                recent = dict(s.rejected)
            else:
                base_time, totals, base_recent = base
                before = totals.get(s.name, {})
                recent = dict(base_recent.get(s.name, {})) if base_time > now - window else {}
                for reason, n in s.rejected.items():
                    if n > before.get(reason, 0):
                        recent[reason] = recent.get(reason, 0) + n - before.get(reason, 0)
            streams.append(StreamHealth(s.name, s.values, s.rejected, recent))
        history.append((now, {s.name: dict(s.rejected) for s in streams},
                        {s.name: dict(s.recent_reasons) for s in streams}))
        self.latest = NodeHealth(health.inputs_level, health.inputs_message, health.window_s, tuple(streams),
                                 health.samples_message, health.samples, health.models)
        self.received_at = now
        return self.latest
