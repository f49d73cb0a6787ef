"""``estimator_node``: the live ROS 2 adapter over :class:`.pipeline.Pipeline`.

The node only converts, schedules and publishes: messages of the topics and types of
:mod:`.inputs` are decoded by :mod:`.cdr` and go through :func:`.inputs.feed` (the code the
offline replay runs), and every completed sample is published as the messages of
:mod:`.outputs` (``~/sample_stamp``, then per ready model M ``~/M/estimates``, its standard
errors, convergence flags and decimated covariances), serialized there: the node publishes the
bytes :meth:`.outputs.OutputLayout.encode` makes, on the publisher of each topic index.
``/diagnostics`` reports input rates and ages, the fate of every message and sample, model fit,
identifiability, convergence and latency (and ``~/M/fit``, ``~/M/identifiability`` follow each
period), and a misconfigured data path (every message of a needed stream
rejected, no sample used) is also logged as a throttled warning: the statuses and the warnings
are computed by :mod:`.diagnostics` and :mod:`.alerts` from a snapshot the node takes each
period. A needed input topic with no publisher for ``diagnostics_window`` seconds is logged
once (:mod:`.input_watch`).

Parameters (declared with the descriptions, ranges and choices of
:data:`rls_uncertainty.settings.parameters.PARAMETERS`, generated from the options classes), the
``~/reset`` and ``~/enable`` services, an optional state file, ``use_sim_time`` and
backwards time jumps are handled here.
"""

from __future__ import annotations

import gc
import os
import sys
import time
from collections.abc import Callable
from typing import Any

import rclpy
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor, SetParametersResult
from rclpy.clock import Clock, ClockChange, ClockType, JumpThreshold, TimeJump
from rclpy.duration import Duration
from rclpy.event_handler import PublisherEventCallbacks, SubscriptionEventCallbacks
from rclpy.exceptions import ParameterException
from rclpy.executors import ExternalShutdownException
from rclpy.impl.implementation_singleton import rclpy_implementation as _rclpy
from rclpy.node import Node
from rclpy.parameter import Parameter as RosParameter
from rclpy.qos import QoSDurabilityPolicy, QoSHistoryPolicy, QoSProfile, QoSReliabilityPolicy, qos_profile_sensor_data
from std_msgs.msg import Float64MultiArray, Header
from std_srvs.srv import SetBool, Trigger

from ..datapath.cdr import decode
from ..datapath.diagnostics import DiagnosticsPolicy, Snapshot, malformed_reason, malformed_warning
from ..datapath.feasibility import configuration_warnings
from ..datapath.inputs import MESSAGE_TYPES, STREAMS, feed, message_class
from ..datapath.outputs import HEADER, NODE_NAME, OutputLayout
from ..datapath.pipeline import Pipeline, SampleOutput, StateFileError
from ..errors import ConfigError
from ..settings.parameters import PARAMETERS, Parameter, node_config, pipeline_config
from ..settings.sources import startup_parameters
from ..state_file import StateFileClaim, claim, set_aside
from .input_watch import SilentInputs

__all__ = ["EstimatorNode", "main", "NODE_NAME"]

_TYPES = {kind: message_class(MESSAGE_TYPES[kind]) for kind in STREAMS}
# No QoS-event handlers: rclpy's executor walks every handler on every wait, which cost more
# CPU than the estimation itself. A QoS mismatch on an input shows in /diagnostics instead
# (``<stream>.publishers`` is 0 and the stream is reported silent).
_NO_EVENTS = PublisherEventCallbacks(use_default_callbacks=False)
_NO_SUB_EVENTS = SubscriptionEventCallbacks(use_default_callbacks=False)


