"""The dashboard's live source: an rclpy node in its own context, executor and thread that
subscribes to a running estimator node's outputs, its maneuver history (``~/maneuvers``) and
``/diagnostics`` and hands what arrives
to the server's event loop (:class:`.server.Inbox`). It only reads: no publisher, no service
client, no parameter services.

Once a second it looks at the ROS graph: whether the node is there, and which
``<node>/<M>/<array>`` and ``<node>/<M>/frequency/<array>`` topics exist (a model's topics
appear when the node is configured with it, the frequency-domain ones with
``estimator.method`` ``frequency`` or ``both``; :func:`.model.array_key` says which are shown
and of which method), subscribing to each new one. The
subscription asks for the reliability and durability the node's publisher offers:
transient-local publishers (which keep their last samples for late joiners, so a dashboard
started after the node shows the latest values at once) are read with a transient-local
subscription, volatile ones with a volatile one (a transient-local subscription would not
match them).

CPU (docs/dashboard.md, measured with benchmarks/dashboard_benchmark.py): rclpy's executor
costs tens of microseconds per message, about 1,250 arrays a second with six models. The
arrays are taken serialized and decoded by :mod:`...cdr` (about 3 us where rclpy's generic
deserializer takes about 17 us); a payload that is not a ``Float64MultiArray`` is handed on as
None and counted.
"""

from __future__ import annotations

import contextlib
import os
import struct
import threading
from collections.abc import Callable
from typing import Any

import rclpy
from diagnostic_msgs.msg import DiagnosticArray
from rclpy.event_handler import SubscriptionEventCallbacks
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.qos import DurabilityPolicy, QoSHistoryPolicy, QoSProfile, ReliabilityPolicy
from rclpy.signals import SignalHandlerOptions
from std_msgs.msg import Float64MultiArray, String

from ..datapath.cdr import FLOAT64_MULTIARRAY, decode
from ..datapath.maneuvers import HISTORY_TOPIC
from ..datapath.outputs import ArrayKey, array_key
from ..ros.environment import split_node_name
from ..ros.health import statuses_of

__all__ = ["RosSource"]

GRAPH_PERIOD_S = 1.0
DEPTH = 50  # queue of each subscription of a volatile publisher (1 s of samples at 50 Hz)
DURABLE_DEPTH = 1000  # of a transient-local one: 20 s at 50 Hz, ten times the node's default qos.depth
# No QoS-event handlers on the subscriptions: rclpy's executor walks each one at every wait
# (about 20 us of the 80 us an array cost); the QoS asked for is the publisher's anyway.
_NO_EVENTS = SubscriptionEventCallbacks(use_default_callbacks=False)


class RosSource:
    """Subscribes to ``node``'s outputs; ``put`` receives, from the executor thread,
    ``("array", key, msg, published_ns)`` (:class:`.model.ArrayKey`; ``msg`` None when the
    payload could not be decoded), ``("diagnostics", statuses)``, ``("maneuvers", json_text)``
    (the node's ``~/maneuvers``) and ``("graph", node_present)``."""

    def __init__(self, node: str, put: Callable[[tuple], None]) -> None:
        self.node_name = node
        self._namespace, self._basename = split_node_name(node)
        self._put = put
        self.context = rclpy.Context()
        rclpy.init(context=self.context, signal_handler_options=SignalHandlerOptions.NO)
        self.node = rclpy.create_node(f"rls_dashboard_{os.getpid()}", context=self.context,
                                      start_parameter_services=False, enable_rosout=False)
        self._subs: dict[str, Any] = {}
        self.node.create_subscription(DiagnosticArray, "/diagnostics", self._on_diagnostics, 50,
                                      event_callbacks=_NO_EVENTS)
        # The maneuver history, latched by the node (reliable, transient local, depth 1).
        latched = QoSProfile(depth=1, history=QoSHistoryPolicy.KEEP_LAST, reliability=ReliabilityPolicy.RELIABLE,
                             durability=DurabilityPolicy.TRANSIENT_LOCAL)
        self.node.create_subscription(String, f"{node.rstrip('/')}/{HISTORY_TOPIC}",
                                      lambda msg: self._put(("maneuvers", getattr(msg, "data", ""))), latched,
                                      event_callbacks=_NO_EVENTS)
        self.node.create_timer(GRAPH_PERIOD_S, self._look)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        self._thread = threading.Thread(target=self._spin, name="rls_dashboard_ros", daemon=True)

    def start(self) -> None:
        self._thread.start()

    def _spin(self) -> None:
        self._look()
        with contextlib.suppress(ExternalShutdownException):
            self.executor.spin()

    def stop(self) -> None:
        self.executor.shutdown(timeout_sec=2.0)
        self.context.try_shutdown()
        self._thread.join(timeout=5.0)
        self.node.destroy_node()

    def _on_diagnostics(self, msg: DiagnosticArray) -> None:
        self._put(("diagnostics", statuses_of(msg)))

    def _look(self) -> None:
        """The 1 Hz look at the graph: is the node there, which of its arrays exist."""
        present = (self._basename, self._namespace) in self.node.get_node_names_and_namespaces()
        prefix = self.node_name.rstrip("/") + "/"
        for topic, _types in self.node.get_topic_names_and_types():
            if topic in self._subs or not topic.startswith(prefix):
                continue
            key = array_key(topic[len(prefix):])
            if key is not None:
                self._subscribe(topic, key)
        self._put(("graph", present))

    def _subscribe(self, topic: str, key: ArrayKey) -> None:
        infos = self.node.get_publishers_info_by_topic(topic)
        if not infos:
            return  # the publisher went away again; looked at next time
        durable = all(i.qos_profile.durability == DurabilityPolicy.TRANSIENT_LOCAL for i in infos)
        reliable = all(i.qos_profile.reliability == ReliabilityPolicy.RELIABLE for i in infos)
        # A late joiner takes the samples the node kept at once (discovery does not tell their
        # number): up to DURABLE_DEPTH, so that each array's queue keeps the same window and
        # the arrays of a sample find their partners.
        qos = QoSProfile(depth=DURABLE_DEPTH if durable else DEPTH, history=QoSHistoryPolicy.KEEP_LAST,
                         reliability=ReliabilityPolicy.RELIABLE if reliable else ReliabilityPolicy.BEST_EFFORT,
                         durability=DurabilityPolicy.TRANSIENT_LOCAL if durable else DurabilityPolicy.VOLATILE)
        put = self._put

        def on_array(raw: bytes, info: Any) -> None:
            published = info.get("source_timestamp") if isinstance(info, dict) else getattr(info, "source_timestamp",
                                                                                             None)
            try:
                msg = decode(FLOAT64_MULTIARRAY, raw)
            except struct.error:
                msg = None
            put(("array", key, msg, published))

        # rclpy passes the message info (source timestamp) to a callback of two parameters;
        # raw=True hands over the serialized bytes.
        self._subs[topic] = self.node.create_subscription(Float64MultiArray, topic, on_array, qos,  # type: ignore[arg-type]
                                                          raw=True, event_callbacks=_NO_EVENTS)
