"""``estimator_node``: the live ROS 2 adapter over :class:`.pipeline.Pipeline`.

The node only converts, schedules and publishes: messages of the topics and types of
:mod:`.inputs` are taken in batches each intake period (``intake_period``; by default the
estimator period, at most 5 ms),
decoded by :mod:`.cdr` and go through :func:`.inputs.feed` in order of arrival (the code and
order of the offline replay), and every completed sample is published as the messages of
:mod:`.outputs` (``~/sample_stamp``, then per ready model M ``~/M/estimates``, its standard
errors, convergence flags and decimated covariances), serialized there: the node publishes the
bytes :meth:`.outputs.OutputLayout.encode` makes, on the publisher of each topic index, for
the topics that have a subscriber (:mod:`.sample_publishers`). The node runs on rclpy's
events executor (:func:`_spin`).
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

if __name__ == "__main__":  # pragma: no cover - run in a subprocess by the tests
    # ``python -m rls_uncertainty.ros.node`` (the demo, the testing plugin, the docs): this copy
    # only loads the module again and runs its main, so that Ctrl-C while the node loads (about
    # a second) ends it as the ``estimator_node`` console script does, in one line with exit
    # status 130 instead of a traceback (:class:`.interrupt.SigintWhileLoading`), also when it
    # comes back as another exception or was swallowed, or lands as the module hands over.
    import importlib
    import sys as _sys

    _loading, _started = None, False
    try:
        from rls_uncertainty.ros.interrupt import SigintWhileLoading

        with SigintWhileLoading() as _loading:
            _main = importlib.import_module("rls_uncertainty.ros.node").main
        if _loading.stopped():
            raise KeyboardInterrupt
        _started = True
        _code = _main()
    except (KeyboardInterrupt, Exception) as _exc:
        if not isinstance(_exc, KeyboardInterrupt) and (_loading is None or not _loading.stopped(_exc)):
            raise
        _said = "" if _started else " while starting; nothing written"
        print(f"estimator_node: stopped by SIGINT{_said}", file=_sys.stderr)
        _code = 130
    _sys.exit(_code)

import gc
import math
import sys
import time
from collections.abc import Callable
from typing import Any

import rclpy
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor, SetParametersResult
from rclpy.clock import Clock, ClockChange, ClockType, JumpThreshold, TimeJump
from rclpy.duration import Duration
from rclpy.event_handler import PublisherEventCallbacks
from rclpy.exceptions import ParameterException
from rclpy.executors import ExternalShutdownException
from rclpy.experimental import EventsExecutor
from rclpy.impl.implementation_singleton import rclpy_implementation as _rclpy
from rclpy.node import Node
from rclpy.parameter import Parameter as RosParameter
from rclpy.qos import QoSDurabilityPolicy, QoSHistoryPolicy, QoSProfile, QoSReliabilityPolicy, qos_profile_sensor_data
from rclpy.task import Future
from std_srvs.srv import SetBool, Trigger

from ..datapath.cdr import decode
from ..datapath.diagnostics import DiagnosticsPolicy, Status, malformed_reason, malformed_warning
from ..datapath.diagnostics_round import DiagnosticsRound
from ..datapath.feasibility import configuration_warnings
from ..datapath.inputs import MESSAGE_TYPES, STREAMS, feed, message_class
from ..datapath.load_policy import LoadPolicy
from ..datapath.maneuvers import EVENT
from ..datapath.outputs import NODE_NAME, OutputLayout
from ..datapath.pipeline import Pipeline, SampleOutput
from ..errors import ConfigError
from ..settings.config import intake_period
from ..settings.parameters import PARAMETERS, Parameter, node_config, pipeline_config
from ..settings.sources import NodeParameters, startup_parameters
from .input_watch import SilentInputs
from .intake import Backlog, Intake
from .interrupt import sigint_through_rclpy
from .maneuvers import LiveManeuvers
from .node_state import NodeStateFile
from .sample_publishers import SamplePublishers

__all__ = ["EstimatorNode", "main", "NODE_NAME"]

_TYPES = {kind: message_class(MESSAGE_TYPES[kind]) for kind in STREAMS}
# No QoS-event handlers: rclpy's executor walks every handler on every wait, which cost more
# CPU than the estimation itself. A QoS mismatch on an input shows in /diagnostics instead
# (``<stream>.publishers`` is 0 and the stream is reported silent).
_NO_EVENTS = PublisherEventCallbacks(use_default_callbacks=False)


# The longest an intake pass feeds before the executor's other work gets a turn.
_PASS_BUDGET_S = 0.01


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
        self.node_cfg = node_config(params)
        for line in configuration_warnings(self.config, self.node_cfg.topics):
            self.get_logger().warning(line)
        self.pipeline = Pipeline(self.config, enabled=self.node_cfg.enabled)
        self._state = NodeStateFile(self.node_cfg.state_file)
        self._state.load(self.pipeline, self.get_logger())
        self._latencies: list[float] = []  # wall time from message to last publish
        # CPU time (without preemption) of feeding every message since the previous sample's
        # publish, and of publishing: a sample's share of the input work, read once per sample.
        self._cpu_times: list[float] = []
        self._cpu_since_sample = 0.0
        self._malformed_logged: set[str] = set()  # inputs whose first malformed message was logged
        self._diagnostics = DiagnosticsPolicy(self.get_fully_qualified_name(),
                                              window_s=self.node_cfg.diagnostics_window)
        self._last_diag = time.monotonic()
        self._waits: list[float] = []  # per intake pass, how long its oldest message waited
        self._overload_said: str | None = None  # "cannot keep up: ..." while it is so (logged once)
        self._periodic: list[float] = []  # wall time of each step of periodic work since the last report
        self._round: DiagnosticsRound | None = None  # the diagnostics period in progress
        self._silent = SilentInputs()  # input topics nobody publishes, logged once
        # When each stream's newest message arrived (steady clock): its age in /diagnostics, so a
        # bag's recorded stamps and /clock do not make a fresh stream look stale.
        self._arrived: dict[str, float] = {}

        # Transient local: a subscriber that joins late (a dashboard) gets the last qos.depth
        # samples at once; volatile subscribers match as before. Keep-last bounds the memory.
        out_qos = QoSProfile(depth=self.node_cfg.depth, reliability=QoSReliabilityPolicy.RELIABLE,
                             history=QoSHistoryPolicy.KEEP_LAST, durability=QoSDurabilityPolicy.TRANSIENT_LOCAL)
        # ~/M/fit and ~/M/identifiability, once per diagnostics period: the latest kept for late joiners.
        fit_qos = QoSProfile(depth=1, reliability=QoSReliabilityPolicy.RELIABLE,
                             durability=QoSDurabilityPolicy.TRANSIENT_LOCAL, history=QoSHistoryPolicy.KEEP_LAST)
        self._out = SamplePublishers(self, out_qos, fit_qos, _NO_EVENTS)
        self._layout = OutputLayout.of(self.pipeline)
        self._out.follow(self._layout)
        self._diag_pub = self.create_publisher(DiagnosticArray, "/diagnostics", 10, event_callbacks=_NO_EVENTS)
        in_qos = _input_qos(self.node_cfg.reliable, self.node_cfg.depth)
        self._intake = Intake(self, _TYPES, self.node_cfg.topics, in_qos)  # off the executor: taken in batches
        self._subs = self._intake.subs
        self._backlog = Backlog()  # taken, not yet fed
        # maneuvers.source events/detect: the test points' boundaries and ~/maneuvers (ros/maneuvers.py).
        self._maneuvers = LiveManeuvers(self, self.pipeline) if self.config.maneuvers.source != "off" else None
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
        diagnose = unless_stopped(self, self._publish_diagnostics)
        self.create_timer(self.node_cfg.diagnostics_period, diagnose, clock=steady)
        period = intake_period(self.node_cfg.intake_period, self.config.rate)
        self._intake_timer = self.create_timer(period, unless_stopped(self, self._take_inputs), clock=steady)
        if self.node_cfg.state_file and self.node_cfg.state_save_period > 0:
            self.create_timer(self.node_cfg.state_save_period, self.save_state, clock=steady)
        models = ", ".join(f"{m.output}({len(m.regressors)})" for m in self.config.models)
        est = self.config.estimator
        lags = f"auto (at most {est.max_lags})" if est.lags == "auto" else est.lags  # (samples: lag_span x rate)
        self.get_logger().info(
            f"estimating {models} at {self.config.rate:g} Hz, {lags} lags, aircraft {self.config.aircraft.name}; "
            f"inputs {', '.join(self.node_cfg.topics[k] for k in STREAMS)}, taken every "
            f"{period * 1e3:g} ms; "
            + self._state.startup_text()
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
        self._intake_timer.timer_period_ns = int(intake_period(self.node_cfg.intake_period, new.rate) * 1e9)
        self._diagnostics.window_s = self.node_cfg.diagnostics_window
        if new != self.config:
            changed = ", ".join(sorted(p.name for p in params))
            old_fp, new_fp = self.config.fingerprint(), new.fingerprint()
            what = "estimator reset" if old_fp != new_fp else "pipeline restarted"
            self.get_logger().warning(f"parameters changed ({changed}): {what}")
            for line in configuration_warnings(new, self.node_cfg.topics):
                self.get_logger().warning(line)
            self.config = new
            self.pipeline = self.pipeline.reconfigured(new)
            if self._maneuvers is not None:
                self._maneuvers.follow(self.pipeline)
            self._layout = OutputLayout.of(self.pipeline)
            self._out.follow(self._layout)

    # ------------------------------------------------------------------ data path
    def destroy_node(self) -> None:
        self._intake.destroy()
        if self._maneuvers is not None:
            self._maneuvers.destroy()
        super().destroy_node()

    def _take_inputs(self) -> None:
        """Every message the input subscriptions hold, taken at once each intake period
        (:func:`..settings.config.intake_period`) and fed to :func:`.inputs.feed` in order of arrival
        (:func:`.inputs.arrival_order`, the reception times of the middleware, :mod:`.intake`): the offline
        replay feeds the same messages in the same order. A pass feeds for at most
        :data:`_PASS_BUDGET_S`; the rest of the batch is fed by the next passes before anything
        new is taken (:class:`.intake.Backlog`). Latency is counted from the arrival of the
        message that completed a sample to its last publish."""
        if self._round is not None:
            self._diagnostics_step()
        backlog = self._backlog
        if not backlog:
            taken = self._intake.take()
            maneuvers = self._maneuvers
            events = maneuvers.take() if maneuvers is not None else {}
            if not any(taken.values()) and not any(events.values()):
                return
            now = time.monotonic()
            for kind, queued in taken.items():
                if queued:
                    self._arrived[kind] = now  # the stream's age in /diagnostics runs from here
            backlog.refill(taken | events)  # (the events merged in order of arrival with the inputs)
        self._feed(time.perf_counter() + _PASS_BUDGET_S)

    def _feed(self, deadline: float) -> None:
        """Feed the backlog in order until it is empty or ``deadline`` (``time.perf_counter``)
        has passed, at least one message."""
        backlog, pipeline, start = self._backlog, self.pipeline, time.time_ns()
        if not backlog:
            return
        self._waits.append(max(start - backlog.oldest(start), 0) * 1e-9)
        if pipeline.needs_clock:  # inputs.max_clock_offset: stamps are checked against it
            pipeline.clock_ns = self.get_clock().now().nanoseconds
        maneuvers, queue, perf_counter, msgtypes = self._maneuvers, backlog.queue, time.perf_counter, MESSAGE_TYPES
        pop = queue.popleft
        c0 = time.thread_time()
        while queue and perf_counter() < deadline:
            kind, (arrived, raw) = pop()
            if kind == EVENT:
                maneuvers.event(raw)  # type: ignore[union-attr]  # (events come only with maneuvers)
                continue
            try:
                msg = decode(msgtypes[kind], raw)
                if kind == "control_surfaces" and maneuvers is not None:  # (maneuvers.source detect)
                    maneuvers.surfaces(msg)
                outputs = feed(pipeline, kind, msg)
            except Exception as exc:  # noqa: BLE001 - a bad message must never stop the node
                self._malformed(kind, exc)
                continue
            if outputs:
                for out in outputs:
                    self._publish(out)
                self._latencies.append((time.time_ns() - (arrived or start)) * 1e-9)
                c1 = time.thread_time()
                self._cpu_times.append(self._cpu_since_sample + c1 - c0)
                self._cpu_since_sample, c0 = 0.0, c1
        self._cpu_since_sample += time.thread_time() - c0

    def _malformed(self, kind: str, exc: Exception) -> None:
        """Count a message that could not be decoded or fed; log the first one per input."""
        self.pipeline.reject(kind, malformed_reason(exc), str(exc))
        if kind not in self._malformed_logged:
            self._malformed_logged.add(kind)
            self.get_logger().warning(malformed_warning(self._subs[kind].topic_name, exc))

    def _publish(self, out: SampleOutput) -> None:
        """A sample's messages, on the topics someone subscribes to (:mod:`.sample_publishers`)."""
        self._out.publish(out, self.node_cfg.frame_id)
        if self._maneuvers is not None:
            self._maneuvers.sample(out)

    # ------------------------------------------------------------------ services, time
    def _on_reset(self, request: Trigger.Request, response: Trigger.Response) -> Trigger.Response:
        self._feed(math.inf)  # what was taken before the call is fed before it, as it arrived
        self.pipeline.reset("service")  # the estimator and every input state: older stamps are accepted again
        response.success = True
        response.message = "estimator and inputs reset: estimates restart from the next messages, whatever their stamps"
        self.get_logger().info(response.message)
        return response

    def _on_enable(self, request: SetBool.Request, response: SetBool.Response) -> SetBool.Response:
        enabled = bool(request.data)
        self._feed(math.inf)  # what was taken before the call is fed before it, as it arrived
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
                self.get_logger().warning(f"time jumped {delta * 1e-9:+.3f} s: estimator and inputs restart when "
                                          "the stamps follow")
            else:
                self.get_logger().info(f"time jumped {delta * 1e-9:+.3f} s: the inputs are already near the new time")

    def save_state(self) -> None:
        """Save the estimator's state to ``state_file`` (a periodic step, timed)."""
        t0 = time.perf_counter()
        if self._state.save(self.pipeline, self.get_logger()):
            self._periodic.append(time.perf_counter() - t0)

    def release_state_file(self) -> None:
        """Free the state file's lock (after the last save)."""
        self._state.release()

    # ------------------------------------------------------------------ diagnostics
    def _namesakes(self) -> int:
        """Other nodes on the ROS graph with this node's fully qualified name."""
        me = (self.get_name(), self.get_namespace())
        return max(0, sum(1 for name_ns in self.get_node_names_and_namespaces() if tuple(name_ns) == me) - 1)

    def _publish_diagnostics(self) -> None:
        """Start one :class:`.diagnostics_round.DiagnosticsRound`: here only the node's own
        facts are read (constant time); the rest runs one step per intake pass
        (:meth:`_diagnostics_step`), before the pass feeds."""
        t0 = time.perf_counter()
        if self._round is not None:  # the previous round has not finished: it goes on
            return
        wall = time.monotonic()
        self._out.refresh(self.node_cfg.frame_id)  # which outputs anyone subscribes to
        publishers = {kind: sub.get_publisher_count() for kind, sub in self._subs.items()}  # graph cache reads
        topics = {kind: sub.topic_name for kind, sub in self._subs.items()}
        for line in self._silent.update(self, wall, publishers, topics, self.pipeline.required,
                                        self.node_cfg.diagnostics_window, self.node_cfg.reliable):
            self.get_logger().warning(line)
        facts = {
            "required": tuple(self.pipeline.required), "max_gap": self.config.inputs.max_gap,
            "now_ns": self.get_clock().now().nanoseconds, "elapsed_s": wall - self._last_diag,
            "publishers": publishers, "topics": topics, "reliable": self.node_cfg.reliable,
            "enabled": self.pipeline.enabled, "state_file": self._state.status,
            "latencies_s": self._latencies, "cpu_times_s": self._cpu_times, "namesakes": self._namesakes(),
            "periodic_s": self._periodic, "waits_s": self._waits, "period_s": 1.0 / self.config.rate,
            "arrival_ages_s": {kind: wall - t for kind, t in self._arrived.items()},
            "frequency_every": self.config.frequency.every if self.config.frequency is not None else 0,
            "covariance_decimation": self.config.outputs.covariance_decimation,
            "buffer_duration": self.config.inputs.buffer_duration,
            "shed": self.node_cfg.shed_load, "outputs_subscribed": self._out.subscribed,
            "intake_period_s": self._intake_timer.timer_period_ns * 1e-9,
            "queues_full": self._intake.full_queues(), "queue_depth": self._intake.depth,
        }
        self._last_diag = wall
        self._latencies, self._cpu_times, self._periodic, self._waits = [], [], [], []
        self._round = DiagnosticsRound(self.pipeline, self._layout, self._diagnostics, facts,
                                       self._out.publish_fit, self._publish_statuses)
        self._periodic.append(time.perf_counter() - t0)

    def _diagnostics_step(self) -> None:
        """One step of the running round; the next is due on the next intake pass. A round
        whose pipeline was reconfigured meanwhile is dropped (the next period reports)."""
        t0 = time.perf_counter()
        r = self._round
        if r is None:
            return
        if r.pipeline is not self.pipeline or r.layout is not self._layout or r.step():
            self._round = None
        self._periodic.append(time.perf_counter() - t0)

    def _publish_statuses(self, statuses: list[Status]) -> None:
        if self._maneuvers is not None:
            self._maneuvers.publish()
            statuses = [*statuses, self._maneuvers.status(self.get_fully_qualified_name())]
        arr = DiagnosticArray()
        arr.header.stamp = self.get_clock().now().to_msg()
        arr.status = [
            DiagnosticStatus(level=bytes((s.level,)), name=s.name, message=s.message, hardware_id=s.hardware_id,
                             values=[KeyValue(key=k, value=v) for k, v in s.values])
            for s in statuses
        ]
        self._diag_pub.publish(arr)
        overload = self._diagnostics.overload
        if overload is not None and self._overload_said is None:  # said once per episode
            self.get_logger().warning(overload)
        elif overload is None and self._overload_said is not None:
            self.get_logger().info("keeping up with the inputs again")
        self._overload_said = overload
        load = self._diagnostics.load
        if load is not None:  # the degradation policy's step of this period, said once
            _shed(self.pipeline, load)
            for line in load.said:  # a step down is a warning, a step back news
                if line.startswith("degraded"):
                    self.get_logger().warning(line)
                else:
                    self.get_logger().info(line)
        for line in self._diagnostics.alerts.due():  # a misconfigured data path, throttled
            self.get_logger().warning(line)