def _descriptor(p: Parameter) -> ParameterDescriptor:
    """The parameter's ROS descriptor: its meaning (and unit), its choices or its range, and
    whether a change needs a restart (the topics, the QoS and the state file: the node only
    ever writes the state file it checked at start-up)."""
    unit = f" ({p.unit})" if p.unit else ""
    special = "".join(f"; {s.seconds:g}: {s.meaning}" for s in p.specials)
    d = ParameterDescriptor(description=p.description + unit + special, read_only=p.read_only)
    if p.choices:
        d.additional_constraints = "one of: " + ", ".join(p.choices)
    if p.low is not None and p.high is not None:  # a range has both bounds
        if isinstance(p.default, float):
            d.floating_point_range = [FloatingPointRange(from_value=float(p.low), to_value=float(p.high), step=0.0)]
        else:
            d.integer_range = [IntegerRange(from_value=int(p.low), to_value=int(p.high), step=1)]
    return d


def _input_qos(reliable: bool, depth: int) -> QoSProfile:
    """Reliable inputs (``qos.reliable``) or sensor-data QoS (best effort, volatile)."""
    if reliable:
        return QoSProfile(depth=depth, reliability=QoSReliabilityPolicy.RELIABLE, history=QoSHistoryPolicy.KEEP_LAST)
    return QoSProfile(depth=max(depth, 5), reliability=qos_profile_sensor_data.reliability,
                      history=QoSHistoryPolicy.KEEP_LAST, durability=qos_profile_sensor_data.durability)


