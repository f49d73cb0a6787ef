"""The ``/diagnostics`` statuses of the estimator node, computed without ROS.

The node collects one :class:`Snapshot` per diagnostics period, the pipeline's bookkeeping
(:meth:`.pipeline.Pipeline.counters`, :meth:`.pipeline.Pipeline.model_fit`) plus the few facts
only the node knows (its clock, matched publishers, the period, callback latencies), and
:meth:`DiagnosticsPolicy.update` turns it into :class:`Status` records: name, level, message and
ordered key-values. The node only converts them into a ``diagnostic_msgs/DiagnosticArray``.

Three statuses, named ``<node>: ...`` (:func:`status_prefix`: ``rls_estimator: inputs`` for the
node in the root namespace, as always, and the fully qualified name under a namespace,
``/ns/rls_estimator: inputs``, so two namespaced nodes never share a status name on
``/diagnostics``; ``hardware_id`` is the same ``<node>``):

* ``inputs``: ``recent_window_s``, then per stream ``required``, ``publishers``, ``rate_hz``,
  ``age_s`` (seconds since the stream's newest message arrived, on the node's steady clock:
  neither the stamps' origin nor ``/clock`` matters), the cumulative ``received``,
  ``accepted``, ``expired``, ``missing``, the counts of the recent window ``recent.rejected``,
  ``recent.missing``, ``recent.expired``, and the cumulative ``rejected.<reason>``. WARN
  when a required stream is silent or stale (older than ``max(1 s, 2 max_gap)``; with a hint
  when no publisher matched), or when messages were
  rejected, missing or expired *within the recent window*: one dropped packet warns for
  ``window_s`` seconds, not for the rest of the flight (the cumulative counters stay beside).
  ERROR when the data path is misconfigured (:mod:`.alerts`: every message of a needed stream
  rejected, or no sample used for a window although messages arrive): the alerts' texts, which
  name what was expected, what came and the parameter to change, come first in the message.
* ``samples``: ``enabled``, ``samples_formed``, ``samples_used``, ``samples_pending``,
  ``samples_rejected.<reason>``, ``resets.<reason>``, ``unknown_joint.<name>``, callback
  latency and CPU percentiles of the period, from the node ``intake_period_ms`` (the intake
  period in effect), ``intake_wait_ms.p99`` (how long inputs waited to be fed),
  ``periodic_ms.max`` (the longest step of the node's periodic work, which holds up the input
  callbacks for that long),
  ``state_file``, ``nodes_with_this_name``, and from the node ``outputs_subscribed`` (its
  sample topics that had a subscriber at the period's start: the ones it publishes; a
  listener reads it back with :func:`outputs_discovered`). OK, or
  ERROR while another node with this node's fully qualified name is on the ROS graph (its
  outputs then mix with this node's on the same topics: every consumer receives each sample
  from both): the text first in the message, and logged as a warning (throttled like the
  alerts). WARN while the node cannot keep up with its inputs (:func:`overload`), the text
  first, and while it sheds work (:mod:`.load_policy`: ``load.frequency_every``,
  ``load.covariance_decimation`` and ``degraded: ...`` in the message). While the node is the
  cause (:func:`.load_policy.cause`), the ``inputs`` status and the alerts name it instead of
  guessing at the transport or the clocks (:func:`.load_policy.blame`).
* ``model M``: the model fit, and the convergence flags when the node hands them in
  (``converged``, ``converged_parameters``) with the identifiability figures
  (:mod:`.identifiability`: ``identifiable``, ``not_identifiable``, ``held_back``,
  ``max_parameter_correlation``, ``excitation.<regressor>``); OK when ready, WARN while a
  parameter's convergence flag is held back as not identifiable (the message says why, naming
  the regressors and the figure); while initializing OK until the first sample is used, WARN
  after (naming the regressor that does not move, or the two that move together, once
  ``convergence.window`` of samples has not initialized the model).

**The window.** The policy keeps, per snapshot, the steady time (the sum of ``elapsed_s``)
and the totals of the counters (:class:`.bookkeeping.Window`). The recent counts are the
current totals minus those of the newest snapshot at least ``window_s`` old (the node's start
before the first ``window_s`` seconds), so the window spans ``window_s`` to ``window_s`` plus
one period; the history holds about ``window_s / period`` totals.

**Bounded size.** Whatever arrives, each table of names (a stream's rejection reasons,
rejected samples, resets, unknown joints) shows at most ``max_keys`` entries, the largest
counts first, then ``<table>_other_names`` and ``<table>_other_count`` for the rest; a name
is cut to :data:`MAX_NAME` characters (with a hash, so keys stay unique) and unprintable
characters become ``?``; a value is cut to :data:`MAX_VALUE` characters. The ``inputs`` status
holds at most ``1 + 5 (13 + max_keys)`` key-values, ``samples`` at most ``13 + 3 (2 +
max_keys)``.
"""

