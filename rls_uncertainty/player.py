"""DDS playback of replay bags, and the live demo.

``rls-uncertainty play BAG`` publishes each message's recorded CDR bytes unchanged on its
topic at the bag's pace (times a rate factor), and ``/clock`` at every message's log time so
a node with ``use_sim_time`` follows the bag (rosbag2's player is not installable here).
Reliable QoS by default: an integration test against the live node must not lose messages.

``rls-uncertainty demo`` starts the estimator node in its own process, plays the bundled
T-2 bag to it over DDS, listens to its outputs and prints the final estimates beside the
offline replay of the same bag.
"""

from __future__ import annotations

import math
import os
import subprocess
import sys
import time
from pathlib import Path

from .errors import BagError, ConfigError
from .messages import ARRAY_OUTPUTS, NODE_NAME, message_class

__all__ = ["play", "demo", "bundled_bag"]


def _loopback_default() -> None:
    # DDS discovery stays on this machine unless the caller chose otherwise.
    os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")


class _Publisher:
    """Publishers for every topic of a bag (and /clock) on an existing rclpy node."""

    def __init__(self, node, bag: Path, *, clock: bool, reliable: bool, depth: int = 1000) -> None:
        from rclpy.qos import QoSHistoryPolicy, QoSProfile, QoSReliabilityPolicy  # noqa: PLC0415

        from .bags import _open_reader, typestore  # noqa: PLC0415

        self.path = Path(bag)
        self.reader = _open_reader(self.path, typestore())
        qos = QoSProfile(depth=depth, history=QoSHistoryPolicy.KEEP_LAST,
                         reliability=QoSReliabilityPolicy.RELIABLE if reliable else QoSReliabilityPolicy.BEST_EFFORT)
        self.pubs = {}
        for conn in self.reader.connections:
            try:
                cls = message_class(conn.msgtype)
            except (ImportError, AttributeError, ValueError) as exc:
                self.reader.close()
                raise BagError(f"{self.path}: topic {conn.topic}: type {conn.msgtype} is not available in this "
                               "ROS install") from exc
            self.pubs[conn.topic] = node.create_publisher(cls, conn.topic, qos)
        clock_type = message_class("rosgraph_msgs/msg/Clock")
        self.clock_pub = node.create_publisher(clock_type, "/clock", 10) if clock else None
        self._clock = clock_type()

    def wait_for_subscribers(self, n: int, timeout: float, spin=None) -> None:
        deadline = time.monotonic() + timeout
        while n and any(p.get_subscription_count() < n for p in self.pubs.values()):
            if time.monotonic() > deadline:
                missing = [t for t, p in self.pubs.items() if p.get_subscription_count() < n]
                raise BagError(f"{self.path}: no subscriber on {missing} after {timeout:g} s")
            spin() if spin else time.sleep(0.05)

    def run(self, rate: float, spin=None) -> int:
        """Publish every message; ``spin`` is called between messages when given."""
        t_wall0, t_bag0, count = time.monotonic(), None, 0
        for conn, t, raw in self.reader.messages():
            if t_bag0 is None:
                t_bag0 = t
            if rate > 0:
                delay = t_wall0 + (t - t_bag0) * 1e-9 / rate - time.monotonic()
                if delay > 0:
                    time.sleep(delay)
            if self.clock_pub is not None:
                self._clock.clock.sec, self._clock.clock.nanosec = divmod(t, 1_000_000_000)
                self.clock_pub.publish(self._clock)
            self.pubs[conn.topic].publish(bytes(raw))
            count += 1
            if spin is not None and count % 50 == 0:
                spin()
        return count

    def close(self) -> None:
        self.reader.close()


def _check_rate(rate: float) -> None:
    if not (math.isfinite(rate) and rate >= 0):
        raise ConfigError(f"rate must be a finite number >= 0 (0 = as fast as possible), got {rate!r}")


def play(bag: str | Path, *, rate: float = 1.0, clock: bool = True, reliable: bool = True,
         wait_for_subscribers: int = 0, start_delay: float = 0.5, wait_timeout: float = 30.0) -> int:
    """Publish ``bag``; ``rate`` is the speed factor (0 = as fast as possible). Waits for
    ``wait_for_subscribers`` subscribers on every topic first. Returns a process exit code."""
    _check_rate(rate)
    if not (isinstance(wait_for_subscribers, int) and wait_for_subscribers >= 0):
        raise ConfigError(f"the number of subscribers to wait for must be an integer >= 0, got {wait_for_subscribers!r}")
    for name, value in (("start delay", start_delay), ("wait timeout", wait_timeout)):
        if not (math.isfinite(value) and value >= 0):
            raise ConfigError(f"{name} must be a finite number of seconds >= 0, got {value!r}")
    _loopback_default()
    import rclpy  # noqa: PLC0415

    rclpy.init()
    node = rclpy.create_node("rls_player")
    player = None
    try:
        player = _Publisher(node, Path(bag), clock=clock, reliable=reliable)
        player.wait_for_subscribers(wait_for_subscribers, wait_timeout)
        time.sleep(start_delay)
        t0 = time.monotonic()
        count = player.run(rate)
        time.sleep(0.5)  # let reliable delivery finish before the publishers go away
        print(f"published {count} messages from {bag} in {time.monotonic() - t0:.2f} s", file=sys.stderr)
        return 0
    finally:
        if player is not None:
            player.close()
        node.destroy_node()
        rclpy.try_shutdown()


