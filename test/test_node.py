"""The estimator node in its own process, talking real DDS on loopback to this test process:
outputs equal the offline replay (estimates, standard errors, convergence flags and the
decimated covariances against bank.covariance), labels and layouts, diagnostics, bad and
malformed input, parameters, services, state file (a refused file is kept), simulated time,
the consumer example; and main() leaves DDS discovery to the environment."""

from __future__ import annotations

import io
import json
import math
import os
import re
import stat
import subprocess
import sys
import time
import zipfile
from collections import Counter

import numpy as np
import pytest
import rclpy
from rcl_interfaces.msg import Parameter as ParameterMsg
from rcl_interfaces.msg import ParameterType, ParameterValue
from rcl_interfaces.srv import SetParameters
from rosgraph_msgs.msg import Clock
from std_srvs.srv import SetBool, Trigger

from rls_uncertainty.datapath.inputs import MESSAGE_TYPES, feed
from rls_uncertainty.datapath.outputs import NODE_NAME as NODE
from rls_uncertainty.datapath.outputs import parse_stamp_label
from rls_uncertainty.datapath.pipeline import Pipeline
from rls_uncertainty.offline.bags import read_inputs
from rls_uncertainty.offline.replay import run_pipeline
from rls_uncertainty.settings import load_parameters_file, pipeline_config
from rls_uncertainty.state_file import load_state

from ros_harness import BUNDLED, ROOT, T2, NodeProcess, RosTester, to_rclpy

pytestmark = pytest.mark.usefixtures("ros")


@pytest.fixture(scope="module")
def bag():
    messages, _ = read_inputs(BUNDLED)
    return messages


@pytest.fixture
def tester():
    t = RosTester()
    yield t
    t.close()


# DDS keeps each topic's order but not the interleaving across topics: a node that falls
# behind (a busy machine) takes about one message per topic per executor round, so a slow stream's
# backlog drains ahead of the IMU's and with the default 2 s buffer its messages expire. With a
# buffer longer than any test's sequence, the outcome does not depend on the interleaving.
NO_EXPIRY = {"inputs.buffer_duration": 60.0}


def _t2_config(overrides=None):
    return pipeline_config({**load_parameters_file("t2"), **(overrides or {})})


def _ros_params(values):
    return [arg for name, value in values.items() for arg in ("-p", f"{name}:={value}")]


# These tests play faster than real time and compare with the offline replay: a node that falls
# behind on a busy machine must not shed work (which samples carry covariances would change).
# Shedding is tested in test_node_overload.py.
NO_SHEDDING = ("-p", "shed_load:=false")


def _node(tmp_path, *args, name="node"):
    # Reliable inputs with a queue deeper than any test's topic: a node slowed down by a busy
    # machine then delays messages instead of losing them (KEEP_LAST overwrites when full).
    return NodeProcess(tmp_path, "--params-file", T2, "-p", "qos.reliable:=true", "-p", "qos.depth:=10000",
                       "-p", "diagnostics_period:=0.2", *NO_SHEDDING, *args, name=name)


def _arrays(tester, model, suffix):
    return tester.outputs[f"/{NODE}/{model}/{suffix}"]


def _stamp(msg):
    return parse_stamp_label(msg.layout.dim[-1].label)


def _offline_covariances(bag, config):
    """A Pipeline fed the messages one by one, and for each sample that publishes covariances
    ``{stamp: {model index: (corrected, conventional)}}``: bank.covariance itself when the
    sample was the last its message completed (the bank is still there), else the pipeline's."""
    pipe = Pipeline(config)
    cov = {}
    for kind, _s, msg in bag:
        produced = feed(pipe, kind, msg)
        for i, out in enumerate(produced):
            if out.covariance is None:
                continue
            cov[out.stamp_ns] = {}
            for j, n in enumerate(pipe.sizes):
                if not out.ready[j]:
                    continue
                if i == len(produced) - 1:
                    pair = tuple(pipe.bank.covariance(j, k) for k in ("corrected", "conventional"))
                else:
                    pair = (out.covariance[0, j, :n, :n], out.covariance[1, j, :n, :n])
                cov[out.stamp_ns][j] = pair
    return cov


def test_live_node_reproduces_the_offline_replay(tmp_path, tester, bag):
    node = _node(tmp_path, *_ros_params(NO_EXPIRY))
    try:
        tester.wait_connected()
        offline = run_pipeline(bag, _t2_config(NO_EXPIRY))
        n_out = len(offline.outputs)
        tester.publish_all([(k, to_rclpy(k, m)) for k, _s, m in bag])
        stamps = tester.outputs[f"/{NODE}/sample_stamp"]
        # Every array the checks below count, of both models, has arrived (each topic is its own
        # DDS writer: on a loaded machine the last message of one may come after another's).
        expected = {model: sum(o.ready[j] for o in offline.outputs) for j, model in enumerate(("CZ", "Cm"))}
        assert tester.spin_until(
            lambda: len(stamps) >= n_out
            and all(len(_arrays(tester, model, suffix)) >= count for model, count in expected.items()
                    for suffix in ("estimates", "standard_errors", "standard_errors_conventional", "converged")),
            60,
        ), node.text()
        assert len(stamps) == n_out
        last = offline.outputs[-1]
        assert stamps[-1].stamp.sec * 10**9 + stamps[-1].stamp.nanosec == last.stamp_ns
        models = (("CZ", "CZ_0,CZ_alpha,CZ_delta_e"), ("Cm", "Cm_0,Cm_alpha,Cm_q,Cm_delta_e"))
        for j, (model, label) in enumerate(models):
            n = len(label.split(","))
            for suffix, want in (("estimates", last.theta), ("standard_errors", last.se),
                                 ("standard_errors_conventional", last.se_conventional)):
                msgs = _arrays(tester, model, suffix)
                assert len(msgs) == sum(o.ready[j] for o in offline.outputs)
                dim = msgs[-1].layout.dim[0]
                assert (dim.label, dim.size, dim.stride) == (label, n, n)
                assert parse_stamp_label(msgs[-1].layout.dim[1].label) == last.stamp_ns
                assert (msgs[-1].layout.dim[1].size, msgs[-1].layout.dim[1].stride) == (1, 1)
                np.testing.assert_allclose(np.array(msgs[-1].data), want[j, :n], rtol=1e-9, atol=0)
                assert all(np.isfinite(m.data).all() for m in msgs)
        _check_convergence_and_covariance(tester, bag, offline)
        diag = tester.wait_diagnostics(lambda d: f"{NODE}: samples" in d)
        assert diag[f"{NODE}: samples"]["samples_used"] == str(offline.pipeline.samples_used)
        assert diag[f"{NODE}: inputs"]["imu.received"] == "2400"
        assert float(diag[f"{NODE}: model CZ"]["r_squared"]) > 0.8
        assert "latency_ms.p99" in diag[f"{NODE}: samples"] or len(tester.diagnostics) >= 1
        # Convergence in the model status (the bundled maneuver converges), the lags in use.
        cm = diag[f"{NODE}: model Cm"]
        assert (cm["converged"], cm["converged_parameters"]) == ("True", "Cm_0,Cm_alpha,Cm_q,Cm_delta_e")
        assert cm["message"].endswith("; converged") and cm["lags"] == "50"
        assert diag[f"{NODE}: inputs"]["recent_window_s"] == "10"
    finally:
        assert node.stop() == 0, node.text()