from __future__ import annotations

import heapq
import zlib
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field, replace

from .alerts import Alert, AlertPolicy
from .bookkeeping import NO_TOTALS, Totals, Window, increase
from .load_policy import CLOCKS, NODE, LoadPolicy, Timing, behind, blame, cause, clock_text, keep_up_text
from .outputs import NODE_NAME
from .states import initializing

__all__ = [
    "OK",
    "WARN",
    "ERROR",
    "STALE",
    "Status",
    "Snapshot",
    "DiagnosticsPolicy",
    "stale_after",
    "percentile",
    "malformed_reason",
    "malformed_warning",
    "status_prefix",
    "namesake_alert",
    "OUTPUTS_SUBSCRIBED",
    "outputs_subscribed",
    "outputs_discovered",
    "MAX_KEYS",
    "MAX_NAME",
    "MAX_VALUE",
]

MAX_KEYS = 16  # entries shown per table of names (rejection reasons, unknown joints, ...)
MAX_NAME = 64  # characters of a name inside a key
MAX_VALUE = 1024  # characters of a value

# The ``samples`` status's key for the node's sample topics with a subscriber (the ones it publishes on).
OUTPUTS_SUBSCRIBED = "outputs_subscribed"

# diagnostic_msgs/DiagnosticStatus levels (the message defines them as bytes 0..3).
OK, WARN, ERROR, STALE = 0, 1, 2, 3


@dataclass(frozen=True)
class Status:
    """One ``diagnostic_msgs/DiagnosticStatus``: values are ``(key, text)`` pairs, in order."""

    name: str
    level: int
    message: str
    values: tuple[tuple[str, str], ...]
    hardware_id: str = NODE_NAME


@dataclass(frozen=True)
class Snapshot:
    """What one diagnostics period saw.

    ``counters`` is :meth:`.pipeline.Pipeline.counters`; ``models`` pairs each configured
    model's output name with :meth:`.pipeline.Pipeline.model_fit`; ``required`` lists the
    streams the samples need and ``max_gap`` (s) is the configured largest interpolated gap.
    The rest only the node knows: its clock (``now_ns``, simulated under ``use_sim_time``), when
    each stream's newest message arrived (``arrival_ages_s``), the steady time since the previous snapshot
    (``elapsed_s``), the publishers matched per input and the resolved topic names, the QoS
    choice, the wall and CPU times of the callbacks that produced outputs in the period, the
    wall time of each step of the node's periodic work (``periodic_s``), the
    state-file status, whether estimation is enabled and how many other nodes on the graph
    carry this node's fully qualified name (``namesakes``).
    """

    counters: Mapping
    models: Sequence[tuple[str, Mapping]]
    required: Sequence[str]
    max_gap: float
    now_ns: int
    elapsed_s: float
    publishers: Mapping[str, int]
    topics: Mapping[str, str]
    reliable: bool
    enabled: bool
    state_file: str
    latencies_s: Sequence[float] = field(default_factory=tuple)
    cpu_times_s: Sequence[float] = field(default_factory=tuple)
    namesakes: int = 0  # other nodes on the ROS graph with this node's fully qualified name
    # Seconds since each stream's newest message arrived, on the node's steady clock (a stream
    # never heard from is absent). When given, it is the streams' age; without it (the offline
    # replay) the age is ``now_ns`` minus the stream's newest stamp.
    arrival_ages_s: Mapping[str, float] | None = None
    periodic_s: Sequence[float] = field(default_factory=tuple)  # wall time of each periodic job step
    waits_s: Sequence[float] = field(default_factory=tuple)  # per intake pass, how long its oldest input waited
    period_s: float = 0.0  # the estimator period (1 / rate)
    intake_period_s: float = 0.0  # the node's intake period in effect (0: the offline replay, which has none)
    # What the degradation policy (:mod:`.load_policy`) starts from: the configured
    # frequency.every (0: no frequency domain) and outputs.covariance_decimation, and the stamp
    # spread between streams beyond which a constant one is another clock (inputs.buffer_duration).
    frequency_every: int = 0
    covariance_decimation: int = 0
    buffer_duration: float = 1.0
    shed: bool = False  # the node sheds work while it cannot keep up (shed_load)
    # The node's sample topics with a subscriber at the period's start, the ones it publishes
    # (None: the offline replay, which publishes none).
    outputs_subscribed: int | None = None
    # Per input stream, the intake passes of the period that found its queue full (qos.depth
    # messages, ``queue_depth``): the middleware dropped the oldest, unseen by the node.
    queues_full: Mapping[str, int] = field(default_factory=dict)
    queue_depth: int = 0


