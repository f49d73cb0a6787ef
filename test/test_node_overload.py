"""A node given more work than it can do says so, in /diagnostics and once in its log, blames
itself (not the transport or the clocks) and spaces its frequency-domain evaluations out."""

from __future__ import annotations

import time

import pytest

from rls_uncertainty.datapath.outputs import NODE_NAME as NODE
from rls_uncertainty.offline.bags import read_inputs

from ros_harness import BUNDLED, T2, NodeProcess, RosTester, to_rclpy

pytestmark = pytest.mark.usefixtures("ros")


def test_an_overloaded_node_says_it_cannot_keep_up_and_spaces_out_the_frequency_domain(tmp_path):
    # The bundled maneuver estimated at 1 kHz, both methods, a frequency-domain evaluation on
    # every sample over a one-second lag span: far more than a period's work per sample.
    node = NodeProcess(tmp_path, "--params-file", T2, "-p", "qos.reliable:=true", "-p", "qos.depth:=10000",
                       "-p", "diagnostics_period:=0.2", "-p", "rate:=1000.0", "-p", "estimator.method:=both",
                       "-p", "frequency.every:=1", "-p", "inputs.buffer_duration:=60.0")
    tester = RosTester()
    try:
        tester.wait_connected()
        messages, _ = read_inputs(BUNDLED)
        tester.publish_all([(k, to_rclpy(k, m)) for k, _s, m in messages])
        key = f"{NODE}: samples"
        d = tester.wait_diagnostics(lambda d: d.get(key, {}).get("message", "").startswith("cannot keep up: "),
                                    timeout=180.0)
        text = d[key]["message"]
        assert " ms behind, " in text and " ms per sample against a period of 1.0 ms" in text, text
        assert d[key]["level"] == 1  # WARN
        d = tester.wait_diagnostics(lambda d: "degraded: frequency.every 1 -> " in d.get(key, {}).get("message", ""),
                                    timeout=180.0)
        assert int(d[key]["load.frequency_every"]) >= 5
        assert "lost in transport" not in d[f"{NODE}: inputs"]["message"]
        assert "different clocks" not in d[f"{NODE}: inputs"]["message"]
        step = "degraded: frequency.every 1 -> 5 (cannot keep up)"  # logged just after that status went out
        deadline = time.monotonic() + 60.0
        while step not in node.text():
            assert time.monotonic() < deadline, node.text()
            time.sleep(0.1)
        log = node.text()
        assert log.count("cannot keep up: ") == 1, log  # said once per episode
    finally:
        tester.close()
        assert node.stop() == 0, node.text()


def test_messages_dropped_from_a_full_input_queue_are_blamed_on_the_node_not_the_transport(tmp_path):
    # Input queues two messages deep, the bundled maneuver published unpaced: the middleware
    # drops the oldest IMU messages before the node's next intake pass takes them.
    node = NodeProcess(tmp_path, "--params-file", T2, "-p", "qos.reliable:=true", "-p", "qos.depth:=2",
                       "-p", "diagnostics_period:=0.2", "-p", "inputs.buffer_duration:=60.0")
    tester = RosTester()
    try:
        tester.wait_connected()
        messages, _ = read_inputs(BUNDLED)
        tester.publish_all([(k, to_rclpy(k, m)) for k, _s, m in messages], pace=1e9)
        inputs = f"{NODE}: inputs"
        d = tester.wait_diagnostics(lambda d: "full input queue" in d.get(inputs, {}).get("message", ""),
                                    timeout=120.0)
        text = d[inputs]["message"]
        assert "(dropped from the node's full input queue, qos.depth 2: the node is behind its inputs)" in text, text
        assert "lost in transport" not in text and "different clocks" not in text, text
        assert int(d[inputs]["imu.recent.queue_full"]) > 0 and int(d[inputs]["imu.recent.missing"]) > 0
    finally:
        tester.close()
        assert node.stop() == 0, node.text()
