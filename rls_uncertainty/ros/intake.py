"""The node's input subscriptions, kept off rclpy's executor, and the pass that takes all they hold.

rclpy's executor wakes, rebuilds its wait set and dispatches one callback per message (1,400
a second with a 1 kHz IMU), which cost the node more CPU than the estimation. The node instead
creates its five input subscriptions outside the executor's view and, once per intake period,
takes every message they hold, serialized, with the middleware's reception time
(:meth:`Intake.take`); it feeds them in order of arrival (:func:`..datapath.inputs.arrival_order`).

A pass feeds for at most a time budget (:class:`Backlog`): what it has not fed waits, in order,
for the next pass, and nothing new is taken until it is all fed. Between passes the executor
runs the periodic work (the diagnostics timer, state saves; each pass also runs one step of a
diagnostics round before it feeds), so a node with more input than it can process still
reports, and its memory stays bounded: messages that arrive meanwhile wait in the
subscriptions' queues (``qos.depth`` each), which drop the oldest when full.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Mapping
from typing import Any

from rclpy.event_handler import SubscriptionEventCallbacks
from rclpy.impl.implementation_singleton import rclpy_implementation as _rclpy
from rclpy.node import Node
from rclpy.qos import QoSProfile
from rclpy.subscription import Subscription
from rclpy.type_support import check_is_valid_msg_type

from ..datapath.inputs import arrival_order

__all__ = ["Intake", "Taken", "Backlog"]

# Per stream, ``(reception time ns, (reception time ns, serialized message))`` in queue order:
# the shape :func:`..datapath.inputs.arrival_order` merges (the time also rides with the message).
Taken = dict[str, list[tuple[int, tuple[int, bytes]]]]


def _unused(_msg: Any) -> None:
    """The subscriptions' callback: never called (the executor does not see them)."""


class Intake:
    """One subscription per input stream of ``node`` (``types`` and ``topics`` by stream), on
    the node's rcl handle (the ROS graph shows them as the node's), with no QoS-event handlers."""

    def __init__(self, node: Node, types: Mapping[str, type], topics: Mapping[str, str], qos: QoSProfile) -> None:
        self.types = types
        self.subs: dict[str, Subscription] = {}
        no_events = SubscriptionEventCallbacks(use_default_callbacks=False)
        for kind, msgtype in types.items():
            check_is_valid_msg_type(msgtype)  # loads the type support
            with node.handle:
                impl = _rclpy.Subscription(node.handle, msgtype, topics[kind], qos.get_c_qos_profile())
            self.subs[kind] = Subscription(impl, msgtype, topics[kind], _unused, node.default_callback_group, qos,
                                           True, no_events)
        self._handles = [(kind, sub.handle, types[kind]) for kind, sub in self.subs.items()]
        # Per stream, the takes that emptied a full queue since :meth:`full_queues` last read them:
        # the subscription held its ``qos.depth`` messages and dropped the oldest of any more.
        self.depth = qos.depth
        self._full: dict[str, int] = {}

    def take(self) -> Taken:
        """Every message the subscriptions hold now, per stream in queue order (reception time
        0 where the middleware gives none)."""
        taken: Taken = {}
        for kind, handle, msgtype in self._handles:
            queue: list[tuple[int, tuple[int, bytes]]] = []
            taken[kind], append = queue, queue.append
            with handle:
                take = handle.take_message
                while (msg_info := take(msgtype, True)) is not None:
                    t = msg_info[1]["received_timestamp"]
                    append((t, (t, msg_info[0])))
            if len(queue) >= self.depth:
                self._full[kind] = self._full.get(kind, 0) + 1
        return taken

    def full_queues(self) -> dict[str, int]:
        """Per stream, how many takes since the last call found its queue full (``qos.depth``
        messages: the middleware drops the oldest of any more, messages the node never sees);
        the counts restart."""
        full, self._full = self._full, {}
        return full

    def destroy(self) -> None:
        for sub in self.subs.values():
            sub.destroy()


class Backlog:
    """The messages of the last :meth:`Intake.take` not fed yet, ``(kind, (arrival ns, raw))``
    in order of arrival."""

    def __init__(self) -> None:
        # The queue itself: the node's feeding loop pops from it directly (one message at a time,
        # thousands a second).
        self.queue: deque[tuple[str, tuple[int, bytes]]] = deque()

    def __len__(self) -> int:
        return len(self.queue)

    def refill(self, taken: Taken) -> None:
        self.queue.extend(arrival_order(taken))

    def oldest(self, default: int) -> int:
        """The arrival time (ns) of the next message to feed (``default`` when unknown)."""
        t = self.queue[0][1][0] if self.queue else 0
        return t if t > 0 else default
