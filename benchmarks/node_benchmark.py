"""Drive the live estimator node over DDS and print latency, CPU use and dropped samples.

Three processes on loopback: the node (six models of Eq. 2, 50 lags), a publisher that
sends a synthetic six-degree-of-freedom maneuver in real time (IMU at --imu-rate, air data,
dynamic pressure and surfaces at --air-rate), and this process, which subscribes to the
sample stamp and each sample's last array (the node publishes only the topics someone
subscribes to). Latency is input to output: from the publication of the message that completes a
sample (the last stream to pass the sample time, ``lag`` samples later because of the
differentiator) to the reception of that sample's last output array.

    .venv/bin/python benchmarks/node_benchmark.py                      # 1 kHz IMU, 100 Hz air data
    .venv/bin/python benchmarks/node_benchmark.py --imu-rate 200 --air-rate 50
    .venv/bin/python benchmarks/node_benchmark.py --extreme --no-baseline  # more than the node can do
    .venv/bin/python benchmarks/node_benchmark.py --offline            # the data path alone, no DDS
    .venv/bin/python benchmarks/node_benchmark.py --floor              # what any rclpy node pays
    .venv/bin/python benchmarks/node_benchmark.py --intake-period 0.02 # inputs taken every 20 ms

``--extreme``: estimates at 1000 Hz with ``estimator.method: both`` and ``frequency.every: 1``
(1 kHz IMU): more work than one core does in real time. It prints the node's RSS, the last
``/diagnostics`` texts of the samples and inputs statuses verbatim, and what the node logged
about keeping up.

``--offline``: the node's data path alone on the same messages (serialized by rclpy), without
DDS, executor or other processes: CPU per output sample of decoding, of feeding with
estimation disabled and enabled, and of encoding. The live run prints the node's CPU by
thread (``main`` runs the executor and every callback).

``--floor``: instead of the estimator node, an rclpy node on the same executor with the same
input subscriptions, taking every message and doing nothing else (:func:`floor_node`; variants
``intake``, ``callbacks``, ``timer``): the CPU any rclpy node pays here for these inputs,
measured as the node's is, per output-sample period and by thread.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import math
import os
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
os.environ.setdefault("ROS_DOMAIN_ID", str(1 + os.getpid() % 100))

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
T0 = 1_800_000_000 * 10**9
MODELS = ("CX", "CY", "CZ", "Cl", "Cm", "Cn")


def signals(t: float):
    """Smooth, independent excitation of every regressor of Eq. 2."""
    s = math.sin
    return {
        "p": 0.2 * s(2.1 * t), "q": 0.1 * s(3.3 * t + 1), "r": 0.08 * s(1.7 * t + 2),
        "alpha": 0.08 + 0.03 * s(2.7 * t), "beta": 0.04 * s(1.9 * t + 0.5),
        "de": 0.05 * s(4.1 * t + 0.3), "da": 0.04 * s(3.7 * t + 1.1), "dr": 0.03 * s(2.3 * t + 2.2),
    }


def schedule(args) -> list[tuple[int, str]]:
    """The maneuver's messages, ``(stamp ns, kind)`` in publication order: IMU at imu_rate, the
    rest at air_rate (offset 1 ms)."""
    events = []
    n_imu = int(args.duration * args.imu_rate)
    events += [(T0 + int(round(k * 1e9 / args.imu_rate)), "imu") for k in range(n_imu)]
    n_air = int(args.duration * args.air_rate)
    for k in range(n_air):
        s = T0 + int(round(k * 1e9 / args.air_rate)) + 10**6
        # Thrust is needed by CX (Eq. 1a): at the air-data rate, since a slower stream would
        # hold every sample back until its next message (the node never extrapolates).
        events += [(s, "airspeed"), (s, "dynamic_pressure"), (s, "control_surfaces"), (s, "thrust")]
    events.sort()
    return events


def message(kind: str, stamp: int):
    """The rclpy message of ``kind`` stamped ``stamp`` (ns)."""
    from geometry_msgs.msg import Vector3Stamped, WrenchStamped
    from sensor_msgs.msg import FluidPressure, Imu, JointState

    x = signals((stamp - T0) * 1e-9)
    if kind == "imu":
        m = Imu()
        m.angular_velocity.x, m.angular_velocity.y, m.angular_velocity.z = x["p"], -x["q"], -x["r"]
        m.linear_acceleration.x = 0.5 + 3 * x["alpha"]
        m.linear_acceleration.y = -(2 * x["beta"] + x["dr"])
        m.linear_acceleration.z = 9.8 + 20 * x["alpha"] + 3 * x["de"]
    elif kind == "airspeed":
        m = Vector3Stamped()
        V = 60.0
        a, b = x["alpha"], x["beta"]
        m.vector.x = V * math.cos(a) * math.cos(b)
        m.vector.y = -V * math.sin(b)
        m.vector.z = -V * math.sin(a) * math.cos(b)
    elif kind == "dynamic_pressure":
        m = FluidPressure()
        m.fluid_pressure = 0.5 * 1.1 * 60.0**2
    elif kind == "control_surfaces":
        m = JointState()
        m.name = ["elevator", "aileron_left", "aileron_right", "rudder"]
        m.position = [x["de"], -x["da"], x["da"], x["dr"]]
    else:
        m = WrenchStamped()
        m.wrench.force.x = 4000.0
    m.header.stamp.sec, m.header.stamp.nanosec = divmod(stamp, 10**9)
    m.header.frame_id = "base_link"  # the node's inputs.frame_id
    return m


def publisher(args) -> None:
    """Publish the maneuver in real time; write (monotonic time, kind, stamp) to a file."""
    import rclpy
    from geometry_msgs.msg import Vector3Stamped, WrenchStamped
    from rclpy.qos import QoSHistoryPolicy, QoSProfile, QoSReliabilityPolicy
    from sensor_msgs.msg import FluidPressure, Imu, JointState

    rclpy.init()
    node = rclpy.create_node("bench_publisher")
    qos = QoSProfile(depth=1000, reliability=QoSReliabilityPolicy.RELIABLE, history=QoSHistoryPolicy.KEEP_LAST)
    types = {"imu": Imu, "airspeed": Vector3Stamped, "dynamic_pressure": FluidPressure,
             "control_surfaces": JointState, "thrust": WrenchStamped}
    pubs = {k: node.create_publisher(t, k, qos) for k, t in types.items()}
    while any(p.get_subscription_count() < 1 for p in pubs.values()):
        time.sleep(0.05)
    time.sleep(1.0)
    kinds = {"imu": 0, "airspeed": 1, "dynamic_pressure": 2, "control_surfaces": 3, "thrust": 4}
    events = schedule(args)
    log = np.zeros((len(events), 3))
    Path(args.log).with_suffix(".started").touch()  # (the floor run measures from here)
    start = time.monotonic()
    for i, (stamp, kind) in enumerate(events):
        due = start + (stamp - T0) * 1e-9
        left = due - time.monotonic()
        if left > 0:
            time.sleep(left)  # no busy wait: the publisher must not steal the node's core
        pubs[kind].publish(message(kind, stamp))
        log[i] = (time.monotonic(), kinds[kind], stamp - T0)
    np.save(args.log, log)
    time.sleep(1.0)
    node.destroy_node()
    rclpy.try_shutdown()


def offline(args) -> None:
    """The node's data path without DDS or executor, on this run's messages serialized by
    rclpy: CPU per output sample (``time.process_time``, best of ``--repeats``) of decoding
    (:mod:`.cdr`), of feeding with estimation disabled (judging, sampling, differentiating:
    the ``estimation_disabled`` path) and enabled (:func:`.inputs.feed`, what the node runs per
    message), and of encoding a sample's messages (:meth:`.outputs.OutputLayout.encode`)."""
    from rclpy.serialization import serialize_message

    from rls_uncertainty.datapath.cdr import decode
    from rls_uncertainty.datapath.inputs import MESSAGE_TYPES, feed
    from rls_uncertainty.datapath.outputs import OutputLayout
    from rls_uncertainty.datapath.pipeline import Pipeline
    from rls_uncertainty.settings.parameters import PARAMETERS, pipeline_config

    values = {p.name: p.default for p in PARAMETERS}
    values.update({"rate": args.rate, "estimator.lag_span": args.lag_span, "surfaces.elevator": ["elevator"],
                   "estimator.method": args.method})
    if args.method != "time":
        values["frequency.every"] = args.frequency_every
    config = pipeline_config(values)
    stamped = [(stamp, (MESSAGE_TYPES[kind], kind, serialize_message(message(kind, stamp))))
               for stamp, kind in schedule(args)]
    raws = [raw for _, raw in stamped]
    best: dict[str, float] = {}

    def timed(what: str, fn, *fn_args) -> Any:
        t0 = time.process_time()
        result = fn(*fn_args)
        best[what] = min(best.get(what, math.inf), time.process_time() - t0)
        return result

    def run(enabled: bool) -> list:
        pipeline, outs = Pipeline(config, enabled=enabled), []
        for msgtype, kind, raw in raws:
            outs += feed(pipeline, kind, decode(msgtype, raw))
        return outs

    def encode(outs: list, wanted: list[bool] | None) -> None:
        for out in outs:
            layout.encode(out, "base_link", wanted)

    layout = OutputLayout.of(Pipeline(config))
    two = [topic in ("sample_stamp", "Cn/standard_errors_conventional") for topic, _ in layout.topics]  # (live run's)
    outs: list = []
    for _ in range(args.repeats):
        timed("decode", lambda: [decode(msgtype, raw) for msgtype, _kind, raw in raws])
        timed("feed, estimation disabled", run, False)
        outs = timed("feed", run, True)
        timed("encode, 2 topics", encode, outs, two)
        timed(f"encode, {len(layout.topics)} topics", encode, outs, None)
    n = len(outs)
    print(f"node data path without DDS: {len(raws)} messages, {n} output samples, CPU per output sample "
          f"(best of {args.repeats}), ms:")
    for what, seconds in best.items():
        print(f"  {what:38s} {1e3 * seconds / n:.3f}")
    print(f"  (feed includes decoding; estimation is feed minus feed with estimation disabled: "
          f"{1e3 * (best['feed'] - best['feed, estimation disabled']) / n:.3f})")
    cpu, n_paced, period = paced_feed(args, Pipeline(config), stamped)
    print(f"  {'feed, paced as the node feeds live':38s} {1e3 * cpu / n_paced:.3f}  (one pass per {1e3 * period:g} ms "
          f"in real time with the messages stamped in it, {args.duration:g} s; thread CPU of the passes)")