def bundled_bag() -> Path:
    """``bags/t2_maneuver`` in the source tree or the ROS install's share directory."""
    from .config import package_path  # noqa: PLC0415

    return package_path("bags", "t2_maneuver")


# Input queue depth for the node in a reliable replay: deeper than any topic of the bundled
# bag, so a node that falls behind (a busy machine) delays messages instead of overwriting them.
_REPLAY_DEPTH = 10_000


def demo(rate: float = 4.0, params_file: str = "t2") -> int:
    """The live node on the bundled bag: estimates over DDS beside the offline replay."""
    _check_rate(rate)
    _loopback_default()
    import numpy as np  # noqa: PLC0415
    import rclpy  # noqa: PLC0415
    from rclpy.qos import QoSHistoryPolicy, QoSProfile, QoSReliabilityPolicy  # noqa: PLC0415

    from .bags import read_inputs  # noqa: PLC0415
    from .config import config_dir, load_parameters_file, pipeline_config  # noqa: PLC0415
    from .replay import run_pipeline  # noqa: PLC0415
    from .report import results_table, rows_from_arrays  # noqa: PLC0415
    from .simulation import T2_TRUE  # noqa: PLC0415

    bag = bundled_bag()
    params_path = str(config_dir() / f"{params_file}.yaml")
    params = load_parameters_file(params_path)
    config = pipeline_config(params)
    print(f"starting the estimator node ({params_path}) and playing {bag} over DDS at {rate:g}x ...")
    import tempfile  # noqa: PLC0415

    node_log = tempfile.NamedTemporaryFile("w+", prefix="rls_demo_node_", suffix=".log", delete=False)
    node_proc = subprocess.Popen(
        [sys.executable, "-m", "rls_uncertainty.node", "--ros-args", "--params-file", params_path,
         "-p", "qos.reliable:=true", "-p", f"qos.depth:={_REPLAY_DEPTH}"], stdout=node_log, stderr=subprocess.STDOUT, text=True,
    )
    rclpy.init()
    node = rclpy.create_node("rls_demo")
    latest: dict[str, object] = {}
    counts = {"samples": 0}
    qos = QoSProfile(depth=1000, reliability=QoSReliabilityPolicy.RELIABLE, history=QoSHistoryPolicy.KEEP_LAST)
    subs = [node.create_subscription(message_class("std_msgs/msg/Header"), f"/{NODE_NAME}/sample_stamp",
                                     lambda m: counts.__setitem__("samples", counts["samples"] + 1), qos)]
    array_type = message_class("std_msgs/msg/Float64MultiArray")
    for m in config.models:
        for suffix in ARRAY_OUTPUTS:
            topic = f"/{NODE_NAME}/{m.output}/{suffix}"
            subs.append(node.create_subscription(array_type, topic,
                                                 lambda msg, t=topic: latest.__setitem__(t, msg), qos))
    player = None
    try:
        player = _Publisher(node, bag, clock=False, reliable=True)
        spin = lambda: rclpy.spin_once(node, timeout_sec=0.01)  # noqa: E731
        player.wait_for_subscribers(1, 30.0, spin)
        deadline = time.monotonic() + 30
        while any(s.get_publisher_count() < 1 for s in subs) and time.monotonic() < deadline:
            spin()
        end = time.monotonic() + 1.0  # discovery is not symmetric: let both sides match
        while time.monotonic() < end:
            spin()
        player.run(rate, spin)
        offline = run_pipeline(read_inputs(bag)[0], config)
        want = len(offline.outputs)
        deadline = time.monotonic() + 20
        while counts["samples"] < want and time.monotonic() < deadline:
            spin()
        end = time.monotonic() + 0.5
        while time.monotonic() < end:
            spin()
    finally:
        if player is not None:
            player.close()
        node.destroy_node()
        rclpy.try_shutdown()
        node_proc.send_signal(2)
        try:
            node_proc.wait(15)
        except subprocess.TimeoutExpired:
            node_proc.kill()
    last = offline.outputs[-1]
    print(f"\nlive node: {counts['samples']} samples published (offline replay: {want})\n")
    rows = []
    worst = 0.0
    for j, m in enumerate(config.models):
        get = lambda s: latest.get(f"/{NODE_NAME}/{m.output}/{s}")  # noqa: E731
        est, se, sc = (get(suffix) for suffix in ARRAY_OUTPUTS)
        if est is None or se is None or sc is None:
            print(f"{m.output}: no estimate received from the node; its log: {node_log.name}")
            return 1
        names = est.layout.dim[0].label.split(",")
        rows += rows_from_arrays(names, est.data, sc.data, se.data, T2_TRUE)
        n = len(names)
        for live, off in ((est.data, last.theta[j, :n]), (se.data, last.se[j, :n]), (sc.data, last.se_conventional[j, :n])):
            worst = max(worst, float(np.max(np.abs(np.array(live) - off) / np.abs(off))))
    print(results_table(rows))
    print(f"\nlargest relative difference between the live node and the offline replay: {worst:.1e}")
    os.unlink(node_log.name)
    print("Conventional standard errors assume white residuals (Eq. 13); the corrected ones use the recursive\n"
          "residual autocorrelation (Eqs. 17-22) and cover the real scatter of the estimates (Table 3).")
    return 0 if worst < 1e-9 and counts["samples"] == want else 1