def status_prefix(node: str) -> str:
    """What every status of ``node`` (a fully qualified name, or a name in the root namespace)
    is named after: the bare name in the root namespace (``rls_estimator``, the form consumers
    have always matched), the fully qualified name under a namespace (``/ns/rls_estimator``)."""
    full = node if node.startswith("/") else f"/{node}"
    namespace, _, name = full.rpartition("/")
    return full if namespace else name


def outputs_subscribed(values: Mapping[str, str] | Iterable[tuple[str, str]]) -> int:
    """The :data:`OUTPUTS_SUBSCRIBED` count among the key-values of a node's ``samples`` status
    (a mapping or ``(key, value)`` pairs, as received): how many sample topics the node
    publishes on; -1 when the key is missing or its value is not a count."""
    text = dict(values).get(OUTPUTS_SUBSCRIBED)
    try:
        count = int(text) if text is not None else -1
    except (TypeError, ValueError):
        return -1
    return count if count >= 0 else -1


def outputs_discovered(values: Mapping[str, str] | Iterable[tuple[str, str]], matched: int,
                       subscriptions: int) -> bool:
    """Whether discovery matched both ends of a listener's ``subscriptions`` subscriptions to
    the node's sample topics: all of them matched the node's publishers (``matched``, the
    listener's view), and the node's ``samples`` status (``values``, :func:`outputs_subscribed`)
    says it publishes on at least as many sample topics (the node's view, which lags the other
    by seconds on a busy machine: the node publishes only on the topics whose publisher had
    matched a subscriber at its last report, and a sample sent before is lost to the listener)."""
    return matched == subscriptions and outputs_subscribed(values) >= subscriptions


def namesake_alert(node: str, namesakes: int) -> Alert | None:
    """The alert while ``namesakes`` other nodes carry ``node``'s fully qualified name."""
    if namesakes <= 0:
        return None
    full = node if node.startswith("/") else f"/{node}"
    return Alert(("graph", "namesake"), (
        f"{namesakes} other node(s) named {full} on the ROS graph: their outputs mix with this node's on "
        f"{full}/..., so every consumer receives each sample {namesakes + 1} times, and {full}/reset and "
        f"{full}/enable reach any of them; start each node with its own name or namespace "
        "(--ros-args -r __node:=NAME or -r __ns:=/NAMESPACE)"))


def timing(snap: Snapshot, previous_offsets: Mapping[str, float]) -> Timing:
    """The snapshot's :class:`.load_policy.Timing`: the node's waits and CPU per sample, the
    required streams' stamp gaps of the period and, when arrivals are known, each required
    stream's stamp age minus its arrival age."""
    offsets: dict[str, float] = {}
    if snap.arrival_ages_s is not None:
        for kind in snap.required:
            stream, age = snap.counters["streams"].get(kind), snap.arrival_ages_s.get(kind)
            if stream and stream["newest_stamp_ns"] is not None and age is not None:
                offsets[kind] = (snap.now_ns - stream["newest_stamp_ns"]) * 1e-9 - age
    return Timing(snap.period_s, snap.cpu_times_s, snap.waits_s, offsets_s=offsets,
                  previous_offsets_s=previous_offsets, clock_tolerance_s=snap.buffer_duration,
                  queues_full={k: n for k, n in snap.queues_full.items() if n}, queue_depth=snap.queue_depth)