def paced_feed(args: argparse.Namespace, pipeline: Any, stamped: list) -> tuple[float, int, float]:
    """Decode and feed ``stamped`` (``(stamp ns, (msgtype, kind, raw))``) in the live node's
    rhythm, without DDS: the messages stamped in one intake period fed in one pass, a pass
    per period in real time, sleeping between passes. The passes' thread CPU, the output
    samples and the period: against the loop over all messages at once, the cost of feeding
    in short passes between which other threads and processes run."""
    from rls_uncertainty.datapath.cdr import decode
    from rls_uncertainty.datapath.inputs import feed
    from rls_uncertainty.settings.config import intake_period

    period = intake_period(args.intake_period, args.rate)
    passes: dict[int, list] = {}
    for stamp, item in stamped:
        passes.setdefault(int((stamp - T0) // round(period * 1e9)), []).append(item)
    cpu, n, start = 0.0, 0, time.monotonic()
    for k in sorted(passes):
        delay = start + (k + 1) * period - time.monotonic()
        if delay > 0:
            time.sleep(delay)
        c0 = time.thread_time()
        for msgtype, kind, raw in passes[k]:
            n += len(feed(pipeline, kind, decode(msgtype, raw)))
        cpu += time.thread_time() - c0
    return cpu, n, period


def echo_node() -> None:
    """The baseline's middle process: republish every Header at once (no work at all)."""
    import rclpy
    from rclpy.qos import QoSProfile, QoSReliabilityPolicy
    from std_msgs.msg import Header

    rclpy.init()
    node = rclpy.create_node("bench_echo")
    qos = QoSProfile(depth=1000, reliability=QoSReliabilityPolicy.RELIABLE)
    pub = node.create_publisher(Header, "bench_echo_out", qos)
    node.create_subscription(Header, "bench_echo_in", pub.publish, qos)
    with contextlib.suppress(KeyboardInterrupt):
        rclpy.spin(node)


def echo_baseline(samples: int = 1000) -> np.ndarray:
    """Round trip through a Python node that does nothing: the floor under any rclpy node's
    input-to-output latency on this machine (same two DDS hops, same 50 Hz)."""
    import rclpy
    from rclpy.qos import QoSProfile, QoSReliabilityPolicy
    from std_msgs.msg import Header

    echo = subprocess.Popen([sys.executable, __file__, "--echo"])
    node = rclpy.create_node("bench_echo_client")
    qos = QoSProfile(depth=1000, reliability=QoSReliabilityPolicy.RELIABLE)
    sent, lat = {}, []
    node.create_subscription(Header, "bench_echo_out",
                             lambda m: lat.append(time.monotonic() - sent[m.stamp.nanosec]), qos)
    pub = node.create_publisher(Header, "bench_echo_in", qos)
    while pub.get_subscription_count() < 1:
        rclpy.spin_once(node, timeout_sec=0.05)
    end = time.monotonic() + 1.0
    while time.monotonic() < end:
        rclpy.spin_once(node, timeout_sec=0.05)
    for k in range(samples):
        msg = Header()
        msg.stamp.nanosec = k
        sent[k] = time.monotonic()
        pub.publish(msg)
        t_next = sent[k] + 0.02
        while time.monotonic() < t_next:
            rclpy.spin_once(node, timeout_sec=max(0.0, t_next - time.monotonic()))
    echo.send_signal(2)
    echo.wait(20)
    node.destroy_node()
    return np.array(lat) * 1e3


FLOORS = ("intake", "callbacks", "timer")


def floor_node(variant: str, rate: float, period: float) -> None:
    """The floor run's node: an rclpy node on the estimator node's executor (its ``_spin``:
    rclpy's events executor) with its input subscriptions (the same six topics, types and QoS
    as the benchmark starts it, without QoS-event handlers), taking every message raw and
    doing nothing else. ``intake``: the node's own :class:`.intake.Intake`, taken by a timer
    every intake period on the steady clock (200 Hz here), as the node takes it;
    ``callbacks``: plain raw subscriptions on the executor, whose callback does nothing;
    ``timer``: the intake's subscriptions and timer, which takes nothing (the middleware
    receives every message as before; the main thread pays only the timer's wakes)."""
    import gc

    import rclpy
    from rclpy.clock import Clock, ClockType
    from rclpy.event_handler import SubscriptionEventCallbacks
    from rclpy.executors import ExternalShutdownException

    from rls_uncertainty.datapath.inputs import DEFAULT_TOPICS
    from rls_uncertainty.ros.intake import Intake
    from rls_uncertainty.ros.node import _TYPES, _input_qos, _spin
    from rls_uncertainty.settings.config import intake_period

    rclpy.init()
    node = rclpy.create_node("bench_floor")
    qos = _input_qos(True, 1000)  # qos.reliable true, qos.depth 1000 (start_node's)
    if variant in ("intake", "timer"):
        intake = Intake(node, _TYPES, DEFAULT_TOPICS, qos)
        node.create_timer(intake_period(period, rate), intake.take if variant == "intake" else lambda: None,
                          clock=Clock(clock_type=ClockType.STEADY_TIME))
    else:
        no_events = SubscriptionEventCallbacks(use_default_callbacks=False)
        for kind, msgtype in _TYPES.items():
            node.create_subscription(msgtype, DEFAULT_TOPICS[kind], lambda _raw: None, qos,
                                     event_callbacks=no_events, raw=True)
    gc.freeze()  # as the node does once it is built
    with contextlib.suppress(KeyboardInterrupt, ExternalShutdownException):
        _spin(node)
    node.destroy_node()
    rclpy.try_shutdown()


def publisher_command(args, log_path: Path) -> list[str]:
    """This script as the maneuver's publisher, logging to ``log_path``."""
    return [sys.executable, __file__, "--publisher", "--log", str(log_path), "--imu-rate", str(args.imu_rate),
            "--air-rate", str(args.air_rate), "--duration", str(args.duration)]


def floor_run(args, variant: str, tmp: Path) -> dict:
    """One floor node (:func:`floor_node`) fed the maneuver: its process CPU and CPU by thread
    over the streaming part (from the publisher's first message to its exit, the node run's
    tail included), and that part's wall time."""
    node = subprocess.Popen([sys.executable, *os.environ.get("RLS_BENCH_PYFLAGS", "").split(), __file__,
                             "--floor-node", variant, "--rate", str(args.rate),
                             "--intake-period", str(args.intake_period)], cwd=ROOT)
    log_path = tmp / f"floor_{variant}.npy"
    pub = subprocess.Popen(publisher_command(args, log_path), cwd=ROOT)
    while pub.poll() is None and not log_path.with_suffix(".started").exists():
        time.sleep(0.005)
    cpu0, wall0, threads0 = cpu_seconds(node.pid), time.monotonic(), thread_cpu_seconds(node.pid)
    pub.wait()
    cpu1, wall1, threads1 = cpu_seconds(node.pid), time.monotonic(), thread_cpu_seconds(node.pid)
    node.send_signal(2)
    node.wait(20)
    return {"cpu_s": cpu1 - cpu0, "wall_s": wall1 - wall0,
            "threads": {k: v - threads0.get(k, 0.0) for k, v in threads1.items()}}


def floor(args) -> None:
    """The CPU any rclpy node pays here for these inputs (:func:`floor_node`), each variant of
    ``args.floor`` in turn: % of one core, and ms per output-sample period (1 / ``--rate``):
    process CPU over the ``--duration`` x ``--rate`` samples' worth of input streamed."""
    from rls_uncertainty.settings.config import intake_period

    tmp = Path(os.environ.get("TMPDIR", "/tmp")) / f"rls_bench_{os.getpid()}"
    tmp.mkdir(parents=True, exist_ok=True)
    print(f"floor: an rclpy node on the node's executor and input subscriptions, taking every message and "
          f"doing nothing else; IMU {args.imu_rate:g} Hz, air data and surfaces {args.air_rate:g} Hz, "
          f"{args.duration:g} s, per output-sample period ({1e3 / args.rate:g} ms)")
    results = {}
    for variant in args.floor or FLOORS:
        r = results[variant] = floor_run(args, variant, tmp)
        periods = args.duration * args.rate  # the samples the stream makes (as the node's, if it falls behind)
        intake_hz = 1 / intake_period(args.intake_period, args.rate)  # the node's intake period
        what = {"intake": f"timer {intake_hz:g} Hz, take_message", "callbacks": "a callback per message",
                "timer": f"timer {intake_hz:g} Hz, nothing taken"}[variant]
        threads = {k: v for k, v in sorted(r["threads"].items(), key=lambda kv: -kv[1]) if v > 0}
        r["cpu_percent"], r["cpu_per_period_ms"] = 100 * r["cpu_s"] / r["wall_s"], 1e3 * r["cpu_s"] / periods
        r["threads_ms_per_period"] = {k: 1e3 * v / periods for k, v in threads.items()}
        print(f"  {variant} ({what}): CPU {r['cpu_percent']:.1f} % of one core, {r['cpu_per_period_ms']:.3f} ms "
              f"per period; by thread, ms/period "
              + ", ".join(f"{k} {v:.3f}" for k, v in r["threads_ms_per_period"].items()))
    with open(tmp / "floor.json", "w") as fh:
        json.dump(results, fh)


def cpu_seconds(pid: int) -> float:
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def thread_cpu_seconds(pid: int) -> dict[str, float]:
    """CPU seconds of each of process ``pid``'s threads so far, summed by thread name (the
    main thread, which runs the executor and every callback, as ``main``; threads the
    middleware starts without a name carry the process's, ``python``)."""
    out: dict[str, float] = {}
    for task in Path(f"/proc/{pid}/task").iterdir():
        try:
            name = "main" if task.name == str(pid) else (task / "comm").read_text().strip()
            fields = (task / "stat").read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue
        out[name] = out.get(name, 0.0) + (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")
    return out


def rss_mb(pid: int) -> float:
    """Resident set size of process ``pid``, MB (0 once it has gone)."""
    try:
        for line in Path(f"/proc/{pid}/status").read_text().splitlines():
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024
    except OSError:
        pass
    return 0.0


def completing_times(log: np.ndarray, rate: float, lag: int, required=(0, 1, 2, 3, 4)) -> dict[int, float]:
    """For each output sample stamp: when the input that completed sample (stamp + lag) was
    published (the pipeline's frontier rule, replayed on the publication log)."""
    P = int(round(1e9 / rate))
    newest = dict.fromkeys(required, -1)
    out = {}
    t_next = None
    for wall, kind_logged, stamp_logged in log:
        kind, stamp = int(kind_logged), int(stamp_logged)
        if kind not in newest:
            continue
        newest[kind] = stamp
        if min(newest.values()) < 0:
            continue
        if t_next is None:
            t_next = -(-max(newest.values()) // P) * P
        frontier = min(newest.values())
        while t_next <= frontier:
            out[t_next - lag * P] = wall
            t_next += P
    return out


def report(args, tmp: Path, received: dict[int, float], count: dict[str, int], m: dict) -> None:
    """Print the run's figures (``m``: what the run measured) and write them to result.json."""
    diag, texts, proc_p99, periodic, rss = m["diag"], m["texts"], m["proc_p99"], m["periodic"], m["rss"]
    log = np.load(tmp / "publish_log.npy")
    lag = 4
    done = completing_times(log, args.rate, lag)
    lat = np.array([received[s] - done[s] for s in received if s in done]) * 1e3
    # The first output: after the first formed sample and the differentiator warm-up (window 9).
    first = min(k for k in done) + 8 * int(round(1e9 / args.rate))
    expected = sum(1 for s in done if s >= first)
    n_in = log.shape[0]
    samples = diag.get("rls_estimator: samples", {})
    print(f"node benchmark: IMU {args.imu_rate:g} Hz, air data and surfaces {args.air_rate:g} Hz, estimates "
          f"{args.rate:g} Hz, six models, {args.lag_span:g} s of lags, {args.duration:g} s, intake period "
          f"{samples.get('intake_period_ms', '?')} ms")
    print(f"  input messages published        {n_in}")
    print(f"  samples completed by the inputs  {expected}")
    print(f"  sample stamps received           {count['stamps']}  (dropped: {expected - count['stamps']}; "
          f"the last {lag} wait for the differentiator)")
    print(f"  last-model arrays received       {count['arrays']}  (non-finite: {count['nonfinite']})")
    if lat.size:
        print(f"  input-to-output latency, ms      p50 {np.percentile(lat, 50):.3f}  p99 {np.percentile(lat, 99):.3f}  "
              f"max {lat.max():.3f}")
    cpu_percent = 100 * m["cpu_s"] / m["wall_s"]
    print(f"  node CPU                         {cpu_percent:.1f} % of one core")
    per_sample = 1e3 * m["cpu_s"] / max(m["stamps"], 1)
    print(f"  node CPU per output sample       {per_sample:.3f} ms  (process CPU / samples published)")
    threads = {k: v for k, v in sorted(m["threads"].items(), key=lambda kv: -kv[1]) if v > 0}
    print("  of which, by thread, ms/sample   "
          + ", ".join(f"{k} {1e3 * v / max(m['stamps'], 1):.3f}" for k, v in threads.items()))
    if periodic:
        print(f"  longest periodic step (diagnostics periodic_ms.max)  {max(periodic):.3f} ms")
    if samples:
        rejected = {k: v for k, v in samples.items() if k.startswith("samples_rejected")}
        print(f"  node diagnostics                 used {samples.get('samples_used')}, rejected {rejected}, "
              f"in-node wall p99 (worst second) {max((p[0] for p in proc_p99), default=float('nan')):.3f} ms")
        print(f"  in-node CPU per output sample    p50 {np.median([p[2] for p in proc_p99]):.3f} ms, "
              f"p99 (worst second) {max((p[1] for p in proc_p99), default=float('nan')):.3f} ms")
    print(f"  node RSS, MB                     start {rss[0]:.0f}, max {max(rss):.0f}, end {rss[-1]:.0f}")
    for name in ("rls_estimator: samples", "rls_estimator: inputs"):
        if name in texts:
            print(f"  last /diagnostics {name.split(': ')[1]:8s}       {texts[name]}")
    said = [line.strip() for line in (tmp / "node.log").read_text(errors="replace").splitlines()
            if any(w in line for w in ("cannot keep up", "degraded:", "restored:", "keeping up"))]
    for line in said:
        print(f"  node log: {line}")
    with open(tmp / "result.json", "w") as fh:
        json.dump({"p50_ms": float(np.percentile(lat, 50)) if lat.size else None,
                   "p99_ms": float(np.percentile(lat, 99)) if lat.size else None,
                   "max_ms": float(lat.max()) if lat.size else None,
                   "cpu_percent": cpu_percent, "cpu_per_sample_ms": per_sample,
                   "threads_ms_per_sample": {k: 1e3 * v / max(m["stamps"], 1) for k, v in threads.items()},
                   "periodic_max_ms": max(periodic, default=None),
                   "dropped": expected - count["stamps"],
                   "intake_period_ms": float(samples["intake_period_ms"]) if "intake_period_ms" in samples else None},
                  fh)


def parse_args() -> argparse.Namespace:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--imu-rate", type=float, default=1000.0)
    ap.add_argument("--air-rate", type=float, default=100.0)
    ap.add_argument("--rate", type=float, default=50.0, help="estimator rate, Hz")
    ap.add_argument("--duration", type=float, default=20.0)
    ap.add_argument("--lag-span", type=float, default=1.0, help="estimator.lag_span, s (1.0: 50 lags at 50 Hz)")
    ap.add_argument("--method", choices=("time", "frequency", "both"), default="time", help="estimator.method")
    ap.add_argument("--frequency-every", type=int, default=5, help="frequency.every (with --method frequency/both)")
    ap.add_argument("--extreme", action="store_true",
                    help="rate 1000 Hz, method both, frequency.every 1 (overrides --rate, --method, --frequency-every)")
    ap.add_argument("--intake-period", type=float, default=0.0, metavar="S",
                    help="the node's intake_period, s (0: the estimator period, at most 5 ms)")
    ap.add_argument("--no-baseline", action="store_true", help="skip the echo-node latency baseline")
    ap.add_argument("--offline", action="store_true",
                    help="time the node's data path (decode, feed, encode) on the same messages, without DDS")
    ap.add_argument("--repeats", type=int, default=3, help="with --offline: passes over the messages")
    ap.add_argument("--floor", nargs="*", choices=FLOORS, default=None,
                    help="instead of the estimator node, an rclpy node that only takes the inputs "
                         "(all variants, or those named): the CPU floor of any rclpy node here")
    ap.add_argument("--floor-node", choices=FLOORS, default=None, help=argparse.SUPPRESS)
    ap.add_argument("--publisher", action="store_true", help=argparse.SUPPRESS)
    ap.add_argument("--echo", action="store_true", help=argparse.SUPPRESS)
    ap.add_argument("--log", default=None, help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.extreme:
        args.rate, args.method, args.frequency_every = 1000.0, "both", 1
    return args


def start_node(args: argparse.Namespace, tmp: Path) -> subprocess.Popen:
    """The estimator node, its log in ``tmp/node.log``."""
    # The child writes node.log through its own descriptor: ours is closed once it has started.
    with open(tmp / "node.log", "w") as node_log:
        node = subprocess.Popen(
            [sys.executable, *os.environ.get("RLS_BENCH_PYFLAGS", "").split(), "-m", "rls_uncertainty.ros.node",
             "--ros-args", "-p", "qos.reliable:=true",
             "-p", f"rate:={args.rate}", "-p", f"estimator.lag_span:={args.lag_span}",
             "-p", "surfaces.elevator:=[elevator]",
             "-p", "qos.depth:=1000", "-p", f"estimator.method:={args.method}",
             "-p", f"intake_period:={args.intake_period}",
             *(["-p", f"frequency.every:={args.frequency_every}"] if args.method != "time" else [])],
            stdout=node_log, stderr=subprocess.STDOUT, cwd=ROOT,
        )
    return node


def read_diagnostics(diags: list) -> dict:
    """The last key-values and text of each status, every period's latency and CPU percentiles and
    longest periodic step."""
    diag, proc_p99, periodic, texts = {}, [], [], {}
    for d in diags:
        for s in d.status:
            diag[s.name] = {kv.key: kv.value for kv in s.values}
            texts[s.name] = f"[{['OK', 'WARN', 'ERROR', 'STALE'][s.level[0]]}] {s.message}"
            if "periodic_ms.max" in diag[s.name]:
                periodic.append(float(diag[s.name]["periodic_ms.max"]))
            if "latency_ms.p99" in diag[s.name]:
                proc_p99.append((float(diag[s.name]["latency_ms.p99"]), float(diag[s.name]["processing_cpu_ms.p99"]),
                                 float(diag[s.name]["processing_cpu_ms.p50"])))
    return {"diag": diag, "texts": texts, "proc_p99": proc_p99, "periodic": periodic}


def main() -> int:
    args = parse_args()
    if args.publisher:
        publisher(args)
        return 0
    if args.echo:
        echo_node()
        return 0
    if args.offline:
        offline(args)
        return 0
    if args.floor_node:
        floor_node(args.floor_node, args.rate, args.intake_period)
        return 0
    if args.floor is not None:
        floor(args)
        return 0

    import rclpy
    from diagnostic_msgs.msg import DiagnosticArray
    from rclpy.qos import QoSHistoryPolicy, QoSProfile, QoSReliabilityPolicy
    from std_msgs.msg import Float64MultiArray, Header

    tmp = Path(os.environ.get("TMPDIR", "/tmp")) / f"rls_bench_{os.getpid()}"
    tmp.mkdir(parents=True, exist_ok=True)
    node = start_node(args, tmp)
    rclpy.init()
    sub = rclpy.create_node("bench_subscriber")
    qos = QoSProfile(depth=1000, reliability=QoSReliabilityPolicy.RELIABLE, history=QoSHistoryPolicy.KEEP_LAST)
    received: dict[int, float] = {}
    count = {"arrays": 0, "stamps": 0, "nonfinite": 0}
    last_topic = "/rls_estimator/Cn/standard_errors_conventional"
    stamps_seen: list[int] = []

    def on_stamp(msg):
        stamps_seen.append(msg.stamp.sec * 10**9 + msg.stamp.nanosec - T0)
        count["stamps"] += 1

    def on_array(topic):
        def cb(msg):
            count["arrays"] += 1
            if not np.isfinite(np.asarray(msg.data)).all():
                count["nonfinite"] += 1
            if topic == last_topic and stamps_seen:
                received[stamps_seen[-1]] = time.monotonic()
        return cb

    # The stamp (published first for a sample) and the last array of a sample (published
    # last): a subscriber on all 19 topics would itself become the bottleneck in Python.
    subs = [sub.create_subscription(Header, "/rls_estimator/sample_stamp", on_stamp, qos),
            sub.create_subscription(Float64MultiArray, last_topic, on_array(last_topic), qos)]
    diags = []
    subs.append(sub.create_subscription(DiagnosticArray, "/diagnostics", diags.append, 10))
    deadline = time.monotonic() + 30
    while any(s.get_publisher_count() < 1 for s in subs[:-1]) and time.monotonic() < deadline:
        rclpy.spin_once(sub, timeout_sec=0.05)
    log_path = tmp / "publish_log.npy"
    pub = subprocess.Popen(publisher_command(args, log_path), cwd=ROOT)
    # Measure the node's CPU over the streaming part only.
    while pub.poll() is None and not stamps_seen:
        rclpy.spin_once(sub, timeout_sec=0.01)
    cpu0, wall0, stamps0 = cpu_seconds(node.pid), time.monotonic(), count["stamps"]
    threads0 = thread_cpu_seconds(node.pid)
    rss = [rss_mb(node.pid)]
    next_rss = time.monotonic() + 0.5
    while pub.poll() is None:
        rclpy.spin_once(sub, timeout_sec=0.01)
        if time.monotonic() >= next_rss:
            rss.append(rss_mb(node.pid))
            next_rss += 0.5
    cpu1, wall1, stamps1 = cpu_seconds(node.pid), time.monotonic(), count["stamps"]
    threads1 = thread_cpu_seconds(node.pid)
    end = time.monotonic() + 2
    while time.monotonic() < end:
        rclpy.spin_once(sub, timeout_sec=0.05)
    rss.append(rss_mb(node.pid))
    m = read_diagnostics(diags)
    node.send_signal(2)
    node.wait(20)

    m.update(threads={k: v - threads0.get(k, 0.0) for k, v in threads1.items()})
    m.update(rss=rss, cpu_s=cpu1 - cpu0, wall_s=wall1 - wall0, stamps=stamps1 - stamps0)
    report(args, tmp, received, count, m)
    sub.destroy_node()
    if not args.no_baseline:
        base = echo_baseline()
        print(f"  baseline: round trip through a Python node that only republishes (two DDS hops, 50 Hz): "
              f"p50 {np.percentile(base, 50):.3f} ms, p99 {np.percentile(base, 99):.3f} ms")
    rclpy.try_shutdown()
    return 0


if __name__ == "__main__":
    sys.exit(main())
