"""Helpers for the DDS tests: the estimator node in its own process, and a test-side rclpy
node that publishes inputs and records every output of the estimator node."""

from __future__ import annotations

import os
import subprocess
import sys
import time
from pathlib import Path

import rclpy
from diagnostic_msgs.msg import DiagnosticArray
from rclpy.qos import QoSHistoryPolicy, QoSProfile, QoSReliabilityPolicy
from std_msgs.msg import Float64MultiArray, Header

from rls_uncertainty.datapath.diagnostics import outputs_discovered, outputs_subscribed
from rls_uncertainty.datapath.inputs import MESSAGE_TYPES, STREAMS, message_class
from rls_uncertainty.datapath.outputs import MODEL_OUTPUTS, NODE_NAME
from rls_uncertainty.ros.player import stop_process

ROOT = Path(__file__).resolve().parents[1]
BUNDLED = ROOT / "bags" / "t2_maneuver"
T2 = str(ROOT / "config" / "t2.yaml")
# The node settings the README gives for a replay at any rate: reliable inputs whose queues
# hold every message of the bag's busiest topic, and a buffer longer than the node's backlog
# can grow (the node takes one message per topic per executor round, so a backlog lets the
# slow streams run ahead of the IMU; with the default 2 s buffer their messages would expire).
REPLAY_NODE = ("-p", "qos.reliable:=true", "-p", "qos.depth:=10000", "-p", "inputs.buffer_duration:=60.0",
               "-p", "shed_load:=false")  # a node that is to equal the replay never sheds
TYPES = {kind: message_class(MESSAGE_TYPES[kind]) for kind in STREAMS}
RELIABLE = QoSProfile(depth=5000, reliability=QoSReliabilityPolicy.RELIABLE, history=QoSHistoryPolicy.KEEP_LAST)


class NodeProcess:
    """``python -m rls_uncertainty.ros.node --ros-args ...`` with its output in a log file."""

    # When the newest node process started (wall clock, ns): diagnostics sent before it come from
    # a node stopped earlier and are dropped by RosTester (see _take_diagnostics).
    last_start_ns = 0

    def __init__(self, tmp_path: Path, *ros_args: str, name: str = "node") -> None:
        NodeProcess.last_start_ns = time.time_ns()
        self.log = tmp_path / f"{name}.log"
        self._fh = open(self.log, "w")  # noqa: SIM115 - the child process writes to it; closed in stop()
        self.proc = subprocess.Popen(
            [sys.executable, "-m", "rls_uncertainty.ros.node", "--ros-args", *ros_args],
            stdout=self._fh, stderr=subprocess.STDOUT, cwd=ROOT, env=dict(os.environ),
        )

    def text(self) -> str:
        return self.log.read_text()

    def stop(self, timeout: float = 15.0) -> int:
        stop_process(self.proc, timeout)
        self._fh.close()
        return self.proc.returncode