def overload(snap: Snapshot) -> str | None:
    """"cannot keep up: ..." when the node falls behind its inputs (:func:`.load_policy.behind`),
    naming how far behind (p99 of the waits), the CPU per sample (p50) against the period and
    the parameters that lighten the load; None otherwise."""
    t = timing(snap, {})
    if not behind(t):
        return None
    return f"{keep_up_text(t)}; lower rate or estimator.lag_span, or raise frequency.every"


def stale_after(max_gap: float) -> float:
    """Age (s) beyond which a required stream is reported stale: twice the largest gap the
    pipeline interpolates across, at least one second."""
    return max(1.0, 2.0 * max_gap)


def _age(snap: Snapshot, kind: str, newest_stamp_ns: int | None) -> float | None:
    """How old stream ``kind``'s newest message is (s; None: never received): since it arrived
    when the snapshot has arrival ages (the node), else the snapshot's clock minus its stamp."""
    if snap.arrival_ages_s is not None:
        return snap.arrival_ages_s.get(kind)
    return (snap.now_ns - newest_stamp_ns) * 1e-9 if newest_stamp_ns is not None else None


def percentile(sorted_values: Sequence[float], q: float) -> float:
    """The ``q`` quantile (0..1) of ascending ``sorted_values`` as the element at index
    ``min(n - 1, int(q n))`` (no interpolation: a reported latency really happened)."""
    n = len(sorted_values)
    if n == 0:
        raise ValueError("percentile of no values")
    return sorted_values[min(n - 1, int(q * n))]


def malformed_reason(exc: BaseException) -> str:
    """The ``rejected.<reason>`` of a message that could not be decoded or fed."""
    return f"malformed: {type(exc).__name__}"


def malformed_warning(topic: str, exc: BaseException) -> str:
    """The warning logged for the first malformed message of an input: the topic, the
    exception type and its text, and where the later ones are counted."""
    return (f"malformed message on {topic}: {type(exc).__name__}: {exc} (this and later ones are "
            f"counted in /diagnostics as rejected.{malformed_reason(exc)}; only the first is logged)")


def _frequency_clause(fit: Mapping) -> str:
    """The frequency domain's fit in words: R^2, residual lag-1 correlation and convergence,
    or how far it is from publishing."""
    if fit["frequency.ready"]:
        text = f"R^2 {fit['frequency.r_squared']:.3f}, residual lag-1 correlation {fit['frequency.residual_rho1']:.2f}"
        return text + ("; converged" if fit.get("frequency.converged") else "; not converged")
    return f"initializing: {initializing(fit['frequency.samples'], fit['frequency.publish_at_samples'])}"


def _ms(seconds: float) -> str:
    return f"{1e3 * seconds:.3f}"


def _name(text: str) -> str:
    """A name (a joint, a reason) as it appears in a key: printable and at most MAX_NAME
    characters. A name that had to change (cut, or unprintable characters replaced by ``?``)
    ends in a hash of the whole, so keys stay unique."""
    if len(text) <= MAX_NAME and text.isprintable():
        return text
    head = "".join(c if c.isprintable() else "?" for c in text[: MAX_NAME - 12])
    return f"{head}...#{zlib.crc32(text.encode('utf-8', 'surrogatepass')):08x}"


def _table(prefix: str, counts: Mapping[str, int], max_keys: int, noun: str) -> list[tuple[str, object]]:
    """``prefix.<name>`` for the ``max_keys`` largest counts (ties by name), sorted by name, then
    ``prefix_other_<noun>`` and ``prefix_other_count`` for the rest."""
    if len(counts) <= max_keys:
        shown = sorted(counts.items())
    else:
        shown = sorted(heapq.nsmallest(max_keys, counts.items(), key=lambda kv: (-kv[1], kv[0])))
    kv: list[tuple[str, object]] = [(f"{prefix}.{_name(name)}", n) for name, n in shown]
    if len(shown) < len(counts):
        kv += [(f"{prefix}_other_{noun}", len(counts) - len(shown)),
               (f"{prefix}_other_count", sum(counts.values()) - sum(n for _, n in shown))]
    return kv


