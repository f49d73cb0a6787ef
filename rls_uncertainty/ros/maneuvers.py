"""The node's maneuvers: the test-point event subscription, the latched history topic, the status.

With ``maneuvers.source`` other than ``off`` the node keeps one
:class:`..datapath.maneuvers.ManeuverTracker` over its pipeline (its rules are there). This
adapter only subscribes, decodes and publishes:

* with ``detect``, each control-surface message goes to the detector before the pipeline, as
  in the replay;
* ``maneuvers.topic`` (``events``): ``diagnostic_msgs/msg/KeyValue`` (``key`` the test point,
  ``value`` ``start``/``stop``), subscribed outside the executor like the inputs
  (:class:`.intake.Intake`, reliable, 100 deep) and taken in the same batches, so each event is
  acted on in order of arrival among the input messages, placed in data time
  (:meth:`.ManeuverTracker.event`: the newest sample's stamp), as the replay places it.
* ``~/maneuvers``: ``std_msgs/msg/String`` holding JSON, reliable and transient local with
  depth 1 (a late subscriber gets the current history at once), published at start and after
  each maneuver's end (:func:`..datapath.maneuvers.history_json`).
* one ``/diagnostics`` status, ``rls_estimator: maneuvers`` (:meth:`ManeuverTracker.summary`).
"""

from __future__ import annotations

from typing import Any

from diagnostic_msgs.msg import KeyValue
from rclpy.node import Node
from rclpy.qos import QoSDurabilityPolicy, QoSHistoryPolicy, QoSProfile, QoSReliabilityPolicy
from rclpy.serialization import deserialize_message
from std_msgs.msg import String

from ..datapath.diagnostics import Status, status_prefix
from ..datapath.maneuvers import EVENT, HISTORY_TOPIC, ManeuverTracker, history_json, history_key
from ..datapath.pipeline import Pipeline, SampleOutput
from .intake import Intake, Taken

__all__ = ["LiveManeuvers", "history_json"]

OK = 0  # DiagnosticStatus.OK


class LiveManeuvers:
    """The tracker of ``pipeline`` and its ROS ends on ``node`` (module docstring)."""

    def __init__(self, node: Node, pipeline: Pipeline) -> None:
        self.node = node
        options = pipeline.config.maneuvers
        self.tracker = ManeuverTracker(pipeline, options)
        events = QoSProfile(depth=100, reliability=QoSReliabilityPolicy.RELIABLE, history=QoSHistoryPolicy.KEEP_LAST)
        self.intake = Intake(node, {EVENT: KeyValue}, {EVENT: options.topic}, events) \
            if options.source == "events" else None
        latched = QoSProfile(depth=1, reliability=QoSReliabilityPolicy.RELIABLE, history=QoSHistoryPolicy.KEEP_LAST,
                             durability=QoSDurabilityPolicy.TRANSIENT_LOCAL)
        self._pub = node.create_publisher(String, f"~/{HISTORY_TOPIC}", latched)
        self._published: object = None
        self.publish()

    def take(self) -> Taken:
        """The event messages held now (none with ``detect``)."""
        return self.intake.take() if self.intake is not None else {}

    def event(self, raw: bytes) -> None:
        """One serialized event, acted on at the node's clock; a message that does not decode
        is rejected as ``undecodable``."""
        now = self.node.get_clock().now().nanoseconds
        try:
            msg = deserialize_message(raw, KeyValue)
        except Exception:  # noqa: BLE001 - a bad message is counted, never raised
            self.tracker.reject("undecodable")
            self.publish()
            return
        self.tracker.event(now, msg.key, msg.value)
        self.publish()

    def surfaces(self, msg: Any) -> None:
        """A decoded control-surface message for the detector (``detect``; else nothing)."""
        if self.tracker.detector is not None:
            s = msg.header.stamp
            self.tracker.surfaces(int(s.sec) * 1_000_000_000 + int(s.nanosec), list(msg.position))

    def sample(self, out: SampleOutput) -> None:
        self.tracker.sample(out)

    def follow(self, pipeline: Pipeline) -> None:
        """The node reconfigured its pipeline: a running maneuver goes on with the new one."""
        self.tracker.follow(pipeline)

    def publish(self) -> None:
        """``~/maneuvers`` when the history or the running maneuver changed."""
        key = history_key(self.tracker)
        if key != self._published:
            self._published = key
            self._pub.publish(String(data=history_json(self.tracker)))

    def status(self, name: str) -> Status:
        """The ``/diagnostics`` status (level OK: a rejected event is counted and said in the
        message, the estimates are not affected)."""
        values: dict[str, Any] = self.tracker.summary()
        running = values["maneuvers.active"]
        message = f"maneuver {running} running" if running != "-" else "between maneuvers"
        message += f"; {values['maneuvers.recorded']} recorded"
        if values["maneuvers.events_rejected"]:
            message += f", {values['maneuvers.events_rejected']} events rejected"
        prefix = status_prefix(name)
        return Status(f"{prefix}: maneuvers", OK, message, tuple((k, str(v)) for k, v in values.items()),
                      hardware_id=prefix)

    def destroy(self) -> None:
        if self.intake is not None:
            self.intake.destroy()
