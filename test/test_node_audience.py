"""Output topics nobody subscribes to are not published; the first subscriber of one gets the
newest sample once the node has seen it (one diagnostics period), with the offline replay's
values, while no new sample comes; the node's diagnostics count the topics it publishes."""

from __future__ import annotations

import time

import numpy as np
import pytest
import rclpy
from rclpy.qos import QoSDurabilityPolicy, QoSHistoryPolicy, QoSProfile, QoSReliabilityPolicy
from std_msgs.msg import Float64MultiArray

from rls_uncertainty.datapath.outputs import NODE_NAME as NODE
from rls_uncertainty.datapath.outputs import parse_stamp_label
from rls_uncertainty.offline.bags import read_inputs
from rls_uncertainty.offline.replay import run_pipeline
from rls_uncertainty.settings import load_parameters_file, pipeline_config

from ros_harness import BUNDLED, REPLAY_NODE, T2, NodeProcess, RosTester, to_rclpy

pytestmark = pytest.mark.usefixtures("ros")


def _stamp(msg) -> int:
    return parse_stamp_label(msg.layout.dim[-1].label)


def test_an_unsubscribed_topic_is_not_published_and_its_first_subscriber_gets_the_newest_sample(tmp_path):
    node = NodeProcess(tmp_path, "--params-file", T2, *REPLAY_NODE, "-p", "diagnostics_period:=0.2")
    tester = RosTester(models=("CZ",))  # Cm's topics have no subscriber
    late = None
    try:
        tester.wait_connected()
        listened = len(tester.subs) - 1  # the tester's sample topics (its last subscription: /diagnostics)
        said = lambda n: lambda d: d.get(f"{NODE}: samples", {}).get("outputs_subscribed") == str(n)  # noqa: E731
        tester.wait_diagnostics(said(listened))  # the node counts the topics it publishes
        topic = f"/{NODE}/Cm/estimates"
        messages, _ = read_inputs(BUNDLED)
        part = messages[: len(messages) // 3]
        config = pipeline_config({**load_parameters_file("t2"), "inputs.buffer_duration": 60.0})
        offline = run_pipeline(part, config).outputs
        tester.publish_all([(k, to_rclpy(k, m)) for k, _s, m in part])
        stamps = tester.outputs[f"/{NODE}/sample_stamp"]
        assert tester.spin_until(lambda: len(stamps) >= len(offline), 60)
        late = rclpy.create_node("late_cm_display")
        qos = QoSProfile(depth=100, history=QoSHistoryPolicy.KEEP_LAST, reliability=QoSReliabilityPolicy.RELIABLE,
                         durability=QoSDurabilityPolicy.TRANSIENT_LOCAL)
        got: list = []
        late.create_subscription(Float64MultiArray, topic, got.append, qos)
        last_cm = [o for o in offline if o.ready[1]][-1]
        deadline = time.monotonic() + 60  # no new sample meanwhile: only what the node sends on noticing
        while not got and time.monotonic() < deadline:
            rclpy.spin_once(late, timeout_sec=0.1)
        end = time.monotonic() + 1.0  # anything else it would send shows now
        while time.monotonic() < end:
            rclpy.spin_once(late, timeout_sec=0.1)
        # Only the newest: the samples before the subscriber came were never published on Cm.
        assert [_stamp(m) for m in got] == [last_cm.stamp_ns], [_stamp(m) for m in got]
        np.testing.assert_array_equal(np.array(got[0].data), last_cm.theta[1, :4])
        tester.wait_diagnostics(said(listened + 1))
    finally:
        if late is not None:
            late.destroy_node()
        tester.close()
        assert node.stop() == 0, node.text()
