"""The node's output publishers, and which of them anyone listens to.

One publisher per topic of the configuration's :class:`..datapath.outputs.OutputLayout`
(``self.pubs[i]`` publishes topic ``i``), and per ``fit_topics`` entry. A sample's messages
are serialized by :mod:`..datapath.cdr` (byte-identical to rosbags' serialization and read
back by rclpy, checked in test_cdr.py) and published raw: converting 25 Python messages per
sample cost more CPU and latency than the estimation.

A topic nobody subscribes to is neither serialized nor published: :meth:`SamplePublishers.refresh`
reads each publisher's matched subscriptions from the graph cache (the node calls it once per
diagnostics period), and :meth:`SamplePublishers.publish` encodes only the topics that had a
subscriber then. A topic that gains its first subscriber gets the newest sample at that
refresh, so a display that joins while no sample is coming still receives it; from then on
its transient-local history fills as before. Only publication is skipped: the estimator runs
on every sample whoever listens.
"""

from __future__ import annotations

from typing import Any

from rclpy.event_handler import PublisherEventCallbacks
from rclpy.node import Node
from rclpy.qos import QoSProfile
from std_msgs.msg import Float64MultiArray, Header

from ..datapath.outputs import HEADER, OutputLayout
from ..datapath.sample_output import SampleOutput

__all__ = ["SamplePublishers"]


class SamplePublishers:
    """The publishers of ``node``'s sample topics (``qos``) and fit topics (``fit_qos``), with
    ``events`` as their QoS-event handlers."""

    def __init__(self, node: Node, qos: QoSProfile, fit_qos: QoSProfile, events: PublisherEventCallbacks) -> None:
        self._node, self._qos, self._fit_qos, self._events = node, qos, fit_qos, events
        self._by_topic: dict[str, Any] = {}
        self._fit_by_topic: dict[str, Any] = {}
        self.pubs: list[Any] = []
        self.fit_pubs: list[Any] = []
        self.layout: OutputLayout | None = None
        self._wanted: list[bool] = []  # per topic index: a subscriber was matched at the last refresh
        self._last: SampleOutput | None = None  # the newest sample, for a topic's first subscriber

    def follow(self, layout: OutputLayout) -> None:
        """Publishers for ``layout``'s topics, in its order: those of topics that remain are
        kept, those of topics no longer configured destroyed."""
        self.layout = layout
        self.pubs = self._remake(self._by_topic, layout.topics, self._qos)
        self.fit_pubs = self._remake(self._fit_by_topic, layout.fit_topics, self._fit_qos)
        self._last = None
        self._wanted = [p.get_subscription_count() > 0 for p in self.pubs]

    def _remake(self, by_topic: dict[str, Any], topics: list[tuple[str, str]], qos: QoSProfile) -> list[Any]:
        old, new = dict(by_topic), {}
        for topic, msgtype in topics:
            pub = old.pop(topic, None)
            if pub is None:
                pub = self._node.create_publisher(Header if msgtype == HEADER else Float64MultiArray, f"~/{topic}",
                                                  qos, event_callbacks=self._events)
            new[topic] = pub
        for pub in old.values():
            self._node.destroy_publisher(pub)
        by_topic.clear()
        by_topic.update(new)
        return [new[topic] for topic, _ in topics]

    def refresh(self, frame_id: str) -> None:
        """Re-read which topics have a subscriber; publish the newest sample on those that
        gained their first one."""
        wanted = [p.get_subscription_count() > 0 for p in self.pubs]
        gained = [now and not before for now, before in zip(wanted, self._wanted, strict=True)]
        self._wanted = wanted
        if self._last is not None and any(gained):
            self._send(self._last, frame_id, gained)

    @property
    def subscribed(self) -> int:
        """The sample topics that had a subscriber at the last refresh (those published)."""
        return sum(self._wanted)

    def publish(self, out: SampleOutput, frame_id: str) -> None:
        """A sample's messages (:meth:`.outputs.OutputLayout.encode`) on the topics with a
        subscriber, each on the publisher of its topic index."""
        self._last = out
        if any(self._wanted):
            self._send(out, frame_id, self._wanted)

    def _send(self, out: SampleOutput, frame_id: str, wanted: list[bool]) -> None:
        pubs = self.pubs
        for index, raw in self.layout.encode(out, frame_id, wanted):  # type: ignore[union-attr]
            pubs[index].publish(raw)

    def publish_fit(self, index: int, raw: bytes) -> None:
        self.fit_pubs[index].publish(raw)  # ~/M/fit, ~/M/identifiability