def _check_convergence_and_covariance(tester, bag, offline):
    """``~/M/converged`` equals the offline pipeline's flags sample for sample; ``~/M/covariance``
    and ``~/M/covariance_conventional`` come on the decimated samples (every 10th grid point),
    n x n row-major with the stamp in a third dim, equal to bank.covariance to 1e-9."""
    config = offline.pipeline.config
    expected_cov = _offline_covariances(bag, config)
    assert expected_cov and all(s % (10 * config.period_ns) == 0 for s in expected_cov)
    for j, (model, n) in enumerate((("CZ", 3), ("Cm", 4))):
        label = offline.pipeline.labels[j]
        ready = [o for o in offline.outputs if o.ready[j]]
        conv = _arrays(tester, model, "converged")
        assert [_stamp(m) for m in conv] == [o.stamp_ns for o in ready]
        for msg, out in zip(conv, ready, strict=True):
            assert [(d.label, d.size, d.stride) for d in msg.layout.dim] == [(label, n, n), (msg.layout.dim[1].label,
                                                                              1, 1)]
            assert list(msg.data) == out.converged[j, :n].astype(float).tolist()
        assert conv[-1].data.tolist() == [1.0] * n  # the bundled maneuver converges
        for suffix, k in (("covariance", 0), ("covariance_conventional", 1)):
            msgs = _arrays(tester, model, suffix)
            want = {s: c[j][k] for s, c in expected_cov.items() if j in c}
            assert [_stamp(m) for m in msgs] == sorted(want)
            for msg in msgs:
                dims = [(d.label, d.size, d.stride) for d in msg.layout.dim]
                assert dims == [(label, n, n * n), (label, n, n), (msg.layout.dim[2].label, 1, 1)]
                assert msg.layout.data_offset == 0
                cov = np.array(msg.data).reshape(n, n)
                ref = want[_stamp(msg)]
                if np.diag(ref).min() < 0:  # an exact fit's rounding at initialization: published as zero
                    ref = np.zeros_like(ref)
                np.testing.assert_allclose(cov, ref, rtol=0, atol=1e-9 * np.abs(ref).max())
                np.testing.assert_array_equal(cov, cov.T)


def _excitation(t):
    """Inputs that make CZ and Cm identifiable: independent sines on q, alpha and elevator."""
    return 0.1 * math.sin(2 * math.pi * 0.7 * t), 0.08 + 0.03 * math.sin(2 * math.pi * 1.3 * t), \
        0.05 * math.sin(2 * math.pi * 0.4 * t + 1.0)


def _synthetic(t0_ns, seconds, *, gap=None, zero_air=None, bad=True):
    """A message sequence with every kind of bad input mixed into good data."""
    from geometry_msgs.msg import Vector3Stamped
    from sensor_msgs.msg import FluidPressure, Imu, JointState

    def hdr(msg, ns):
        msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(ns, 10**9)
        msg.header.frame_id = "base_link"  # inputs.frame_id: inputs in another frame are rejected
        return msg

    out = []
    for ms in range(int(seconds * 1000)):
        ns = t0_ns + ms * 10**6
        t = ms * 1e-3
        q, alpha, de = _excitation(t)
        if ms % 5 == 0:
            m = hdr(Imu(), ns)
            m.angular_velocity.y = -q
            m.linear_acceleration.z = 9.8 + 5 * alpha + 2 * de
            out.append(("imu", m))
        if ms % 20 == 3 and not (gap and gap[0] <= t < gap[1]):
            m = hdr(Vector3Stamped(), ns)
            V = 0.0 if zero_air and zero_air[0] <= t < zero_air[1] else 40.0
            m.vector.x, m.vector.z = V * math.cos(alpha), -V * math.sin(alpha)
            out.append(("airspeed", m))
            p = hdr(FluidPressure(), ns)
            p.fluid_pressure = 980.0
            out.append(("dynamic_pressure", p))
        if ms % 20 == 7:
            m = hdr(JointState(), ns)
            m.name = ["elevator_left", "elevator_right", "aileron_left", "aileron_right", "rudder"]
            m.position = [de, de, 0.0, 0.0, 0.0]
            out.append(("control_surfaces", m))
        if bad and ms == 2000:
            m = hdr(Imu(), ns + 10**5)
            m.angular_velocity.x = float("nan")
            out.append(("imu", m))
            m = hdr(Imu(), ns + 2 * 10**5)
            m.linear_acceleration.z = float("inf")
            out.append(("imu", m))
            m = hdr(Imu(), ns + 2 * 10**5)  # duplicate of the previous IMU stamp (the Inf one)
            out.append(("imu", m))
            for k in range(20):  # a burst of old messages
                out.append(("imu", hdr(Imu(), ns - (500 + k) * 10**6)))
            m = hdr(JointState(), ns + 3 * 10**5)
            m.name = ["elevator_left", "elevator_right"]
            m.position = [0.0]
            out.append(("control_surfaces", m))
            m = hdr(JointState(), ns + 4 * 10**5)
            m.name = ["elevator_left", "elevator_right", "aileron_left", "aileron_right", "rudder", "flap"]
            m.position = [de, de, 0.0, 0.0, 0.0, 0.2]
            out.append(("control_surfaces", m))
    return out


def test_bad_input_is_counted_in_diagnostics_and_never_published(tmp_path, tester):
    node = _node(tmp_path, *_ros_params(NO_EXPIRY))
    try:
        tester.wait_connected()
        seq = _synthetic(10**18, 8.0, gap=(4.0, 5.0), zero_air=(6.0, 6.5))
        expected = Pipeline(_t2_config(NO_EXPIRY))
        for kind, msg in seq:
            feed(expected, kind, msg)
        c = expected.counters()
        tester.publish_all(seq)
        d = tester.wait_diagnostics(
            lambda d: d.get(f"{NODE}: samples", {}).get("samples_formed") == str(c["samples_formed"])
        )
        inputs, samples = d[f"{NODE}: inputs"], d[f"{NODE}: samples"]
        assert inputs["imu.rejected.non_finite"] == "2"
        assert inputs["imu.rejected.duplicate"] == "1"
        assert inputs["imu.rejected.out_of_order"] == "20"
        assert inputs["control_surfaces.rejected.mismatched_arrays"] == "1"
        assert samples["unknown_joint.flap"] == "1"
        # The 1 s air-data gap: grid points 4.00 ... 4.98 s skip (last message 3.983 s).
        assert samples["samples_rejected.gap_airspeed"] == str(len(range(4000, 5001, 20)))
        # Zero airspeed is below limits.airspeed_min: those messages are rejected, and no sample
        # is interpolated across them.
        assert int(inputs["airspeed.rejected.implausible_airspeed"]) > 0
        assert int(samples["samples_rejected.invalid_airspeed"]) > 0
        for key, value in c["samples_rejected"].items():
            assert samples[f"samples_rejected.{key}"] == str(value)
        assert inputs["message"] != "all inputs fresh" and d[f"{NODE}: inputs"]["level"] == 1
        for topic, msgs in tester.outputs.items():
            if "standard_errors" in topic or "estimates" in topic:
                assert msgs and all(np.isfinite(m.data).all() for m in msgs), topic
        # A stream that stops is reported as stale.
        d = tester.wait_diagnostics(lambda d: "airspeed stale" in d.get(f"{NODE}: inputs", {}).get("message", ""))
    finally:
        assert node.stop() == 0, node.text()


