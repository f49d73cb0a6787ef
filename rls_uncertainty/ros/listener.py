"""The estimator node's outputs heard in another process (the demo's and the testing plugin's
listeners): subscriptions to its sample stamps and its vector outputs, and its newest
``/diagnostics`` report, on an rclpy node of the listener's; whether discovery matched both
ends of every output (:meth:`OutputListener.discovered`). What is kept of a stamp or an array
is the subclass's choice. rclpy is imported when a listener is made, not with this module."""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Mapping, Sequence
from functools import partial
from typing import TYPE_CHECKING, Any

from ..datapath.diagnostics import outputs_discovered, outputs_subscribed, status_prefix
from ..datapath.inputs import message_class
from ..datapath.outputs import SAMPLE_STAMP
from .health import statuses_of

if TYPE_CHECKING:
    from rclpy.node import Node

__all__ = ["OutputListener"]


class OutputListener(ABC):
    """Subscriptions on ``node`` to the sample stamps of the estimator node ``node_name`` (its
    fully qualified name; ``subs[0]``) and to the arrays ``kinds`` of each of ``models``
    (reliable, ``depth`` deep), and to ``/diagnostics``: ``diagnostics`` holds the statuses of
    the newest array that has one of that node's, ``reports`` counts those arrays."""

    def __init__(self, node: Node, node_name: str, models: Sequence[str], kinds: Sequence[str], depth: int) -> None:
        from rclpy.qos import QoSHistoryPolicy, QoSProfile, QoSReliabilityPolicy  # noqa: PLC0415

        self.prefix = f"{status_prefix(node_name)}: "
        self.diagnostics: list[tuple[str, int, str, dict[str, str]]] = []
        self.reports = 0
        qos = QoSProfile(depth=depth, reliability=QoSReliabilityPolicy.RELIABLE, history=QoSHistoryPolicy.KEEP_LAST)
        self.subs = [node.create_subscription(message_class("std_msgs/msg/Header"), f"{node_name}/{SAMPLE_STAMP}",
                                              self._stamp, qos)]
        array_type = message_class("std_msgs/msg/Float64MultiArray")
        for model in models:
            for kind in kinds:
                self.subs.append(node.create_subscription(array_type, f"{node_name}/{model}/{kind}",
                                                          partial(self._array, model, kind), qos))
        self.diag_sub = node.create_subscription(message_class("diagnostic_msgs/msg/DiagnosticArray"),
                                                 "/diagnostics", self._diagnostics, 10)

    @abstractmethod
    def _stamp(self, msg: Any) -> None:
        """A ``std_msgs/Header`` from the node's sample stamp topic."""

    @abstractmethod
    def _array(self, model: str, kind: str, msg: Any) -> None:
        """A ``std_msgs/Float64MultiArray`` from the node's ``model``'s ``kind`` topic."""

    def _diagnostics(self, msg: Any) -> None:
        statuses = statuses_of(msg)
        if any(name.startswith(self.prefix) for name, *_ in statuses):
            self.diagnostics = statuses
            self.reports += 1

    def values(self, status: str) -> Mapping[str, str]:
        """The key-values of the node's newest ``status`` (``samples``, ``inputs``; empty: none)."""
        return next((kv for name, _l, _m, kv in self.diagnostics if name == self.prefix + status), {})

    def matched(self) -> int:
        """The subscriptions that matched the node's publisher (this side's view)."""
        return sum(s.get_publisher_count() >= 1 for s in self.subs)

    def subscribed(self) -> int:
        """How many sample topics the node's newest report says it publishes on (the ones its
        publishers matched a subscriber on; -1: not said)."""
        return outputs_subscribed(self.values("samples"))

    def discovered(self) -> bool:
        """Discovery matched both ends of every output (:func:`..diagnostics.outputs_discovered`):
        these subscriptions matched the node's publishers, and the node's newest report says it
        publishes on as many sample topics."""
        return outputs_discovered(self.values("samples"), self.matched(), len(self.subs))