def spin_until(node, condition, timeout: float) -> bool:
    """Spin ``node`` until ``condition()`` holds (True) or ``timeout`` seconds pass (False)."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        rclpy.spin_once(node, timeout_sec=0.05)
        if condition():
            return True
    return False


def stamp_of(msg) -> int:
    return msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec


class RosTester:
    """Publishes the standard inputs and records the estimator node's outputs."""

    def __init__(self, models=("CZ", "Cm"), name: str = "tester") -> None:
        self.node = rclpy.create_node(name)
        self.pubs = {k: self.node.create_publisher(t, f"/{k}", RELIABLE) for k, t in TYPES.items()}
        self.outputs: dict[str, list] = {}
        self.diagnostics: list = []
        self.subs = []
        for m in models:
            for suffix in MODEL_OUTPUTS:
                self._record(Float64MultiArray, f"/{NODE_NAME}/{m}/{suffix}")
        self._record(Header, f"/{NODE_NAME}/sample_stamp")
        self.subs.append(self.node.create_subscription(DiagnosticArray, "/diagnostics", self._take_diagnostics, 50))

    def _take_diagnostics(self, msg, info) -> None:
        # A node stopped just before the next one started may leave a diagnostics message in this
        # reader, taken only when the test spins again: it must not pass for the new node's (the
        # two have the same name). The DDS source timestamp is the sender's wall clock, also
        # under use_sim_time.
        if info["source_timestamp"] >= NodeProcess.last_start_ns:
            self.diagnostics.append(msg)

    def _record(self, msg_type, topic):
        store = self.outputs.setdefault(topic, [])
        self.subs.append(self.node.create_subscription(msg_type, topic, store.append, RELIABLE))

    def spin_until(self, condition, timeout: float = 20.0) -> bool:
        return spin_until(self.node, condition, timeout)

    def wait_connected(self, timeout: float = 60.0, outputs: bool = True) -> None:
        """Spin until discovery matched both ends of every connection: a message published before
        its reader matched is lost to it. The inputs: this tester's publishers matched a
        subscription on each topic and the node's report counts a publisher on each stream. The
        outputs (unless ``outputs`` is false): this tester's subscriptions matched the node's
        publishers, and the node's report says it publishes on at least as many sample topics (it
        publishes only on those its publishers had matched a subscriber on at its last report)."""
        samples = self.subs[:-1]

        def seen() -> tuple[dict[str, int], dict[str, int], int, dict[str, str]]:
            report = self.latest_diagnostics()
            inputs = report.get(f"{NODE_NAME}: inputs", {})
            node_pubs = {k: int(inputs.get(f"{k}.publishers", 0)) for k in self.pubs}
            return ({k: p.get_subscription_count() for k, p in self.pubs.items()}, node_pubs,
                    sum(s.get_publisher_count() >= 1 for s in samples), report.get(f"{NODE_NAME}: samples", {}))

        def ready() -> bool:
            mine, nodes, matched, values = seen()
            ins = min(mine.values()) >= 1 and min(nodes.values()) >= 1
            return ins and (not outputs or outputs_discovered(values, matched, len(samples)))

        if not self.spin_until(ready, timeout):
            mine, nodes, matched, values = seen()
            subscribed = outputs_subscribed(values)
            raise AssertionError(
                f"estimator node not discovered within {timeout:g} s: subscriptions matched per input {mine}; "
                f"publishers the node reports per input {nodes}; "
                + (f"{matched} of the {len(samples)} output subscriptions matched the node's publishers, the node "
                   f"reports publishing on {subscribed} sample topics (-1: no report)" if outputs else
                   "outputs not waited for"))

    def publish(self, kind: str, msg) -> None:
        self.pubs[kind].publish(msg)

    def publish_all(self, messages, pace: float = 2000.0) -> None:
        """``(kind, msg)`` pairs, paced to about ``pace`` messages per second."""
        t0 = time.monotonic()
        for i, (kind, msg) in enumerate(messages):
            self.pubs[kind].publish(msg)
            if i % 20 == 19:
                delay = t0 + (i + 1) / pace - time.monotonic()
                if delay > 0:
                    time.sleep(delay)
                rclpy.spin_once(self.node, timeout_sec=0)

    def latest_diagnostics(self, after: float | None = None) -> dict[str, dict[str, str]]:
        """The newest DiagnosticArray as ``{status name: {key: value}}`` plus ``message``."""
        if not self.diagnostics:
            return {}
        out = {}
        for s in self.diagnostics[-1].status:
            out[s.name] = {kv.key: kv.value for kv in s.values}
            out[s.name]["message"] = s.message
            out[s.name]["level"] = int.from_bytes(s.level, "little") if isinstance(s.level, bytes) else int(s.level)
        return out

    def wait_diagnostics(self, predicate, timeout: float = 30.0) -> dict:
        self.diagnostics.clear()
        ok = self.spin_until(lambda: bool(self.diagnostics) and predicate(self.latest_diagnostics()), timeout)
        diag = self.latest_diagnostics()
        assert ok, f"diagnostics never satisfied the condition; last: {diag}"
        return diag

    def close(self) -> None:
        self.node.destroy_node()


def to_rclpy(kind: str, rb_msg):
    """A rosbags message of a standard input type as the rclpy message."""
    msg = TYPES[kind]()
    msg.header.stamp.sec = rb_msg.header.stamp.sec
    msg.header.stamp.nanosec = rb_msg.header.stamp.nanosec
    msg.header.frame_id = rb_msg.header.frame_id
    if kind == "imu":
        for f in ("angular_velocity", "linear_acceleration"):
            src, dst = getattr(rb_msg, f), getattr(msg, f)
            dst.x, dst.y, dst.z = src.x, src.y, src.z
        msg.orientation_covariance[0] = -1.0
    elif kind == "airspeed":
        msg.vector.x, msg.vector.y, msg.vector.z = rb_msg.vector.x, rb_msg.vector.y, rb_msg.vector.z
    elif kind == "dynamic_pressure":
        msg.fluid_pressure = rb_msg.fluid_pressure
    elif kind == "control_surfaces":
        msg.name = list(rb_msg.name)
        msg.position = [float(x) for x in rb_msg.position]
    elif kind == "thrust":
        msg.wrench.force.x = rb_msg.wrench.force.x
    return msg
