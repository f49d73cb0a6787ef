"""``rls-uncertainty play BAG``: publish a replay bag over DDS with ``/clock``.

rosbag2's player is not installable here; this one publishes each message's recorded CDR
bytes unchanged on its topic at the bag's pace (times a rate factor), and ``/clock`` at every
message's log time so a node with ``use_sim_time`` follows the bag. Reliable QoS by default:
an integration test against the live node must not lose messages.
"""

from __future__ import annotations

import importlib
import os
import sys
import time
from pathlib import Path

__all__ = ["play"]


def _message_class(msgtype: str):
    pkg, _msg, name = msgtype.split("/")
    return getattr(importlib.import_module(f"{pkg}.msg"), name)


def play(bag: str | Path, *, rate: float = 1.0, clock: bool = True, reliable: bool = True,
         wait_for_subscribers: int = 0, start_delay: float = 0.5, wait_timeout: float = 30.0,
         depth: int = 1000) -> int:
    """Publish ``bag``; ``rate`` is the speed factor (0 = as fast as possible). Waits for
    ``wait_for_subscribers`` subscribers on every topic first. Returns a process exit code."""
    os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    import rclpy  # noqa: PLC0415
    from rclpy.qos import QoSHistoryPolicy, QoSProfile, QoSReliabilityPolicy  # noqa: PLC0415
    from rosgraph_msgs.msg import Clock  # noqa: PLC0415

    from .bags import BagError, _open_reader, typestore  # noqa: PLC0415

    if rate < 0:
        raise ValueError(f"rate must be >= 0, got {rate}")
    path = Path(bag)
    reader = _open_reader(path, typestore())
    rclpy.init()
    node = rclpy.create_node("rls_player")
    try:
        qos = QoSProfile(depth=depth, history=QoSHistoryPolicy.KEEP_LAST,
                         reliability=QoSReliabilityPolicy.RELIABLE if reliable else QoSReliabilityPolicy.BEST_EFFORT)
        pubs = {}
        for conn in reader.connections:
            try:
                cls = _message_class(conn.msgtype)
            except (ImportError, AttributeError, ValueError) as exc:
                raise BagError(f"{path}: topic {conn.topic}: type {conn.msgtype} is not available in this ROS install") from exc
            pubs[conn.topic] = node.create_publisher(cls, conn.topic, qos)
        clock_pub = node.create_publisher(Clock, "/clock", 10) if clock else None
        deadline = time.monotonic() + wait_timeout
        while wait_for_subscribers and any(p.get_subscription_count() < wait_for_subscribers for p in pubs.values()):
            if time.monotonic() > deadline:
                missing = [t for t, p in pubs.items() if p.get_subscription_count() < wait_for_subscribers]
                raise BagError(f"{path}: no subscriber on {missing} after {wait_timeout:g} s")
            time.sleep(0.05)
        time.sleep(start_delay)
        t_wall0 = time.monotonic()
        t_bag0 = None
        count = 0
        clock_msg = Clock()
        for conn, t, raw in reader.messages():
            if t_bag0 is None:
                t_bag0 = t
            if rate > 0:
                delay = t_wall0 + (t - t_bag0) * 1e-9 / rate - time.monotonic()
                if delay > 0:
                    time.sleep(delay)
            if clock_pub is not None:
                clock_msg.clock.sec, clock_msg.clock.nanosec = divmod(t, 1_000_000_000)
                clock_pub.publish(clock_msg)
            pubs[conn.topic].publish(bytes(raw))
            count += 1
        time.sleep(0.5)  # let reliable delivery finish before the publishers go away
        print(f"published {count} messages from {path} in {time.monotonic() - t_wall0:.2f} s", file=sys.stderr)
        return 0
    finally:
        reader.close()
        node.destroy_node()
        rclpy.try_shutdown()