class EstimatorNode(Node):
    """Recursive estimation of stability and control derivatives with honest uncertainty."""

    def __init__(self, **kwargs: Any) -> None:
        super().__init__(NODE_NAME, **kwargs)
        for p in PARAMETERS:
            self.declare_parameter(p.name, p.default, _descriptor(p))
        params = self._parameter_values()
        # Invalid settings at start-up: ConfigError propagates to main(), which says why.
        self.config = pipeline_config(params)
        for line in configuration_warnings(self.config):
            self.get_logger().warning(line)
        self.node_cfg = node_config(params)
        self.pipeline = Pipeline(self.config, enabled=self.node_cfg.enabled)
        self.state_status = "no state file"
        self._load_state()
        self._latencies: list[float] = []  # wall time from message to last publish
        self._cpu_times: list[float] = []  # CPU time of the same (without preemption)
        self._malformed_logged: set[str] = set()  # inputs whose first malformed message was logged
        self._diagnostics = DiagnosticsPolicy(self.get_fully_qualified_name(),
                                              window_s=self.node_cfg.diagnostics_window)
        self._last_diag = time.monotonic()
        self._silent = SilentInputs()  # input topics nobody publishes, logged once

        # Transient local: a subscriber that joins late (a dashboard) gets the last qos.depth
        # samples at once; volatile subscribers match as before. Keep-last bounds the memory.
        self._out_qos = QoSProfile(depth=self.node_cfg.depth, reliability=QoSReliabilityPolicy.RELIABLE,
                                   history=QoSHistoryPolicy.KEEP_LAST,
                                   durability=QoSDurabilityPolicy.TRANSIENT_LOCAL)
        self._outputs_by_topic: dict[str, Any] = {}  # publishers by relative topic
        # ~/M/fit and ~/M/identifiability, once per diagnostics period: the latest kept for late joiners.
        self._fit_qos = QoSProfile(depth=1, reliability=QoSReliabilityPolicy.RELIABLE,
                                   durability=QoSDurabilityPolicy.TRANSIENT_LOCAL, history=QoSHistoryPolicy.KEEP_LAST)
        self._fit_by_topic: dict[str, Any] = {}
        self._make_publishers()
        self._diag_pub = self.create_publisher(DiagnosticArray, "/diagnostics", 10, event_callbacks=_NO_EVENTS)
        in_qos = _input_qos(self.node_cfg.reliable, self.node_cfg.depth)
        self._subs = {
            kind: self.create_subscription(_TYPES[kind], self.node_cfg.topics[kind], self._callback(kind), in_qos,
                                           raw=True, event_callbacks=_NO_SUB_EVENTS)
            for kind in STREAMS
        }
        self.create_service(Trigger, "~/reset", self._on_reset)
        self.create_service(SetBool, "~/enable", self._on_enable)
        self.add_on_set_parameters_callback(self._validate_parameters)
        self.add_post_set_parameters_callback(self._apply_parameters)
        self._jump_handle = self.get_clock().create_jump_callback(
            JumpThreshold(min_forward=None, min_backward=Duration(nanoseconds=-1), on_clock_change=True),
            post_callback=self._on_time_jump,
        )
        # Health reporting and state saving run on the steady clock: they go on when /clock
        # pauses or jumps (use_sim_time).
        steady = Clock(clock_type=ClockType.STEADY_TIME)
        self.create_timer(self.node_cfg.diagnostics_period, self._publish_diagnostics, clock=steady)
        if self.node_cfg.state_file and self.node_cfg.state_save_period > 0:
            self.create_timer(self.node_cfg.state_save_period, self.save_state, clock=steady)
        models = ", ".join(f"{m.output}({len(m.regressors)})" for m in self.config.models)
        est = self.config.estimator
        lags = f"auto (at most {est.max_lags})" if est.lags == "auto" else est.lags  # (samples: lag_span x rate)
        self.get_logger().info(
            f"estimating {models} at {self.config.rate:g} Hz, {lags} lags, aircraft {self.config.aircraft.name}; "
            f"inputs {', '.join(self.node_cfg.topics[k] for k in STREAMS)}; "
            + (f"{self.state_status.partition(':')[0]} (above)" if self._state_said else self.state_status)
        )

    # ------------------------------------------------------------------ parameters
    def _parameter_values(self, overrides: list[RosParameter] | None = None) -> dict[str, Any]:
        values = {p.name: self.get_parameter(p.name).value for p in PARAMETERS}
        for p in overrides or []:
            values[p.name] = p.value
        return values

    def _validate_parameters(self, params: list[RosParameter]) -> SetParametersResult:
        """Refuse any change that makes an invalid configuration, saying why."""
        names = {p.name for p in params}
        if not names & {p.name for p in PARAMETERS}:
            return SetParametersResult(successful=True)
        try:
            pipeline_config(self._parameter_values(params))
            node_config(self._parameter_values(params))
        except ConfigError as exc:
            return SetParametersResult(successful=False, reason=str(exc))
        return SetParametersResult(successful=True)

    def _apply_parameters(self, params: list[RosParameter]) -> None:
        values = self._parameter_values()
        new = pipeline_config(values)
        self.node_cfg = node_config(values)
        self.pipeline.enabled = self.node_cfg.enabled
        self._diagnostics.window_s = self.node_cfg.diagnostics_window
        if new != self.config:
            changed = ", ".join(sorted(p.name for p in params))
            old_fp, new_fp = self.config.fingerprint(), new.fingerprint()
            what = "estimator reset" if old_fp != new_fp else "pipeline restarted"
            self.get_logger().warning(f"parameters changed ({changed}): {what}")
            for line in configuration_warnings(new):
                self.get_logger().warning(line)
            self.config = new
            self.pipeline = self.pipeline.reconfigured(new)
            self._make_publishers()

    def _make_publishers(self) -> None:
        """One publisher per topic of the configuration's :class:`.outputs.OutputLayout`, in
        its order (``self._pubs[i]`` publishes topic ``i``); publishers of topics that remain
        are kept, those of models no longer configured destroyed."""
        self._layout = OutputLayout.of(self.pipeline)
        old, new = self._outputs_by_topic, {}
        for topic, msgtype in self._layout.topics:
            pub = old.pop(topic, None)
            if pub is None:
                pub = self.create_publisher(Header if msgtype == HEADER else Float64MultiArray, f"~/{topic}",
                                            self._out_qos, event_callbacks=_NO_EVENTS)
            new[topic] = pub
        for pub in old.values():
            self.destroy_publisher(pub)
        self._outputs_by_topic = new
        self._pubs = [new[topic] for topic, _ in self._layout.topics]
        self._make_fit_publishers()

    def _make_fit_publishers(self) -> None:
        """The per-period publishers of :attr:`.outputs.OutputLayout.fit_topics`, kept, made
        or destroyed as :meth:`_make_publishers` does."""
        old, new = self._fit_by_topic, {}
        for topic, _msgtype in self._layout.fit_topics:
            pub = old.pop(topic, None)
            new[topic] = pub or self.create_publisher(Float64MultiArray, f"~/{topic}", self._fit_qos,
                                                      event_callbacks=_NO_EVENTS)
        for pub in old.values():
            self.destroy_publisher(pub)
        self._fit_by_topic = new
        self._fit_pubs = [new[topic] for topic, _ in self._layout.fit_topics]

    # ------------------------------------------------------------------ data path
    def _callback(self, kind: str) -> Callable[[bytes], None]:
        """Inputs arrive serialized (``raw=True``) and are decoded by :mod:`.cdr` (either byte
        order) into light objects with the message's field names: building rclpy's Python
        messages (numpy covariance arrays and all) cost more than the pipeline itself."""
        msgtype = MESSAGE_TYPES[kind]

        def on_message(raw: bytes) -> None:
            t0 = time.perf_counter()
            c0 = time.thread_time()
            try:
                pipeline = self.pipeline
                if pipeline.needs_clock:  # inputs.max_clock_offset: stamps are checked against it
                    pipeline.clock_ns = self.get_clock().now().nanoseconds
                outputs = feed(pipeline, kind, decode(msgtype, raw))
            except Exception as exc:  # noqa: BLE001 - a bad message must never stop the node
                self._malformed(kind, exc)
                return
            if outputs:
                for out in outputs:
                    self._publish(out)
                self._latencies.append(time.perf_counter() - t0)
                self._cpu_times.append(time.thread_time() - c0)

        return on_message

    def _malformed(self, kind: str, exc: Exception) -> None:
        """Count a message that could not be decoded or fed; log the first one per input."""
        self.pipeline.reject(kind, malformed_reason(exc), str(exc))
        if kind not in self._malformed_logged:
            self._malformed_logged.add(kind)
            self.get_logger().warning(malformed_warning(self._subs[kind].topic_name, exc))

    def _publish(self, out: SampleOutput) -> None:
        """A sample's messages (:meth:`.outputs.OutputLayout.encode`), each on the publisher of
        its topic index. They are serialized by :mod:`.cdr` (byte-identical to rosbags'
        serialization and read back by rclpy, checked in test_cdr.py) and published raw:
        converting 25 Python messages per sample cost more CPU and latency than the estimation."""
        pubs = self._pubs
        for index, raw in self._layout.encode(out, self.node_cfg.frame_id):
            pubs[index].publish(raw)

    # ------------------------------------------------------------------ services, time
    def _on_reset(self, request: Trigger.Request, response: Trigger.Response) -> Trigger.Response:
        self.pipeline.reset("service")  # the estimator and every input state: older stamps are accepted again
        response.success = True
        response.message = "estimator and inputs reset: estimates restart from the next messages, whatever their stamps"
        self.get_logger().info(response.message)
        return response

    def _on_enable(self, request: SetBool.Request, response: SetBool.Response) -> SetBool.Response:
        enabled = bool(request.data)
        self.pipeline.enabled = enabled
        if not enabled:
            self.save_state()
        response.success = True
        response.message = "estimation enabled" if enabled else "estimation disabled (samples counted, not used)"
        self.get_logger().info(response.message)
        return response

    def _on_time_jump(self, jump: TimeJump) -> None:
        """A backwards jump (a bag replay restarted, /clock reset): the streams whose stamps
        step back near the new time start a new timeline without confirmation, and the data
        path and estimator restart once they do (``resets.time_jumped_backwards``), after the
        samples of the messages sent before the jump: those cannot wipe the new run."""
        if jump.clock_change in (ClockChange.ROS_TIME_ACTIVATED, ClockChange.ROS_TIME_DEACTIVATED):
            self.get_logger().info(f"clock source changed ({jump.clock_change.name})")
        delta = jump.delta.nanoseconds
        if delta < 0:
            now = self.get_clock().now().nanoseconds
            if self.pipeline.time_jumped(now, now - delta):
                self.get_logger().warning(
                    f"time jumped {delta * 1e-9:+.3f} s: estimator and inputs restart when the stamps follow"
                )
            else:
                self.get_logger().info(f"time jumped {delta * 1e-9:+.3f} s: the inputs are already near the new time")

    # ------------------------------------------------------------------ state file
    def _load_state(self) -> None:
        """Resume from ``state_file`` when it holds this configuration's state. The file is
        claimed first (:func:`rls_uncertainty.state_file.claim`): one that is not a regular file,
        or that another process holds, is refused in one line and the node runs without a
        state file. A file that exists but cannot be used (corrupt, crafted, another
        configuration's) is renamed aside (:func:`rls_uncertainty.state_file.set_aside`) so that
        the fresh state saved later never replaces it; if it cannot be moved, nothing is saved
        this run."""
        path = self._state_path = self.node_cfg.state_file
        self._state_claim: StateFileClaim | None = None
        self._state_said = False  # a problem with the file is logged once; the start-up line points to it
        if not path:
            return
        try:
            self._state_claim = claim(path)
        except StateFileError as exc:
            self._state_path = ""
            self.state_status = f"state file refused: {exc}; running without a state file"
            self.get_logger().error(self.state_status)
            self._state_said = True
            return
        if self._state_claim.removed:
            names = ", ".join(p.name for p in self._state_claim.removed)
            self.get_logger().info(f"removed {len(self._state_claim.removed)} temporary file(s) of interrupted "
                                   f"saves of {path}: {names}")
        if not os.path.lexists(path):
            self.state_status = f"state file {path} not found: starting fresh"
            return
        try:
            self.pipeline.load_state(path)
        except StateFileError as exc:
            reason = str(exc)
        else:
            self.state_status = f"resumed from {path} ({self.pipeline.bank.k} samples)"
            return
        try:
            aside = set_aside(path)
        except OSError as exc:
            self._state_path = ""
            self.release_state_file()
            self.state_status = (f"state file ignored: {reason}; it could not be moved aside ({exc}), so it is "
                                 "left as it is and no state is saved this run")
            self.get_logger().error(self.state_status)
            self._state_said = True
            return
        self.state_status = f"state file ignored: {reason}; kept as {aside}; a fresh state will be saved to {path}"
        self.get_logger().warning(self.state_status)
        self._state_said = True

    def save_state(self) -> None:
        path = self._state_path
        if path:
            try:
                self.pipeline.save_state(path)
            except OSError as exc:
                self.get_logger().error(f"cannot save state to {path}: {exc}")

    def release_state_file(self) -> None:
        """Free the state file's lock (after the last save)."""
        if self._state_claim is not None:
            self._state_claim.release()
            self._state_claim = None

    # ------------------------------------------------------------------ diagnostics
    def _namesakes(self) -> int:
        """Other nodes on the ROS graph with this node's fully qualified name."""
        me = (self.get_name(), self.get_namespace())
        return max(0, sum(1 for name_ns in self.get_node_names_and_namespaces() if tuple(name_ns) == me) - 1)

    def _publish_diagnostics(self) -> None:
        """One :class:`.diagnostics.Snapshot` per period in, one ``DiagnosticArray`` out."""
        now_ns = self.get_clock().now().nanoseconds
        wall = time.monotonic()
        publishers = {kind: sub.get_publisher_count() for kind, sub in self._subs.items()}
        topics = {kind: sub.topic_name for kind, sub in self._subs.items()}
        for line in self._silent.update(self, wall, publishers, topics, self.pipeline.required,
                                        self.node_cfg.diagnostics_window, self.node_cfg.reliable):
            self.get_logger().warning(line)
        snapshot = Snapshot(
            counters=self.pipeline.counters(),
            models=[(m.output, self.pipeline.model_report(j)) for j, m in enumerate(self.config.models)],
            required=tuple(self.pipeline.required),
            max_gap=self.config.inputs.max_gap,
            now_ns=now_ns,
            elapsed_s=wall - self._last_diag,
            publishers=publishers,
            topics=topics,
            reliable=self.node_cfg.reliable,
            enabled=self.pipeline.enabled,
            state_file=self.state_status,
            latencies_s=self._latencies,
            cpu_times_s=self._cpu_times,
            namesakes=self._namesakes(),
        )
        self._last_diag = wall
        self._latencies, self._cpu_times = [], []
        arr = DiagnosticArray()
        arr.header.stamp = self.get_clock().now().to_msg()
        arr.status = [
            DiagnosticStatus(level=bytes((s.level,)), name=s.name, message=s.message, hardware_id=s.hardware_id,
                             values=[KeyValue(key=k, value=v) for k, v in s.values])
            for s in self._diagnostics.update(snapshot)
        ]
        self._diag_pub.publish(arr)
        for index, raw in self._layout.encode_fit(self.pipeline):  # ~/M/fit, ~/M/identifiability
            self._fit_pubs[index].publish(raw)
        for line in self._diagnostics.alerts.due():  # a misconfigured data path, throttled
            self.get_logger().warning(line)