def unless_stopped(node: Node, callback: Callable[[], None]) -> Callable[[], None]:
    """``callback`` for a timer of ``node``: an exception raised because a stop shut the node's
    context down while the callback ran ends it quietly, as the spin then ends (rclpy's signal
    handler shuts the context down from its own thread, so a pass feeding a backlog found its
    next publish failing with "publisher's context is invalid", which the executor reported as
    a FATAL exception with a traceback); any other exception goes on to the executor."""

    def run() -> None:
        try:
            callback()
        except Exception:
            if node.context.ok():
                raise

    return run


def _shed(pipeline: Pipeline, load: LoadPolicy) -> None:
    """Apply the degradation policy's settings (:mod:`.load_policy`) to ``pipeline``."""
    if pipeline.frequency is not None and load.base[0]:
        pipeline.frequency.every = load.frequency_every
    if load.base[1]:
        pipeline.covariance_every = load.covariance_decimation


def _overrides(values: dict[str, Any]) -> list[RosParameter]:
    """The start-up values checked by :func:`.settings.sources.startup_parameters`, as the node declares
    them: they replace rcl's reading of the same arguments, so the node starts with exactly
    what was checked (an integer given for a floating-point parameter is that number, as in
    the replay). rclpy types a parameter by its value, and an empty list has no type: an empty
    list of names is declared as ``[""]``, which the configuration reads as empty."""
    return [RosParameter(p.name, value=values[p.name] if values[p.name] != [] else [""])
            for p in PARAMETERS if p.name in values]