class DiagnosticsPolicy:
    """Turns one :class:`Snapshot` per period into the node's statuses.

    Stateful: input rates are the received-count differences between consecutive snapshots
    over ``elapsed_s`` (the first period counts from zero), and levels come from the counts of
    the last ``window_s`` seconds (see the module docstring). :attr:`previous` is the last
    snapshot handed in. ``max_keys`` bounds every table of names. ``node_name``: the node's
    fully qualified name (or its name in the root namespace), which names the statuses
    (:func:`status_prefix`).
    """

    def __init__(self, node_name: str = NODE_NAME, window_s: float = 10.0, max_keys: int = MAX_KEYS,
                 repeat_s: float = 30.0) -> None:
        if not window_s > 0:
            raise ValueError(f"window_s must be positive, got {window_s!r}")
        if max_keys < 1:
            raise ValueError(f"max_keys must be at least 1, got {max_keys!r}")
        self.node_name = node_name
        self.window_s = float(window_s)
        self.max_keys = int(max_keys)
        self.previous: Snapshot | None = None
        self.overload: str | None = None  # the samples status's "cannot keep up" text, when it says that
        self.cause: str | None = None  # why inputs are late or missing (:func:`.load_policy.cause`)
        self.clocks: str | None = None  # with cause CLOCKS, the measured offset (:func:`.load_policy.clock_text`)
        self.load: LoadPolicy | None = None  # the degradation ladder of the node's configuration
        self._offsets: dict[str, float] = {}  # the previous period's stamp offsets
        self._load_key: tuple[float, int, int] | None = None  # the configuration self.load is for
        # The misconfiguration alerts (:mod:`.alerts`): first in the inputs status, and the
        # lines to log (alerts.due()), each at most once per repeat_s seconds.
        self.alerts = AlertPolicy(repeat_s)
        self._window = Window(NO_TOTALS)  # the totals of the snapshot that starts the recent window
        # The intake passes that found each input queue full, since the start and over the window.
        self._full_total: dict[str, int] = {}
        self._full_window: Window[dict[str, int]] = Window({})

    def update(self, snap: Snapshot) -> list[Status]:
        """The statuses of this period: ``inputs``, ``samples``, then one per model."""
        now = Totals.of(snap.counters)
        before, _ = self._window.advance(snap.elapsed_s, now, self.window_s)
        alerts = self.alerts.update(snap.elapsed_s, snap.counters, snap.required, snap.enabled, self.window_s)
        namesake = namesake_alert(self.node_name, snap.namesakes)
        if namesake is not None:  # logged with the alerts (AlertPolicy.due), shown in the samples status
            self.alerts.current = [*alerts, namesake]
        self.alerts.models(snap.models)  # identifiability, logged with the alerts
        self._judge_load(snap, before)
        if self.cause in (NODE, CLOCKS):
            alerts = [Alert(a.key, blame(a.text, self.cause, self.clocks)) for a in alerts]
            self.alerts.current = [Alert(a.key, blame(a.text, self.cause, self.clocks)) for a in self.alerts.current]
        for kind, n in snap.queues_full.items():
            self._full_total[kind] = self._full_total.get(kind, 0) + n
        full_before, _ = self._full_window.advance(snap.elapsed_s, dict(self._full_total), self.window_s)
        full = {kind: n - full_before.get(kind, 0) for kind, n in self._full_total.items()}
        statuses = [self._inputs(snap, now, before, alerts, full), self._samples(snap, namesake)]
        statuses += [self._model(name, fit, snap) for name, fit in snap.models]
        self.previous = snap
        return statuses

    def _judge_load(self, snap: Snapshot, before: Totals) -> None:
        """The cause of late or missing inputs, the "cannot keep up" text, and one step of the
        degradation ladder (:mod:`.load_policy`; only with the node's waits measured)."""
        t = timing(snap, self._offsets)
        gaps = sum(increase(Totals.of(snap.counters).missing[k], before.missing.get(k, 0)) for k in snap.required
                   if k in snap.counters["streams"])
        t = replace(t, stamp_gaps=gaps)
        self._offsets = dict(t.offsets_s)
        self.cause = cause(t)
        self.clocks = clock_text(t.offsets_s) if self.cause == CLOCKS else None
        self.overload = overload(snap) if self.cause == NODE else None
        key = (snap.period_s, snap.frequency_every, snap.covariance_decimation)
        if self.load is None or self._load_key != key:  # a new configuration starts unshed
            rate = 1.0 / snap.period_s if snap.period_s > 0 else 1.0
            self.load, self._load_key = LoadPolicy(rate, snap.frequency_every, snap.covariance_decimation), key
        if snap.shed and (snap.waits_s or self.load.degraded):
            self.load.update(self.cause == NODE, snap.elapsed_s)
        else:
            self.load.said = []

    def _status(self, name: str, level: int, message: str, values: list[tuple[str, object]]) -> Status:
        def text(v: object) -> str:
            t = str(v)
            return t if len(t) <= MAX_VALUE else t[: MAX_VALUE - 3] + "..."

        prefix = status_prefix(self.node_name)
        return Status(f"{prefix}: {name}", level, text(message), tuple((k, text(v)) for k, v in values),
                      hardware_id=prefix)

    def _received_before(self, kind: str) -> int:
        if self.previous is None:
            return 0
        stream = self.previous.counters["streams"].get(kind)
        return stream["received"] if stream else 0

    def _inputs(self, snap: Snapshot, now: Totals, before: Totals, alerts: Sequence[Alert],
                full_recent: Mapping[str, int]) -> Status:
        period = max(snap.elapsed_s, 1e-9)
        limit = stale_after(snap.max_gap)
        window = f"in the last {self.window_s:g} s"
        kv: list[tuple[str, object]] = [("recent_window_s", f"{self.window_s:g}")]
        problems: list[str] = []
        for kind, s in snap.counters["streams"].items():
            needed = kind in snap.required
            rate = (s["received"] - self._received_before(kind)) / period
            age = _age(snap, kind, s["newest_stamp_ns"])
            publishers = snap.publishers[kind]
            rejected = increase(now.rejected_total(kind), before.rejected_total(kind))
            missing = increase(now.missing[kind], before.missing.get(kind, 0))
            expired = increase(now.expired[kind], before.expired.get(kind, 0))
            full = full_recent.get(kind, 0)
            kv += [
                (f"{kind}.required", needed),
                (f"{kind}.publishers", publishers),
                (f"{kind}.rate_hz", f"{rate:.1f}"),
                (f"{kind}.age_s", "never received" if age is None else f"{age:.3f}"),
                (f"{kind}.received", s["received"]),
                (f"{kind}.accepted", s["accepted"]),
                (f"{kind}.expired", s["expired"]),
                (f"{kind}.missing", s["missing"]),
                (f"{kind}.recent.rejected", rejected),
                (f"{kind}.recent.missing", missing),
                (f"{kind}.recent.expired", expired),
                (f"{kind}.recent.queue_full", full),
            ]
            kv += _table(f"{kind}.rejected", s["rejected"], self.max_keys, "reasons")
            if needed and (age is None or age > limit):
                if age is not None and self.cause == NODE:  # its messages wait while the node feeds a backlog
                    problems.append(f"{kind} not taken for {age:.1f} s (the node is behind its inputs)")
                else:
                    problems.append(f"{kind} {'silent' if age is None else f'stale ({age:.1f} s)'}")
                if publishers == 0:
                    problems.append(f"no publisher matched on {snap.topics[kind]} "
                                    f"(none running, or incompatible QoS: qos.reliable={snap.reliable})")
            if rejected:
                problems.append(f"{kind} rejected {rejected} {window}")
            if missing and full:  # the middleware dropped them: the node took too seldom
                problems.append(f"{kind} missing about {missing} {window} (dropped from the node's full input "
                                f"queue, qos.depth {snap.queue_depth}: the node is behind its inputs)")
            elif missing:
                problems.append(blame(f"{kind} missing about {missing} {window} (stamp gaps: lost in transport?)",
                                      self.cause))
            elif full:
                problems.append(f"{kind} input queue full {full} times {window} (qos.depth {snap.queue_depth}, "
                                "the oldest dropped: the node is behind its inputs)")
            if expired:
                problems.append(blame(f"{kind} expired {expired} {window} (buffered, never used: another stream "
                                      "lagging, or a reset)", self.cause))
        level = ERROR if alerts else WARN if problems else OK
        message = "; ".join([a.text for a in alerts] + problems) or "all inputs fresh"
        return self._status("inputs", level, message, kv)

    def _samples(self, snap: Snapshot, namesake: Alert | None = None) -> Status:
        c = snap.counters
        kv: list[tuple[str, object]] = [
            ("enabled", snap.enabled),
            ("samples_formed", c["samples_formed"]),
            ("samples_used", c["samples_used"]),
            ("samples_pending", c["samples_pending"]),
        ]
        kv += _table("samples_rejected", c["samples_rejected"], self.max_keys, "reasons")
        kv += _table("resets", c["resets"], self.max_keys, "reasons")
        kv += _table("unknown_joint", c["unknown_joints"], self.max_keys, "names")
        if snap.latencies_s:
            lat, cpu = sorted(snap.latencies_s), sorted(snap.cpu_times_s)
            kv += [
                ("latency_ms.p50", _ms(percentile(lat, 0.5))),
                ("latency_ms.p99", _ms(percentile(lat, 0.99))),
                ("latency_ms.max", _ms(lat[-1])),
            ]
            if cpu:
                kv += [
                    ("processing_cpu_ms.p50", _ms(percentile(cpu, 0.5))),
                    ("processing_cpu_ms.p99", _ms(percentile(cpu, 0.99))),
                ]
        if snap.intake_period_s > 0:
            kv.append(("intake_period_ms", _ms(snap.intake_period_s)))
        if snap.waits_s:
            kv.append(("intake_wait_ms.p99", _ms(percentile(sorted(snap.waits_s), 0.99))))
        if snap.periodic_s:
            kv.append(("periodic_ms.max", _ms(max(snap.periodic_s))))
        kv += [("state_file", snap.state_file), ("nodes_with_this_name", 1 + max(snap.namesakes, 0))]
        if snap.outputs_subscribed is not None:
            kv.append((OUTPUTS_SUBSCRIBED, snap.outputs_subscribed))
        message = f"{c['samples_used']} of {c['samples_formed']} samples used"
        load = self.load
        if load is not None and snap.waits_s:
            kv += load.values()
        if load is not None and load.degraded:
            message += f"; {load.text()}"
        if not snap.enabled:
            message += "; estimation disabled"
        if namesake is not None:
            return self._status("samples", ERROR, f"{namesake.text}; {message}", kv)
        if self.overload is not None:
            return self._status("samples", WARN, f"{self.overload}; {message}", kv)
        if load is not None and load.degraded:
            return self._status("samples", WARN, message, kv)
        return self._status("samples", OK, message, kv)

    def _model(self, name: str, fit: Mapping, snap: Snapshot) -> Status:
        """The fit of each method published (the time domain's, the frequency domain's
        ``frequency.*``; with both, one clause each), its convergence and why parameters are
        held back; while the model initializes, how far (``37 of 104 samples``) or why it
        cannot."""
        why = fit.get("identifiability", "")
        level = OK
        clauses = []
        both = fit.get("time_domain", True) and "frequency.ready" in fit
        if fit.get("time_domain", True):
            if fit["ready"]:
                text = f"R^2 {fit['r_squared']:.3f}, residual lag-1 correlation {fit['residual_rho1']:.2f}"
                if "converged" in fit:
                    if fit["converged"]:
                        text += "; converged"
                    elif fit.get("converged_parameters"):
                        text += f"; converged: {fit['converged_parameters']}"
                    else:
                        text += "; not converged"
                level = WARN if fit.get("held_back") else OK
            elif "initializing" in fit:
                text = f"initializing: {fit['initializing']}"
            else:
                text = f"initializing: {why.removeprefix(name + ': ') or 'regressors not yet informative'}"
                level = OK if snap.counters["samples_used"] == 0 else WARN
                why = ""
            clauses.append(f"time domain: {text}" if both else text)
        if "frequency.ready" in fit:
            clauses.append(f"frequency domain: {_frequency_clause(fit)}")
            if not fit["frequency.ready"] and not fit.get("time_domain", True) and "frequency.r_squared" not in fit:
                level = OK if snap.counters["samples_used"] == 0 else WARN
        if why and (fit["ready"] or fit.get("frequency.ready")):  # not identifiable: WARN while it holds a flag back
            clauses.append(why.removeprefix(name + ": "))
        return self._status(f"model {name}", level, "; ".join(clauses), list(fit.items()))