def _overrides(values: dict[str, Any]) -> list[RosParameter]:
    """The start-up values checked by :func:`.settings.sources.startup_parameters`, as the node declares
    them: they replace rcl's reading of the same arguments, so the node starts with exactly
    what was checked (an integer given for a floating-point parameter is that number, as in
    the replay). rclpy types a parameter by its value, and an empty list has no type: an empty
    list of names is declared as ``[""]``, which the configuration reads as empty."""
    return [RosParameter(p.name, value=values[p.name] if values[p.name] != [] else [""])
            for p in PARAMETERS if p.name in values]


def _refuse(exc: Exception) -> int:
    """A misconfiguration in one line on stderr; exit status 2."""
    print(f"{NODE_NAME}: invalid configuration: {' '.join(str(exc).split())}", file=sys.stderr)
    return 2


def main(args: list[str] | None = None) -> int:
    """Console script ``estimator_node`` (``ros2 run rls_uncertainty estimator_node``).

    ``args`` is the command line as ``rclpy.init`` takes it (default ``sys.argv``). Its ROS
    arguments are checked before rcl reads them (:func:`rls_uncertainty.settings.sources.startup_parameters`, the policy
    in :mod:`.config`): a misconfiguration is one line and exit status 2, before any DDS.
    DDS discovery follows the environment (``ROS_AUTOMATIC_DISCOVERY_RANGE``, ROS's default
    otherwise): a control room spans machines."""
    argv = list(sys.argv if args is None else args)
    try:
        startup = startup_parameters(argv, NODE_NAME)
    except ConfigError as exc:
        return _refuse(exc)
    try:
        rclpy.init(args=argv)
    except (_rclpy.RCLError, _rclpy.UnknownROSArgsError) as exc:  # an argument rcl reads differently
        return _refuse(exc)
    node = None
    code = 0
    try:
        node = EstimatorNode(parameter_overrides=_overrides(startup.values))
        for note in startup.warnings:
            node.get_logger().warning(note)
        # Everything allocated so far lives for the whole run: keep it out of the cyclic
        # collector, whose full passes otherwise show up as millisecond latency spikes.
        gc.freeze()
        rclpy.spin(node)
    except (ConfigError, ParameterException) as exc:
        code = _refuse(exc)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except _rclpy.RCLError:
        if rclpy.ok():
            raise
        # Ctrl-C between start-up and spinning: rclpy's handler had shut the context down, and
        # spin() could not make its executor. An interrupt, not an error.
    finally:
        if node is not None:
            node.save_state()
            node.release_state_file()
            node.destroy_node()
        rclpy.try_shutdown()
    return code


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