def _spin(node: Node) -> None:
    """Run ``node`` on rclpy's events executor until the context shuts down (Ctrl-C and
    SIGTERM shut it down: :mod:`.interrupt`). It wakes only for what is due
    instead of rebuilding a wait set on every turn: an idle node costs a third of the CPU it
    does on the single-threaded executor (docs/benchmarks.md). Spun until a future that never
    completes, with a finite timeout (its ``spin()`` without one busy-waits): one call serves
    every event of a second, where ``spin_once`` costs its set-up per event (about 60 us, at
    each of the intake timer's 200 wakes a second)."""
    executor = EventsExecutor()
    executor.add_node(node)
    never = Future()
    try:
        while rclpy.ok():
            executor.spin_until_future_complete(never, timeout_sec=1.0)
    finally:
        executor.shutdown()


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
    with sigint_through_rclpy() as rclpy_is_up:
        try:
            rclpy.init(args=argv)
        except (_rclpy.RCLError, _rclpy.UnknownROSArgsError) as exc:  # an argument rcl reads differently
            return _refuse(exc)
        rclpy_is_up()
        return _run(startup)


def _run(startup: NodeParameters) -> int:
    """The node of ``startup``'s parameters, spun until the context shuts down; its exit status."""
    node = None
    code = 0
    try:
        node = EstimatorNode(parameter_overrides=_overrides(startup.values))
        for note in startup.warnings:
            node.get_logger().warning(note)
        # Everything allocated so far lives for the whole run: keep it out of the cyclic
        # collector, whose full passes otherwise show up as millisecond latency spikes.
        gc.freeze()
        _spin(node)
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

