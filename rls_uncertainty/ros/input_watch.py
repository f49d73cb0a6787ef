"""Input topics that nobody publishes, said once in the node's log.

A typo in ``topics.imu`` (or in a remap) leaves the node subscribed to a topic that nothing
publishes: ``/diagnostics`` says "imu silent; no publisher matched on /imu_typo" each period,
and this line says it in the log, often the only thing read. :class:`SilentInputs` watches
the subscriptions of the streams the estimation needs (:func:`.pipeline.required_streams`:
an optional stream nobody publishes is expected) and says each one once when its
subscription has matched no publisher for ``diagnostics_window`` seconds (the node's
"recent" span, 10 s by default), but never less than :data:`MIN_SILENCE_S`, since the node
started or since its last publisher left; a publisher that comes re-arms it. The line names
the topic, the parameter, the message type and why: publishers on the topic whose QoS does
not match the subscription's (``qos.reliable``), or, when other topics of the same type have
publishers, those topics as the likely intended ones (docs/node.md, "Diagnostics", shows
it).

The node calls :meth:`SilentInputs.update` once per diagnostics period with the publisher
counts it already reads for ``/diagnostics``; the ROS graph is queried only for a line due.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

from ..datapath.inputs import MESSAGE_TYPES

__all__ = ["MIN_SILENCE_S", "SilentInputs", "silent_text"]

_SHOWN = 3  # candidate topics named at most
# The shortest silence said: a node discovers publishers already running within about 2 s on
# a loaded machine (0.5 to 2.1 s measured here at load average 5.5 on 2 cores), and a shorter
# diagnostics_window must not have it warn about every input at start-up.
MIN_SILENCE_S = 5.0


def silent_text(kind: str, topic: str, seconds: float, on_topic: int, reliable: bool,
                others: Sequence[tuple[str, int]]) -> str:
    """The line for stream ``kind`` subscribed on ``topic``: ``on_topic`` publishers on the
    topic itself (on the graph, not matched), ``others`` the (topic, publishers) of other
    topics of the stream's message type."""
    msg_type = MESSAGE_TYPES[kind]
    text = (f"no publisher on {topic} (topics.{kind}, {msg_type}) for {seconds:g} s: the estimation waits for "
            f"{kind}")
    if on_topic > 0:
        return f"{text}; {on_topic} publisher(s) on it do not match the subscription's QoS (qos.reliable={reliable})"
    if others:
        named = ", ".join(f"{t} has {n} publisher(s)" for t, n in others[:_SHOWN])
        more = f" (and {len(others) - _SHOWN} more topics)" if len(others) > _SHOWN else ""
        return f"{text}; {named}{more} of that type: is it the one meant (topics.{kind} or a remap)?"
    return f"{text}; no topic of that type has a publisher"


class SilentInputs:
    """Which required input subscriptions have matched no publisher for long enough, each
    said once per silence (module docstring)."""

    def __init__(self) -> None:
        self._since: dict[str, float] = {}  # stream -> steady time its silence began
        self._said: set[str] = set()

    def due(self, now_s: float, matched: Mapping[str, int], required: Sequence[str], seconds: float) -> list[str]:
        """The streams to say now, given each stream's matched publishers at ``now_s``, silent
        for ``seconds`` (at least :data:`MIN_SILENCE_S`)."""
        seconds = max(seconds, MIN_SILENCE_S)
        out = []
        for kind, count in matched.items():
            if count > 0 or kind not in required:
                self._since.pop(kind, None)
                self._said.discard(kind)
                continue
            since = self._since.setdefault(kind, now_s)
            if now_s - since >= seconds and kind not in self._said:
                self._said.add(kind)
                out.append(kind)
        return out

    def update(self, node: Any, now_s: float, matched: Mapping[str, int], topics: Mapping[str, str],
               required: Sequence[str], seconds: float, reliable: bool) -> list[str]:
        """The lines to log now (:meth:`due`), the graph of the rclpy ``node`` read for them."""
        due = self.due(now_s, matched, required, seconds)
        seconds = max(seconds, MIN_SILENCE_S)
        if not due:
            return []
        graph = node.get_topic_names_and_types()
        lines = []
        for kind in due:
            topic = topics[kind]
            others = [(t, n) for t, types in graph if t != topic and MESSAGE_TYPES[kind] in types
                      and (n := node.count_publishers(t)) > 0]
            lines.append(silent_text(kind, topic, seconds, node.count_publishers(topic), reliable, others))
        return lines