def test_malformed_messages_are_counted_and_the_first_of_each_input_logged(tmp_path, tester):
    """Raw payloads: two truncated IMU messages and one garbage JointState are counted as
    malformed and logged once per input; a big-endian IMU message is decoded and accepted."""
    from rosbags.typesys import Stores, get_typestore

    store = get_typestore(Stores.ROS2_JAZZY)
    T = store.types
    imu = T["sensor_msgs/msg/Imu"](
        header=T["std_msgs/msg/Header"](stamp=T["builtin_interfaces/msg/Time"](sec=5, nanosec=0), frame_id="base_link"),
        orientation=T["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0, w=1.0),
        orientation_covariance=np.zeros(9),
        angular_velocity=T["geometry_msgs/msg/Vector3"](x=0.0, y=0.1, z=0.0),
        angular_velocity_covariance=np.zeros(9),
        linear_acceleration=T["geometry_msgs/msg/Vector3"](x=0.0, y=0.0, z=9.8),
        linear_acceleration_covariance=np.zeros(9))
    good = bytes(store.serialize_cdr(imu, "sensor_msgs/msg/Imu"))
    big_endian = bytes(store.serialize_cdr(imu, "sensor_msgs/msg/Imu", little_endian=False))
    node = _node(tmp_path)
    try:
        tester.wait_connected()
        tester.publish("imu", good[:40])
        tester.publish("imu", good[:-8])
        tester.publish("control_surfaces", b"\x00\x01\x00\x00" + bytes(range(200, 240)))
        tester.publish("imu", big_endian)
        d = tester.wait_diagnostics(lambda d: d.get(f"{NODE}: inputs", {}).get("imu.received") == "3"
                                    and d[f"{NODE}: inputs"].get("control_surfaces.received") == "1")
        inputs = d[f"{NODE}: inputs"]
        assert (inputs["imu.rejected.malformed: error"], inputs["imu.accepted"]) == ("2", "1")
        assert inputs["control_surfaces.rejected.malformed: error"] == "1"
        assert "imu rejected 2" in inputs["message"] and inputs["level"] == 1
    finally:
        assert node.stop() == 0, node.text()
    lines = node.text().splitlines()
    imu_lines = [line for line in lines if "malformed message on /imu" in line]
    assert len(imu_lines) == 1, node.text()
    assert "WARN" in imu_lines[0]
    assert f"error: {MESSAGE_TYPES['imu']}: malformed 40-byte payload" in imu_lines[0]  # the first, type and text
    surfaces = [line for line in lines if "malformed message on /control_surfaces" in line]
    assert len(surfaces) == 1 and MESSAGE_TYPES["control_surfaces"] in surfaces[0]


def test_a_misconfigured_data_path_is_logged_and_in_diagnostics(tmp_path, tester, bag):
    """Default parameters (surfaces.elevator expects 'elevator') and the bundled bag (split
    elevators): every JointState is rejected. The node says so in one WARN line naming the
    joints expected and received and the parameter to change (once: throttled), and the
    inputs status carries the same text at level ERROR."""
    node = NodeProcess(tmp_path, "-p", "qos.reliable:=true", "-p", "qos.depth:=10000", "-p", "diagnostics_period:=0.2")
    names = next(m for k, _s, m in bag if k == "control_surfaces").name
    want = (r"control_surfaces: all \d+ messages rejected \(missing_joint\): surfaces.elevator expects \[elevator\], "
            rf"messages carry \[{', '.join(names)}\]; set surfaces.elevator")
    try:
        tester.wait_connected()
        first = [(k, to_rclpy(k, m)) for k, s, m in bag if s < bag[0][1] + 3 * 10**9]
        tester.publish_all(first)
        d = tester.wait_diagnostics(lambda d: d.get(f"{NODE}: inputs", {}).get("control_surfaces.received")
                                    == str(sum(k == "control_surfaces" for k, _ in first)))
        inputs = d[f"{NODE}: inputs"]
        assert inputs["level"] == 2 and re.match(want, inputs["message"]), inputs["message"]
    finally:
        assert node.stop() == 0, node.text()
    warnings = [line for line in node.text().splitlines() if "messages rejected (missing_joint)" in line]
    assert len(warnings) == 1 and "WARN" in warnings[0] and re.search(want, warnings[0]), node.text()


def test_main_leaves_dds_discovery_to_the_environment(monkeypatch):
    """No DDS here: rclpy.init is replaced by a probe that records the discovery range main()
    starts rclpy with, then stops main()."""
    from rls_uncertainty.ros import node as node_module
    seen = []

    class Probe(Exception):
        pass

    def probe_init(*args, **kwargs):
        seen.append(os.environ.get("ROS_AUTOMATIC_DISCOVERY_RANGE", "<unset>"))
        raise Probe

    monkeypatch.setattr(node_module.rclpy, "init", probe_init)
    monkeypatch.setattr(node_module.rclpy, "try_shutdown", lambda *a, **k: None)
    monkeypatch.delenv("ROS_AUTOMATIC_DISCOVERY_RANGE", raising=False)
    with pytest.raises(Probe):
        node_module.main([])
    assert "ROS_AUTOMATIC_DISCOVERY_RANGE" not in os.environ
    monkeypatch.setenv("ROS_AUTOMATIC_DISCOVERY_RANGE", "SUBNET")
    with pytest.raises(Probe):
        node_module.main([])
    assert seen == ["<unset>", "SUBNET"]


def _wait_received(tester, seq, timeout=60.0):
    """Until the node's diagnostics count every message of ``seq`` (its first messages) as received."""
    want = {kind: str(sum(k == kind for k, _ in seq)) for kind, _ in seq}
    tester.wait_diagnostics(lambda d: all(d.get(f"{NODE}: inputs", {}).get(f"{kind}.received") == n
                                          for kind, n in want.items()), timeout)


def _set_parameters(tester, **values):
    client = tester.node.create_client(SetParameters, f"/{NODE}/set_parameters")
    assert client.wait_for_service(10)
    req = SetParameters.Request()
    for name, value in values.items():
        v = ParameterValue()
        if isinstance(value, str):
            v.type, v.string_value = ParameterType.PARAMETER_STRING, value
        elif isinstance(value, int):
            v.type, v.integer_value = ParameterType.PARAMETER_INTEGER, value
        else:
            v.type, v.double_value = ParameterType.PARAMETER_DOUBLE, value
        req.parameters.append(ParameterMsg(name=name, value=v))
    future = client.call_async(req)
    assert tester.spin_until(future.done, 10)
    return future.result().results


def _call(tester, srv_type, name, request):
    client = tester.node.create_client(srv_type, f"/{NODE}/{name}")
    assert client.wait_for_service(10)
    future = client.call_async(request)
    assert tester.spin_until(future.done, 10)
    return future.result()


def _declared_as_written(tester):
    """The node's parameter descriptors, asked over DDS, against the settings' declarations:
    each parameter's range (or choices), meaning and read-only flag are its field's."""
    from rcl_interfaces.srv import DescribeParameters

    from rls_uncertainty.datapath.config import InputConfig
    from rls_uncertainty.schema import settings
    from rls_uncertainty.settings.config import NodeConfig
    from rls_uncertainty.settings.parameters import PARAMETERS

    names = [p.name for p in PARAMETERS]
    described = {d.name: d for d in _call(tester, DescribeParameters, "describe_parameters",
                                          DescribeParameters.Request(names=names)).descriptors}
    assert sorted(described) == sorted(names)
    for cls in (InputConfig, NodeConfig):
        for _f, s in settings(cls):
            d = described[s.ros]
            assert d.description.startswith(s.description) and d.read_only == s.read_only, s.ros
            ranges = d.floating_point_range or d.integer_range
            assert ([(r.from_value, r.to_value) for r in ranges] or [(None, None)]) == [(s.low, s.high)], s.ros
    window = described["estimator.window"]
    assert window.additional_constraints == "one of: truncated, bartlett" and not window.read_only
    span = described["estimator.lag_span"]
    assert (span.floating_point_range[0].from_value, span.floating_point_range[0].to_value) == (-1.0, 2000.0)
    assert "(s); -1: keeps all lags (Eq. 20); 0: the conventional covariance" in span.description
    assert described["topics.imu"].read_only and described["qos.depth"].read_only


def _intake_period_follows_its_parameter(node, tester, bag):
    """The intake timer's period (``intake_period_ms`` in /diagnostics, read from the timer)
    is 5 ms at 50 Hz by default and follows ``intake_period`` without a reset; a period over
    the estimator period is refused naming the parameter, and so is a rate that makes the
    given period too long. The inputs then wait for the longer period: with messages
    arriving every half millisecond, the oldest of a pass has waited about 20 ms."""
    tester.wait_diagnostics(lambda d: d.get(f"{NODE}: samples", {}).get("intake_period_ms") == "5.000")
    assert "taken every 5 ms" in node.text()
    (r,) = _set_parameters(tester, intake_period=0.05)
    assert not r.successful and r.reason.startswith("intake_period 0.05 s is longer than the estimator period")
    (r,) = _set_parameters(tester, intake_period=0.0005)
    assert not r.successful and r.reason.startswith("intake_period must be")
    (r,) = _set_parameters(tester, intake_period=0.02)
    assert r.successful
    (r,) = _set_parameters(tester, rate=100.0)
    assert not r.successful and r.reason.startswith("intake_period 0.02 s is longer")
    imu = [(kind, msg) for kind, _s, msg in bag if kind == "imu"]
    deadline = time.monotonic() + 60

    def waited_a_period() -> bool:
        samples = tester.latest_diagnostics().get(f"{NODE}: samples", {})
        return samples.get("intake_period_ms") == "20.000" and float(samples.get("intake_wait_ms.p99", 0)) >= 10

    for start in range(0, len(imu), 100):  # (the bag's IMU messages once, 50 ms at a time)
        tester.publish_all([(k, to_rclpy(k, m)) for k, m in imu[start:start + 100]], pace=2000.0)
        if waited_a_period() or time.monotonic() > deadline:
            break
    assert tester.spin_until(waited_a_period, 10), tester.latest_diagnostics()


def test_parameters_are_refused_with_reasons_and_changes_reset(tmp_path, tester, bag):
    node = _node(tmp_path)
    try:
        tester.wait_connected()
        _declared_as_written(tester)
        (r,) = _set_parameters(tester, **{"estimator.window": "hann"})
        assert not r.successful and "estimator.window" in r.reason
        (r,) = _set_parameters(tester, **{"estimator.lag_span": -5.0})
        assert not r.successful
        (r,) = _set_parameters(tester, **{"estimator.lag_span": 0.001})  # under one sample at 50 Hz
        assert not r.successful and "less than one sample" in r.reason
        (r,) = _set_parameters(tester, **{"estimator.forgetting": 1.5})
        assert not r.successful
        (r,) = _set_parameters(tester, **{"estimator.residual_burn_in_span": -2.0})
        assert not r.successful and "estimator.residual_burn_in_span" in r.reason
        (r,) = _set_parameters(tester, **{"topics.imu": "other_imu"})
        assert not r.successful and "read-only" in r.reason.lower()
        # The node only writes the state file it checked at start-up.
        (r,) = _set_parameters(tester, state_file=str(tmp_path / "elsewhere.npz"))
        assert not r.successful and "read-only" in r.reason.lower()
        (r,) = _set_parameters(tester, **{"differentiator.lag": 12})
        assert not r.successful and "differentiator.lag" in r.reason
        _intake_period_follows_its_parameter(node, tester, bag)
        (r,) = _set_parameters(tester, **{"estimator.lag_span": 0.4})
        assert r.successful
        d = tester.wait_diagnostics(lambda d: "resets.parameters_changed" in d.get(f"{NODE}: samples", {}))
        assert d[f"{NODE}: samples"]["resets.parameters_changed"] == "1"
        assert "parameters changed (estimator.lag_span): estimator reset" in node.text()
    finally:
        assert node.stop() == 0


@pytest.mark.parametrize("arg,needle", [
    ("estimator.window:=hann", "estimator.window"),
    ("models.enabled:=[CZ,CQ]", "CQ"),
    ("aircraft:=concorde", "concorde"),
])
def test_invalid_start_up_parameters_stop_the_node_with_the_reason(tmp_path, arg, needle):
    node = NodeProcess(tmp_path, "--params-file", T2, "-p", arg)
    code = node.proc.wait(30)
    node.stop()
    assert code == 2
    assert needle in node.text() and "invalid configuration" in node.text()


def test_reset_and_enable_services(tmp_path, tester):
    # 10 lags: CZ publishes from its 23rd sample on (the publication rule: 2 x 10 lags + 3
    # parameters), so each maneuver below, 2 s at 50 Hz at least, gives it over 50 estimates.
    node = _node(tmp_path, "-p", "estimator.lag_span:=0.2")
    try:
        tester.wait_connected()
        seq = _synthetic(10**18, 3.0, bad=False)
        tester.publish_all(seq)
        est = _arrays(tester, "CZ", "estimates")
        assert tester.spin_until(lambda: len(est) > 50)
        r = _call(tester, SetBool, "enable", SetBool.Request(data=False))
        assert r.success and "disabled" in r.message
        disabled = (10**18 + 3 * 10**9, 10**18 + 5 * 10**9)  # the stamps of the maneuver sent while disabled
        tester.publish_all(_synthetic(disabled[0], 2.0, bad=False))
        d = tester.wait_diagnostics(
            lambda d: int(d.get(f"{NODE}: samples", {}).get("samples_rejected.estimation_disabled", 0)) >= 95
        )
        assert d[f"{NODE}: samples"]["enabled"] == "False"
        r = _call(tester, Trigger, "reset", Trigger.Request())
        assert r.success
        assert _call(tester, SetBool, "enable", SetBool.Request(data=True)).success
        tester.publish_all(_synthetic(disabled[1], 2.0, bad=False))
        d = tester.wait_diagnostics(lambda d: d.get(f"{NODE}: samples", {}).get("resets.service") == "1")
        assert tester.spin_until(lambda: sum(_stamp(m) >= disabled[1] for m in est) > 50)
        # Nothing was estimated while disabled. Judged by the samples' stamps, not by counting
        # at some moment: the first maneuver's last outputs may still be arriving when the node
        # is disabled, and any output of the disabled span would have come before these.
        assert not [_stamp(m) for m in est if disabled[0] <= _stamp(m) < disabled[1]]
        # After the reset the estimator restarted: it re-initialized on the new samples only.
        assert int(d[f"{NODE}: model CZ"]["samples"]) < 120
        # ~/reset clears every input state: data older than anything seen (a replay started
        # over, without /clock) is accepted again, none of it out of order.
        _wait_received(tester, [("imu", None)] * (600 + 400 + 400))
        assert _call(tester, Trigger, "reset", Trigger.Request()).success
        before = len(est)
        tester.publish_all(_synthetic(10**18 - 60 * 10**9, 2.0, bad=False))
        d = tester.wait_diagnostics(lambda d: d.get(f"{NODE}: samples", {}).get("resets.service") == "2"
                                    and d[f"{NODE}: inputs"].get("imu.received") == str(600 + 400 + 400 + 400))
        assert tester.spin_until(lambda: len(est) > before + 30)
        inputs = d[f"{NODE}: inputs"]
        assert not any(k.endswith(".rejected.out_of_order") for k in inputs), inputs
    finally:
        assert node.stop() == 0


def test_state_file_saves_on_shutdown_and_resumes(tmp_path, tester, bag):
    state = tmp_path / "state.npz"
    half = len(bag) // 2
    node = _node(tmp_path, "-p", f"state_file:={state}", *_ros_params(NO_EXPIRY), name="first")
    try:
        tester.wait_connected()
        tester.publish_all([(k, to_rclpy(k, m)) for k, _s, m in bag[:half]])
        stamps = tester.outputs[f"/{NODE}/sample_stamp"]
        first = Pipeline(_t2_config(NO_EXPIRY))
        n1 = sum(len(feed(first, k, m)) for k, _s, m in bag[:half])
        assert tester.spin_until(lambda: len(stamps) >= n1)
    finally:
        assert node.stop() == 0
    assert state.exists()
    # Offline expectation: the saved estimator continues on the second half.
    first.save_state(tmp_path / "expected.npz")
    resumed = Pipeline(_t2_config(NO_EXPIRY))
    resumed.load_state(tmp_path / "expected.npz")
    outs = [o for k, _s, m in bag[half:] for o in feed(resumed, k, m)]

    for lst in tester.outputs.values():
        lst.clear()
    node = _node(tmp_path, "-p", f"state_file:={state}", *_ros_params(NO_EXPIRY), name="second")
    try:
        tester.wait_connected()
        d = tester.wait_diagnostics(lambda d: f"{NODE}: samples" in d)
        assert d[f"{NODE}: samples"]["state_file"].startswith(f"resumed from {state}")
        tester.publish_all([(k, to_rclpy(k, m)) for k, _s, m in bag[half:]])
        est, cz = _arrays(tester, "Cm", "standard_errors"), _arrays(tester, "CZ", "estimates")
        last = outs[-1].stamp_ns
        # Each topic's array of the last sample (the topics arrive independently).
        assert tester.spin_until(lambda: est and cz and _stamp(est[-1]) == last and _stamp(cz[-1]) == last)
        np.testing.assert_allclose(np.array(est[-1].data), outs[-1].se[1, :4], rtol=1e-9)
        np.testing.assert_allclose(np.array(cz[-1].data), outs[-1].theta[0, :3], rtol=1e-9)
    finally:
        assert node.stop() == 0
    # Another configuration ignores the file, says so, and keeps it: renamed aside, never
    # overwritten by the fresh state saved at shutdown.
    saved = state.read_bytes()
    node = _node(tmp_path, "-p", f"state_file:={state}", "-p", "estimator.lag_span:=0.14", name="third")
    try:
        tester.wait_connected(outputs=False)
        d = tester.wait_diagnostics(lambda d: f"{NODE}: samples" in d)
        status = d[f"{NODE}: samples"]["state_file"]
        assert "ignored" in status and "another aircraft, model or estimator configuration" in status
    finally:
        assert node.stop() == 0
    (aside,) = tmp_path.glob("state.npz.rejected-*")
    assert f"kept as {aside}" in status and aside.read_bytes() == saved
    assert load_state(state, _t2_config({"estimator.lag_span": 0.14}).fingerprint()).samples_used == 0


def _crafted_state(path):
    """A state file whose meta is a JSON list: it crashed start-up with a traceback before."""
    with zipfile.ZipFile(path, "w") as zf:
        buf = io.BytesIO()
        np.lib.format.write_array(buf, np.array(json.dumps([1, 2, 3])))
        zf.writestr("meta.npy", buf.getvalue())
    return path.read_bytes()


def test_a_refused_state_file_is_kept_and_the_node_starts(tmp_path, tester):
    """A crafted state file is refused with one diagnostic, renamed aside (never overwritten),
    and the node estimates from scratch; at shutdown the fresh state is written through a new
    exclusive temporary file: planted temporary names that are symlinks are not followed."""
    state = tmp_path / "state.npz"
    crafted = _crafted_state(state)
    victim = tmp_path / "victim.txt"
    victim.write_text("precious")
    for planted in ("state.npz.tmp", ".state.npz.tmp", "state.npz.new"):
        os.symlink(victim, tmp_path / planted)
    node = _node(tmp_path, "-p", f"state_file:={state}", *_ros_params(NO_EXPIRY), name="crafted")
    try:
        tester.wait_connected()
        d = tester.wait_diagnostics(lambda d: f"{NODE}: samples" in d)
        status = d[f"{NODE}: samples"]["state_file"]
        assert status.startswith(f"state file ignored: {state}: field 'meta' must be a JSON object, found a list")
        (aside,) = tmp_path.glob("state.npz.rejected-*")
        assert status.endswith(f"kept as {aside}; a fresh state will be saved to {state}")
        assert aside.read_bytes() == crafted and not state.exists()
        tester.publish_all(_synthetic(10**18, 3.0, bad=False))
        est = _arrays(tester, "CZ", "estimates")
        assert tester.spin_until(lambda: len(est) > 20), node.text()
    finally:
        assert node.stop() == 0, node.text()
    assert "Traceback" not in node.text() and "kept as" in node.text()
    assert victim.read_text() == "precious" and aside.read_bytes() == crafted
    assert not state.is_symlink() and load_state(state, _t2_config(NO_EXPIRY).fingerprint()).samples_used > 20


def _wait_text(node, needle, timeout=60.0):
    deadline = time.monotonic() + timeout
    while needle not in node.text():
        assert time.monotonic() < deadline, f"{needle!r} never logged:\n{node.text()}"
        time.sleep(0.1)


def test_a_second_node_with_the_same_name_and_state_file_is_named_and_keeps_off_the_file(tmp_path, tester, bag):
    """Two nodes /rls_estimator on one domain: each warns and reports ERROR; a consumer does
    receive every sample twice; the second refuses the first's state file in one line (the
    lock) instead of renaming it aside, and the file keeps the first's configuration."""
    state = tmp_path / "state.npz"
    lock = tmp_path / ".state.npz.lock"
    args = ["-p", f"state_file:={state}", "-p", "state_save_period:=0.5", *_ros_params(NO_EXPIRY)]
    first = _node(tmp_path, *args, name="first")
    second = None
    try:
        tester.wait_connected()
        deadline = time.monotonic() + 30
        while not state.exists():
            assert time.monotonic() < deadline, first.text()
            time.sleep(0.1)
        second = _node(tmp_path, *args, "-p", "estimator.lag_span:=0.14", name="second")  # 7 lags at 50 Hz
        assert tester.spin_until(lambda: all(p.get_subscription_count() >= 2 for p in tester.pubs.values()), 30)
        warning = "1 other node(s) named /rls_estimator on the ROS graph: their outputs mix with this node's on "
        for node in (first, second):
            _wait_text(node, warning)
        assert ("[ERROR] [" in second.text() and f"state file refused: {state}: in use: its lock {lock} is held by "
                f"process {first.proc.pid} (another node estimating with it); give each node its own state_file; "
                "running without a state file" in second.text())
        d = tester.wait_diagnostics(lambda d: d.get(f"{NODE}: samples", {}).get("level") == 2)
        assert d[f"{NODE}: samples"]["message"].startswith(warning)
        assert d[f"{NODE}: samples"]["nodes_with_this_name"] == "2"
        half = bag[: len(bag) // 4]
        n = len(run_pipeline(half, _t2_config(NO_EXPIRY)).outputs)
        tester.spin_until(lambda: False, 1.0)  # the second node's outputs matched too
        tester.publish_all([(k, to_rclpy(k, m)) for k, _s, m in half])
        stamps = tester.outputs[f"/{NODE}/sample_stamp"]
        assert tester.spin_until(lambda: len(stamps) >= 2 * n, 60)
        tester.spin_until(lambda: False, 0.5)
        counts = Counter(s.stamp.sec * 10**9 + s.stamp.nanosec for s in stamps)
        assert len(counts) == n and set(counts.values()) == {2}  # every sample twice
    finally:  # both stopped whatever happened, before either exit status is judged
        stopped = [(node, node.stop()) for node in (second, first) if node is not None]
    for node, code in stopped:
        assert code == 0, node.text()
    assert "Traceback" not in first.text() + second.text()
    assert sorted(p.name for p in tmp_path.iterdir() if not p.name.endswith(".log")) == ["state.npz"]
    assert load_state(state, _t2_config(NO_EXPIRY).fingerprint()).samples_used == n


def test_a_state_file_that_is_a_fifo_is_refused_at_once_and_the_node_runs(tmp_path, tester):
    fifo = tmp_path / "state.npz"
    os.mkfifo(fifo)
    node = _node(tmp_path, "-p", f"state_file:={fifo}", *_ros_params(NO_EXPIRY))
    try:
        tester.wait_connected()  # start-up used to block in open() here, for ever
        d = tester.wait_diagnostics(lambda d: f"{NODE}: samples" in d)
        refused = (f"state file refused: {fifo}: is a FIFO, not a regular file (it is not opened, renamed or "
                   "replaced); set state_file to a file's path; running without a state file")
        assert d[f"{NODE}: samples"]["state_file"] == refused
        tester.publish_all(_synthetic(10**18, 3.0, bad=False))
        est = _arrays(tester, "CZ", "estimates")
        assert tester.spin_until(lambda: len(est) > 20), node.text()
    finally:
        assert node.stop() == 0, node.text()
    said = [line for line in node.text().splitlines() if "[ERROR]" in line or "[WARN]" in line]
    assert len(said) == 1 and said[0].startswith("[ERROR]") and said[0].endswith(f"[{NODE}]: {refused}"), said
    assert node.text().count(refused) == 1 and stat.S_ISFIFO(os.lstat(fifo).st_mode)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["node.log", "state.npz"]


def test_a_late_subscriber_gets_the_latest_sample_at_once_and_volatile_ones_still_match(tmp_path, tester, bag):
    """Outputs are transient local: a display that joins after the node published gets the
    newest sample without waiting for the next; the tester's volatile subscribers match and
    receive every sample as before."""
    from rclpy.qos import QoSDurabilityPolicy, QoSHistoryPolicy, QoSProfile, QoSReliabilityPolicy
    from std_msgs.msg import Float64MultiArray, Header

    node = _node(tmp_path, *_ros_params(NO_EXPIRY))
    late = None
    try:
        tester.wait_connected()
        part = bag[: len(bag) // 3]
        offline = run_pipeline(part, _t2_config(NO_EXPIRY)).outputs
        tester.publish_all([(k, to_rclpy(k, m)) for k, _s, m in part])
        stamps = tester.outputs[f"/{NODE}/sample_stamp"]
        assert tester.spin_until(lambda: len(stamps) >= len(offline), 60)
        assert [s.stamp.sec * 10**9 + s.stamp.nanosec for s in stamps] == [o.stamp_ns for o in offline]
        late = rclpy.create_node("late_display")
        qos = QoSProfile(depth=1, history=QoSHistoryPolicy.KEEP_LAST, reliability=QoSReliabilityPolicy.RELIABLE,
                         durability=QoSDurabilityPolicy.TRANSIENT_LOCAL)
        got: dict[str, list] = {"stamp": [], "estimates": []}
        late.create_subscription(Header, f"/{NODE}/sample_stamp", got["stamp"].append, qos)
        late.create_subscription(Float64MultiArray, f"/{NODE}/CZ/estimates", got["estimates"].append, qos)
        last_cz = [o for o in offline if o.ready[0]][-1]

        def newest_arrived():
            return (got["stamp"] and got["estimates"] and _stamp(got["estimates"][-1]) == last_cz.stamp_ns
                    and got["stamp"][-1].stamp.sec * 10**9 + got["stamp"][-1].stamp.nanosec == offline[-1].stamp_ns)

        deadline = time.monotonic() + 30  # no new sample is published meanwhile: only the kept ones arrive
        while not newest_arrived() and time.monotonic() < deadline:
            rclpy.spin_once(late, timeout_sec=0.1)
        assert newest_arrived(), f"the late subscriber got {len(got['stamp'])} stamps, not the newest"
        np.testing.assert_array_equal(np.array(got["estimates"][-1].data), last_cz.theta[0, :3])
        kept = [s.stamp.sec * 10**9 + s.stamp.nanosec for s in got["stamp"]]
        assert kept == sorted(set(kept)) and set(kept) <= {o.stamp_ns for o in offline}
    finally:
        if late is not None:
            late.destroy_node()
        assert node.stop() == 0, node.text()


def test_sim_time_backwards_jump_resets(tmp_path, tester):
    node = _node(tmp_path, "-p", "use_sim_time:=true")
    clock = tester.node.create_publisher(Clock, "/clock", 10)
    try:
        tester.wait_connected()
        assert tester.spin_until(lambda: clock.get_subscription_count() >= 1)

        def tick(sec):
            m = Clock()
            m.clock.sec = sec
            clock.publish(m)

        for s in range(100, 103):
            tick(s)
            tester.spin_until(lambda: False, 0.2)
        seq = _synthetic(100 * 10**9, 2.0, bad=False)
        tester.publish_all(seq)
        # The node takes /clock and each input from its own queue: let it take every message
        # before time jumps back, or the rest would be stamped after the jump.
        _wait_received(tester, seq)
        tick(103)
        tick(50)  # the bag restarted: time jumps back
        # Wait until the node's clock went back (its diagnostics are stamped with it), so the
        # jump is handled before the new data arrives.
        assert tester.spin_until(lambda: any(a.header.stamp.sec in (50, 51) for a in tester.diagnostics), 30)
        formed = int(tester.latest_diagnostics()[f"{NODE}: samples"]["samples_formed"])
        # The stamps follow the clock back: a new run, whose older stamps are all accepted.
        tick(51)
        tester.publish_all(_synthetic(50 * 10**9, 1.0, bad=False))
        d = tester.wait_diagnostics(lambda d: d.get(f"{NODE}: samples", {}).get("resets.time_jumped_backwards") == "1"
                                    and int(d[f"{NODE}: samples"]["samples_formed"]) > formed + 40)
        assert d[f"{NODE}: inputs"].get("imu.rejected.out_of_order") is None
        assert "resets.stamps_jumped_backwards" not in d[f"{NODE}: samples"]
    finally:
        assert node.stop() == 0


def test_the_console_script_runs_the_node_module(monkeypatch):
    """setup.py's ``estimator_node`` is cli.estimator_node, which hands over to ros.node.main
    (the module the tests run as ``python -m rls_uncertainty.ros.node``)."""
    import rls_uncertainty.ros.node
    from rls_uncertainty.cli import estimator_node

    assert "estimator_node = rls_uncertainty.cli:estimator_node" in (ROOT / "setup.py").read_text()
    monkeypatch.setattr(rls_uncertainty.ros.node, "main", lambda: 7)
    assert estimator_node() == 7


def test_play_command_drives_the_live_node_to_the_replay_numbers(tmp_path, tester, bag):
    """`rls-uncertainty play` (with /clock, the node on use_sim_time) reproduces `replay`. The
    node is started as the README advises for replays (a deep reliable queue and a long
    buffer: a node slowed by a busy machine delays messages instead of expiring them)."""
    node = _node(tmp_path, "-p", "use_sim_time:=true", *_ros_params(NO_EXPIRY))
    try:
        tester.wait_connected()
        offline = run_pipeline(bag, _t2_config(NO_EXPIRY))
        player = subprocess.run(
            [sys.executable, "-m", "rls_uncertainty.cli", "play", str(BUNDLED), "--rate", "4", "--subscribers", "1",
             "--wait", "60"],
            capture_output=True, text=True, timeout=120, cwd=ROOT,
        )
        assert player.returncode == 0, player.stderr
        assert "published 4920 messages" in player.stderr
        stamps = tester.outputs[f"/{NODE}/sample_stamp"]
        assert tester.spin_until(lambda: len(stamps) >= len(offline.outputs), 20)
        last = offline.outputs[-1]
        np.testing.assert_allclose(np.array(_arrays(tester, "Cm", "estimates")[-1].data), last.theta[1, :4], rtol=1e-9)
        np.testing.assert_allclose(np.array(_arrays(tester, "CZ", "standard_errors")[-1].data), last.se[0, :3],
                                   rtol=1e-9)
    finally:
        assert node.stop() == 0, node.text()


def test_readme_demo_command_matches_the_offline_replay():
    run = subprocess.run([sys.executable, "-m", "rls_uncertainty.cli", "demo"], capture_output=True, text=True,
                         timeout=180, cwd=ROOT)
    assert run.returncode == 0, run.stdout + run.stderr
    assert "difference between the live node and the offline replay: 0.0e+00" in run.stdout
    assert "Cm_q" in run.stdout


def test_default_sensor_qos_receives_and_a_qos_mismatch_is_diagnosed(tmp_path, tester, bag):
    from rclpy.qos import qos_profile_sensor_data
    from sensor_msgs.msg import Imu

    # Default QoS (best effort): a reliable publisher is compatible, estimates arrive.
    node = NodeProcess(tmp_path, "--params-file", T2, "-p", "diagnostics_period:=0.2", *NO_SHEDDING, name="default_qos")
    try:
        tester.wait_connected()
        tester.publish_all([(k, to_rclpy(k, m)) for k, _s, m in bag[:2000]])
        est = _arrays(tester, "CZ", "estimates")
        assert tester.spin_until(lambda: len(est) > 100), node.text()
    finally:
        assert node.stop() == 0
    # Reliable inputs and a best-effort IMU publisher: incompatible, reported in diagnostics.
    node = _node(tmp_path, "-p", "topics.imu:=imu_best_effort", name="mismatch")
    best_effort = tester.node.create_publisher(Imu, "/imu_best_effort", qos_profile_sensor_data)
    try:
        d = tester.wait_diagnostics(lambda d: "incompatible QoS" in d.get(f"{NODE}: inputs", {}).get("message", ""),
                                    timeout=20)
        assert d[f"{NODE}: inputs"]["imu.publishers"] == "0"
        assert best_effort.get_subscription_count() == 0
    finally:
        assert node.stop() == 0


@pytest.mark.parametrize("sim_time", [False, True], ids=["no_clock", "clock"])
def test_a_bag_played_twice_gives_the_offline_numbers_twice(tmp_path, tester, bag, sim_time):
    """A bag-replay integration test loops the bundled bag: both plays, back to back with no
    wait, reach the node (without /clock; or with /clock and use_sim_time, the clock jumping
    back between them), and each gives exactly the offline replay's numbers. In the first play
    an IMU message stamped three years ahead changes nothing."""
    args = [*_ros_params(NO_EXPIRY)] + (["-p", "use_sim_time:=true"] if sim_time else [])
    node = _node(tmp_path, *args)
    clock = tester.node.create_publisher(Clock, "/clock", 10) if sim_time else None
    try:
        tester.wait_connected()
        offline = run_pipeline(bag, _t2_config(NO_EXPIRY)).outputs
        msgs = [(k, to_rclpy(k, m)) for k, _s, m in bag]
        i = next(j for j, (k, _m) in enumerate(msgs) if k == "imu" and j > len(msgs) // 2)
        future = to_rclpy("imu", bag[i][2])
        future.header.stamp.sec += 3 * 365 * 86400
        first_play = [*msgs[:i], ("imu", future), *msgs[i:]]

        def tick(stamp):
            m = Clock()
            m.clock.sec, m.clock.nanosec = stamp.sec, stamp.nanosec
            clock.publish(m)

        if sim_time:
            assert tester.spin_until(lambda: clock.get_subscription_count() >= 1)
            tick(msgs[0][1].header.stamp)
            assert tester.spin_until(lambda: any(a.header.stamp.sec > 0 for a in tester.diagnostics), 30)
            tester.publish_all(first_play)
            tick(msgs[-1][1].header.stamp)
            tick(msgs[0][1].header.stamp)  # the replay restarts: /clock jumps back
            tester.publish_all(msgs)
        else:
            tester.publish_all(first_play + msgs)
        stamps = tester.outputs[f"/{NODE}/sample_stamp"]
        cm = _arrays(tester, "Cm", "standard_errors")
        n_cm = sum(o.ready[1] for o in offline)
        assert tester.spin_until(lambda: len(stamps) >= 2 * len(offline) and len(cm) >= 2 * n_cm, 60), node.text()
        tester.spin_until(lambda: False, 0.5)  # nothing more arrives
        assert [s.stamp.sec * 10**9 + s.stamp.nanosec for s in stamps] == 2 * [o.stamp_ns for o in offline]
        for model, j, n in (("CZ", 0, 3), ("Cm", 1, 4)):
            for suffix, field in (("estimates", "theta"), ("standard_errors", "se"),
                                  ("standard_errors_conventional", "se_conventional")):
                got = [np.array(m.data) for m in _arrays(tester, model, suffix)]
                want = [getattr(o, field)[j, :n] for o in offline if o.ready[j]]
                assert len(got) == 2 * len(want)
                np.testing.assert_array_equal(np.array(got), np.array(2 * want), err_msg=f"{model} {suffix}")
        d = tester.wait_diagnostics(lambda d: d.get(f"{NODE}: inputs", {}).get("imu.received") == str(2 * 2400 + 1))
        samples, inputs = d[f"{NODE}: samples"], d[f"{NODE}: inputs"]
        assert inputs["imu.rejected.stamp_jump"] == "1"
        resets = {k: v for k, v in samples.items() if k.startswith("resets.")}
        assert resets in ({"resets.stamps_jumped_backwards": "1"}, {"resets.time_jumped_backwards": "1"}), resets
    finally:
        assert node.stop() == 0, node.text()


def test_the_consumer_example_pairs_every_array_by_stamp(tmp_path, tester, bag):
    """examples/consumer.py against the node on the bundled bag: one sample event per Cm
    sample, with the estimates, standard errors and convergence flags of that very sample,
    and one covariance event per decimated sample, paired with its own sample's estimates."""
    node = _node(tmp_path, *_ros_params(NO_EXPIRY))
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(filter(None, [str(ROOT), os.environ.get("PYTHONPATH")])))
    consumer = subprocess.Popen([sys.executable, str(ROOT / "examples" / "consumer.py"), "--model", "Cm", "--json",
                                 "--idle", "5"], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)
    try:
        tester.wait_connected()
        topics = [f"/{NODE}/Cm/{k}" for k in ("estimates", "standard_errors", "converged", "covariance")]
        assert tester.spin_until(lambda: all(tester.node.count_subscribers(t) >= 2 for t in topics), 30)
        tester.spin_until(lambda: False, 0.5)
        offline = run_pipeline(bag, _t2_config(NO_EXPIRY))
        tester.publish_all([(k, to_rclpy(k, m)) for k, _s, m in bag])
        out, err = consumer.communicate(timeout=180)
    finally:
        if consumer.poll() is None:
            consumer.kill()
            consumer.communicate()
        assert node.stop() == 0, node.text()
    assert consumer.returncode == 0, err
    events = [json.loads(line) for line in out.splitlines()]
    samples = [e for e in events if e["event"] == "sample"]
    covs = [e for e in events if e["event"] == "covariance"]
    ready = [o for o in offline.outputs if o.ready[1]]
    assert [e["stamp"] for e in samples] == [o.stamp_ns for o in ready], err
    for e, o in zip(samples, ready, strict=True):
        assert e["names"] == ["Cm_0", "Cm_alpha", "Cm_q", "Cm_delta_e"]
        assert e["estimates"] == o.theta[1, :4].tolist() and e["standard_errors"] == o.se[1, :4].tolist()
        assert e["converged"] == o.converged[1, :4].astype(float).tolist()
    by_stamp = {o.stamp_ns: o for o in ready}
    assert sorted(e["stamp"] for e in covs) == [o.stamp_ns for o in ready if o.covariance is not None]
    for e in covs:
        o = by_stamp[e["stamp"]]
        assert e["estimates"] == o.theta[1, :4].tolist()
        np.testing.assert_array_equal(np.array(e["covariance"]), o.covariance[0, 1, :4, :4])
    assert f"{len(samples)} samples, 0 incomplete" in err


def test_the_consumer_pairing_does_not_depend_on_the_order_across_topics(bag):
    """No DDS: each topic in order, the topics interleaved at random; the same events."""
    import importlib.util
    import random

    spec = importlib.util.spec_from_file_location("consumer_example", ROOT / "examples" / "consumer.py")
    example = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(example)
    Pairing = example.Pairing
    offline = run_pipeline(bag[:2500], _t2_config())
    names = ["Cm_0", "Cm_alpha", "Cm_q", "Cm_delta_e"]
    topics: dict[str, list] = {k: [] for k in ("estimates", "standard_errors", "converged", "covariance")}
    for o in offline.outputs:
        if o.ready[1]:
            topics["estimates"].append((o.stamp_ns, o.theta[1, :4].tolist()))
            topics["standard_errors"].append((o.stamp_ns, o.se[1, :4].tolist()))
            topics["converged"].append((o.stamp_ns, o.converged[1, :4].astype(float).tolist()))
            if o.covariance is not None:
                topics["covariance"].append((o.stamp_ns, o.covariance[0, 1, :4, :4].ravel().tolist()))
    rng = random.Random(3)
    pairing, events = Pairing(), []
    queues = {k: list(v) for k, v in topics.items()}
    while any(queues.values()):
        kind = rng.choice([k for k, q in queues.items() if q])
        stamp, data = queues[kind].pop(0)
        events += pairing.add(kind, names, stamp, data)
    samples = sorted(s for e, s, _ in events if e == "sample")
    assert samples == [s for s, _ in topics["estimates"]]
    assert sorted(s for e, s, _ in events if e == "covariance") == [s for s, _ in topics["covariance"]]
    theta = dict(topics["estimates"])
    assert all(rec["estimates"] == theta[s] for e, s, rec in events)
    assert pairing.dropped == 0 and len(pairing.pending) <= pairing.keep


def test_fit_topics_reach_a_late_subscriber_and_an_unidentifiable_model_is_said_once(tmp_path, tester, bag):
    """C_Z given sideslip, which the longitudinal maneuver never moves: the node logs one WARN
    line naming beta (throttled), its model status says the same, and C_m publishes ~/Cm/fit and
    ~/Cm/identifiability every period, transient local: a subscriber that joins after the data
    gets the latest at once, and it holds what the offline pipeline makes of the same messages."""
    from rclpy.qos import QoSDurabilityPolicy, QoSHistoryPolicy, QoSProfile, QoSReliabilityPolicy
    from std_msgs.msg import Float64MultiArray

    from rls_uncertainty.datapath.outputs import OutputLayout
    from rls_uncertainty.offline.bags import typestore

    params = tmp_path / "beta.yaml"
    params.write_text("/**:\n  ros__parameters:\n    models:\n      CZ: ['1', alpha, beta, delta_e]\n"
                      "    inputs:\n      buffer_duration: 60.0\n")
    node = _node(tmp_path, "--params-file", str(params))
    offline = Pipeline(_t2_config({"models.CZ": ["1", "alpha", "beta", "delta_e"], **NO_EXPIRY}))
    for kind, _s, msg in bag:
        feed(offline, kind, msg)
    want = "CZ: regressor beta not excited (std 0 rad in "
    try:
        tester.wait_connected()
        tester.publish_all([(k, to_rclpy(k, m)) for k, _s, m in bag])
        d = tester.wait_diagnostics(lambda d: d.get(f"{NODE}: samples", {}).get("samples_used")
                                    == str(offline.bank.k), timeout=60)
        model = d[f"{NODE}: model CZ"]
        assert model["level"] == 1 and model["message"].startswith("initializing: regressor beta not excited")
        tester.wait_diagnostics(lambda d: True)  # one period more: the fit of the last sample is out
        qos = QoSProfile(depth=1, reliability=QoSReliabilityPolicy.RELIABLE,
                         durability=QoSDurabilityPolicy.TRANSIENT_LOCAL, history=QoSHistoryPolicy.KEEP_LAST)
        late = {}
        for suffix in ("fit", "identifiability"):
            tester.node.create_subscription(Float64MultiArray, f"/{NODE}/Cm/{suffix}",
                                            lambda msg, s=suffix: late.__setitem__(s, msg), qos)
        assert tester.spin_until(lambda: len(late) == 2, 20), node.text()
    finally:
        assert node.stop() == 0, node.text()
    layout, store = OutputLayout.of(offline), typestore()
    expected = {layout.fit_topics[i][0]: store.deserialize_cdr(raw, "std_msgs/msg/Float64MultiArray")
                for i, raw in layout.encode_fit(offline)}
    assert sorted(expected) == ["Cm/fit", "Cm/identifiability"]  # C_Z never initialized: nothing
    for suffix, msg in late.items():
        exp = expected[f"Cm/{suffix}"]
        assert [(d.label, d.size, d.stride) for d in msg.layout.dim] == \
            [(d.label, d.size, d.stride) for d in exp.layout.dim]
        np.testing.assert_array_equal(np.array(msg.data), exp.data)  # one machine: bit for bit
    warnings = [line for line in node.text().splitlines() if want in line]
    assert len(warnings) == 1 and "WARN" in warnings[0], node.text()


def test_an_input_topic_nobody_publishes_is_logged_once_with_the_likely_topic(tmp_path, tester):
    """topics.imu misspelt, the tester publishing on /imu and the other inputs: one WARN line
    after diagnostics_window seconds (1 s here: 5 s, the least) naming /imu_typo, its parameter
    and type, and /imu as the likely topic; not repeated while the silence lasts (counted in
    diagnostics reports, 0.2 s apart). A publisher that comes and goes re-arms it; one whose QoS does not match is named
    as such. The streams that have publishers are never named."""
    from rclpy.qos import qos_profile_sensor_data
    from sensor_msgs.msg import Imu

    node = _node(tmp_path, "-p", "topics.imu:=imu_typo", "-p", "diagnostics_window:=1.0")
    head = "no publisher on /imu_typo (topics.imu, sensor_msgs/msg/Imu) for 5 s: the estimation waits for imu; "
    remap = head + "/imu has 1 publisher(s) of that type: is it the one meant (topics.imu or a remap)?"
    qos = head + "1 publisher(s) on it do not match the subscription's QoS (qos.reliable=True)"

    def said():
        return [line.split("]: ", 1)[1] for line in node.text().splitlines() if "no publisher on" in line]

    def reports_later(n):  # n more /diagnostics reports of the node: time passes by the node's clock
        tester.diagnostics.clear()
        assert tester.spin_until(lambda: len(tester.diagnostics) >= n, 60), node.text()

    try:
        others = [pub for kind, pub in tester.pubs.items() if kind != "imu"]
        assert tester.spin_until(lambda: all(pub.get_subscription_count() == 1 for pub in others), 60), node.text()
        assert tester.spin_until(lambda: len(said()) >= 1, 60), node.text()
        reports_later(50)  # two silences more
        assert said() == [remap] and "[WARN]" in node.text().split(remap)[0].splitlines()[-1], node.text()
        typo = tester.node.create_publisher(Imu, "/imu_typo", 10)  # reliable: matches, and re-arms the watch
        assert tester.spin_until(lambda: typo.get_subscription_count() == 1, 60)
        reports_later(2)
        tester.node.destroy_publisher(typo)
        best_effort = tester.node.create_publisher(Imu, "/imu_typo", qos_profile_sensor_data)
        assert tester.spin_until(lambda: len(said()) >= 2, 60), node.text()
        reports_later(50)
        assert said() == [remap, qos] and best_effort.get_subscription_count() == 0, node.text()
    finally:
        assert node.stop() == 0, node.text()


def test_silent_inputs_are_due_once_per_silence_and_only_when_needed():
    from rls_uncertainty.ros.input_watch import SilentInputs

    watch = SilentInputs()
    assert watch.due(0.0, {"imu": 0}, ("imu",), 0.1) == [] and watch.due(4.9, {"imu": 0}, ("imu",), 0.1) == []
    assert watch.due(5.0, {"imu": 0}, ("imu",), 0.1) == ["imu"]  # never less than 5 s: discovery takes time
    watch = SilentInputs()
    required = ("imu", "airspeed")
    silent = {"imu": 0, "airspeed": 1, "thrust": 0}  # thrust not needed: never said
    assert watch.due(0.0, silent, required, 10.0) == []
    assert watch.due(9.9, silent, required, 10.0) == []
    assert watch.due(10.0, silent, required, 10.0) == ["imu"]
    assert watch.due(500.0, silent, required, 10.0) == []  # once per silence
    assert watch.due(501.0, {**silent, "imu": 1}, required, 10.0) == []  # a publisher came: re-armed
    assert watch.due(502.0, silent, required, 10.0) == []
    assert watch.due(512.0, {**silent, "airspeed": 0}, required, 10.0) == ["imu"]  # 10 s since 502
    assert watch.due(522.0, {**silent, "airspeed": 0}, required, 10.0) == ["airspeed"]
    assert watch.due(600.0, silent, ("airspeed",), 10.0) == []  # imu no longer needed


def test_the_silent_input_line_names_the_topic_and_why():
    from rls_uncertainty.ros.input_watch import silent_text

    head = ("no publisher on /ns/air (topics.airspeed, geometry_msgs/msg/Vector3Stamped) for 10 s: the estimation "
            "waits for airspeed; ")
    assert silent_text("airspeed", "/ns/air", 10.0, 0, False, []) == head + "no topic of that type has a publisher"
    assert silent_text("airspeed", "/ns/air", 10.0, 2, True, [("/airspeed", 1)]) == (
        head + "2 publisher(s) on it do not match the subscription's QoS (qos.reliable=True)")
    others = [(f"/v{i}", i) for i in range(1, 6)]
    assert silent_text("airspeed", "/ns/air", 10.0, 0, False, others) == (
        head + "/v1 has 1 publisher(s), /v2 has 2 publisher(s), /v3 has 3 publisher(s) (and 2 more topics) of that "
        "type: is it the one meant (topics.airspeed or a remap)?")
