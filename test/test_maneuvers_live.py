"""The node cuts its stream into maneuvers on test-point events (real DDS on loopback): the
latched ~/maneuvers history equals the offline run of the same messages in the same order, a
late subscriber gets it at once, garbage events are counted in /diagnostics."""

from __future__ import annotations

import json

import pytest
import rclpy
from diagnostic_msgs.msg import KeyValue
from rclpy.qos import QoSDurabilityPolicy, QoSHistoryPolicy, QoSProfile, QoSReliabilityPolicy
from std_msgs.msg import String

from rls_uncertainty.datapath.inputs import feed
from rls_uncertainty.datapath.outputs import NODE_NAME as NODE
from rls_uncertainty.datapath.pipeline import Pipeline
from rls_uncertainty.offline.bags import read_inputs
from rls_uncertainty.offline.replay import run_pipeline
from rls_uncertainty.settings import load_parameters_file, pipeline_config

from ros_harness import BUNDLED, RELIABLE, T2, NodeProcess, RosTester, spin_until, to_rclpy

pytestmark = pytest.mark.usefixtures("ros")

S = 1_000_000_000
LATCHED = QoSProfile(depth=1, reliability=QoSReliabilityPolicy.RELIABLE, history=QoSHistoryPolicy.KEEP_LAST,
                     durability=QoSDurabilityPolicy.TRANSIENT_LOCAL)
# (offset from the bag's first stamp, key, value), off the messages' grid.
EVENTS = [(int(0.5 * S) + 1_300_000, "pA", "start"), (int(2.0 * S) + 1_300_000, "", "start"),
          (int(5.5 * S) + 1_300_000, "pA", "stop"), (int(5.6 * S) + 1_300_000, "pA", "stop"),
          (int(6.0 * S) + 1_300_000, "pB", "start"), (int(11.5 * S) + 1_300_000, "pB", "stop")]


class _Event:
    def __init__(self, key, value):
        self.key, self.value = key, value


def _stream():
    """The bundled bag's messages with the events in their place (by stamp)."""
    messages, t0 = read_inputs(BUNDLED)
    out, pending = [], sorted(EVENTS)
    for kind, stamp, msg in messages:
        while pending and t0 + pending[0][0] <= stamp:
            off, key, value = pending.pop(0)
            out.append(("event", t0 + off, _Event(key, value)))
        out.append((kind, stamp, msg))
    return out


def test_the_live_history_equals_the_offline_run_of_the_same_messages(tmp_path):
    stream = _stream()
    params = {**load_parameters_file("t2"), "inputs.buffer_duration": 60.0, "maneuvers.source": "events"}
    offline = run_pipeline(stream, pipeline_config(params), record=False, keep_outputs=False)
    assert offline.maneuvers is not None
    want = [[(r.parameter, r.estimate, r.se_conventional, r.se_corrected, r.samples, r.status)
             for r in rec.rows] for rec in offline.maneuvers.history]
    node = NodeProcess(tmp_path, "--params-file", T2, "-p", "qos.reliable:=true", "-p", "qos.depth:=10000",
                       "-p", "diagnostics_period:=0.2", "-p", "inputs.buffer_duration:=60.0",
                       "-p", "maneuvers.source:=events")
    tester = RosTester()
    events = tester.node.create_publisher(KeyValue, "/test_point", RELIABLE)
    history: list = []
    tester.node.create_subscription(String, f"/{NODE}/maneuvers", history.append, LATCHED)
    try:
        tester.wait_connected()
        assert tester.spin_until(lambda: events.get_subscription_count() >= 1 and history, 20), node.text()
        stamps = tester.outputs[f"/{NODE}/sample_stamp"]
        before = iter(_outputs_before_events(stream, pipeline_config(params)))
        batch = []
        for kind, _stamp, msg in stream:
            if kind != "event":
                batch.append((kind, to_rclpy(kind, msg)))
                continue
            # The node has fed what came before the event once it published those samples; the
            # messages after its last sample were received before the event, so they go first.
            tester.publish_all(batch)
            batch, due, n = [], next(before), len(history)
            assert tester.spin_until(lambda due=due: len(stamps) >= due, 30), node.text()
            events.publish(KeyValue(key=msg.key, value=msg.value))
            assert tester.spin_until(lambda n=n: len(history) > n, 20), node.text()
        tester.publish_all(batch)
        assert tester.spin_until(lambda: json.loads(history[-1].data)["recorded"] == 2, 30), node.text()
        got = json.loads(history[-1].data)
        assert got["rejected"] == {"event_key": 1, "stop_without_start": 1}
        assert [m["name"] for m in got["maneuvers"]] == ["pA", "pB"]
        rows = [[(r["parameter"], r["estimate"], r["se_conventional"], r["se_corrected"], r["samples"], r["status"])
                 for r in m["rows"]] for m in got["maneuvers"]]
        assert rows == want
        diag = tester.wait_diagnostics(lambda d: f"{NODE}: maneuvers" in d)
        status = diag[f"{NODE}: maneuvers"]
        assert status["maneuvers.recorded"] == "2" and status["maneuvers.events_rejected"] == "2"
        assert status["maneuvers.events_rejected.event_key"] == "1" and status["maneuvers.last"] == "pB"
        # A late subscriber gets the history at once (transient local).
        late: list = []
        late_node = rclpy.create_node("late")
        try:
            late_node.create_subscription(String, f"/{NODE}/maneuvers", late.append, LATCHED)
            assert spin_until(late_node, lambda: bool(late), 20)
            assert json.loads(late[-1].data) == got
        finally:
            late_node.destroy_node()
    finally:
        tester.close()
        assert node.stop() == 0, node.text()


def _outputs_before_events(stream, config):
    """Per event of ``stream``, the samples a pipeline makes from the input messages before it."""
    pipe = Pipeline(config)
    made, out = 0, []
    for kind, _stamp, msg in stream:
        if kind == "event":
            out.append(made)
        else:
            made += len(feed(pipe, kind, msg))
    return out
