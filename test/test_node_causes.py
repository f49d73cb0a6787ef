"""The node names the transport or the clocks in /diagnostics when its measurements point
there: stamp gaps while it keeps up are "lost in transport?", a constant offset between the
streams' clocks is said with the measured offset. The inputs are the bundled maneuver played
in real time with its stamps moved to now (looped), so that arrival and stamp ages mean what
they mean live."""

from __future__ import annotations

import time

import pytest
import rclpy

from rls_uncertainty.datapath.outputs import NODE_NAME as NODE
from rls_uncertainty.offline.bags import read_inputs

from ros_harness import BUNDLED, T2, NodeProcess, RosTester, to_rclpy

pytestmark = pytest.mark.usefixtures("ros")

INPUTS = f"{NODE}: inputs"
LIVE = ("--params-file", T2, "-p", "qos.reliable:=true", "-p", "diagnostics_period:=0.2",
        "-p", "diagnostics_window:=2.0")


def _play_until(tester: RosTester, done, timeout: float, skip=lambda i, kind: False,
                shift_ns=lambda kind: 0) -> dict:
    """Publish the bundled maneuver in real time, stamped from now on (plus ``shift_ns(kind)``),
    looping it, leaving out the messages ``skip(index, kind)`` names, until the newest
    /diagnostics satisfies ``done`` (returned) or ``timeout`` seconds pass (fails)."""
    bag, _ = read_inputs(BUNDLED)
    first = bag[0][1]
    span = bag[-1][1] - first + 10**8  # the loop restarts 0.1 s after the last message
    messages = [(kind, stamp - first, to_rclpy(kind, m)) for kind, stamp, m in bag]
    t0, base, seen = time.monotonic(), time.time_ns(), 0
    deadline = t0 + timeout
    loop = 0
    while True:
        for i, (kind, offset, msg) in enumerate(messages):
            at = loop * span + offset
            while (left := t0 + at * 1e-9 - time.monotonic()) > 0:
                rclpy.spin_once(tester.node, timeout_sec=min(left, 0.01))
            if len(tester.diagnostics) > seen:
                seen = len(tester.diagnostics)
                diag = tester.latest_diagnostics()
                if done(diag):
                    return diag
            assert time.monotonic() < deadline, f"diagnostics never satisfied the condition; last: " \
                                                f"{tester.latest_diagnostics()}"
            if skip(i, kind):
                continue
            msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(base + at + shift_ns(kind), 10**9)
            tester.publish(kind, msg)
        loop += 1


def test_stamp_gaps_while_the_node_keeps_up_are_said_to_be_lost_in_transport(tmp_path):
    node = NodeProcess(tmp_path, *LIVE)
    tester = RosTester()
    try:
        tester.wait_connected()
        # Every tenth IMU message never sent: stamp gaps the node, keeping up, did not cause.
        d = _play_until(tester, lambda d: "lost in transport?" in d.get(INPUTS, {}).get("message", ""),
                        timeout=180.0, skip=lambda i, kind: kind == "imu" and i % 10 == 0)
        text = d[INPUTS]["message"]
        assert "imu missing about " in text and "(stamp gaps: lost in transport?)" in text, text
        assert "dropped while the node was behind" not in text and "different clocks" not in text, text
        assert not d[f"{NODE}: samples"]["message"].startswith("cannot keep up"), d
    finally:
        tester.close()
        assert node.stop() == 0, node.text()


def test_streams_stamped_by_clocks_seconds_apart_are_said_to_be_on_different_clocks(tmp_path):
    node = NodeProcess(tmp_path, *LIVE)
    tester = RosTester()
    try:
        tester.wait_connected()
        # Air data and surfaces stamped by a clock 4 s behind the IMU's (the inputs' 2 s buffer
        # cannot bridge it): no sample forms, and the offsets against arrival say why.
        d = _play_until(tester, lambda d: "different clocks: " in d.get(INPUTS, {}).get("message", ""),
                        timeout=180.0, shift_ns=lambda kind: 0 if kind == "imu" else -4 * 10**9)
        text = d[INPUTS]["message"]
        assert "different clocks?" not in text and "lost in transport" not in text, text
        said = text.split("different clocks: ", 1)[1]
        stream, _, seconds = said.split(" ")[:3]
        assert stream in ("airspeed", "dynamic_pressure", "control_surfaces"), said
        assert said.split(" ", 4)[4].startswith("behind imu's, against their arrival"), said
        assert 3.5 < float(seconds) < 4.5, said  # the 4 s shift, give or take the delivery
    finally:
        tester.close()
        assert node.stop() == 0, node.text()
