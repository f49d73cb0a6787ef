"""The ``/diagnostics`` statuses of the estimator node, computed without ROS.

The node collects one :class:`Snapshot` per diagnostics period, the pipeline's bookkeeping
(:meth:`.pipeline.Pipeline.counters`, :meth:`.pipeline.Pipeline.model_fit`) plus the few facts
only the node knows (its clock, matched publishers, the period, callback latencies), and
:meth:`DiagnosticsPolicy.update` turns it into :class:`Status` records: name, level, message and
ordered key-values. The node only converts them into a ``diagnostic_msgs/DiagnosticArray``.

Three statuses, named ``rls_estimator: ...``:

* ``inputs``: per stream ``required``, ``publishers``, ``rate_hz``, ``age_s``, ``received``,
  ``accepted``, ``expired``, ``missing``, ``rejected.<reason>``. WARN when a required stream
  is silent or stale (older than ``max(1 s, 2 max_gap)``; with a hint when no publisher
  matched), when anything was rejected, or when messages are missing.
* ``samples``: ``enabled``, ``samples_formed``, ``samples_used``, ``samples_pending``,
  ``samples_rejected.<reason>``, ``resets.<reason>``, ``unknown_joint.<name>``, callback
  latency and CPU percentiles of the period, ``state_file``. Always OK.
* ``model M``: the model fit; OK when ready, and while initializing OK until the first
  sample is used, WARN after (the regressors are not informative).

Levels are cumulative today (a stream that ever rejected a message stays WARN). The policy is
a small stateful object fed one snapshot per period and keeps the previous one, so levels
computed over a recent window can be added beside the cumulative counters.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

from .messages import NODE_NAME

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
]

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
    The rest only the node knows: its clock (``now_ns``, the clock the stamps are compared
    with, simulated under ``use_sim_time``), the steady time since the previous snapshot
    (``elapsed_s``), the publishers matched per input and the resolved topic names, the QoS
    choice, the wall and CPU times of the callbacks that produced outputs in the period, the
    state-file status and whether estimation is enabled.
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


def stale_after(max_gap: float) -> float:
    """Age (s) beyond which a required stream is reported stale: twice the largest gap the
    pipeline interpolates across, at least one second."""
    return max(1.0, 2.0 * max_gap)


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


def _ms(seconds: float) -> str:
    return f"{1e3 * seconds:.3f}"


class DiagnosticsPolicy:
    """Turns one :class:`Snapshot` per period into the node's statuses.

    Stateful: input rates are the received-count differences between consecutive snapshots
    over ``elapsed_s`` (the first period counts from zero). :attr:`previous` is the last
    snapshot handed in.
    """

    def __init__(self, node_name: str = NODE_NAME) -> None:
        self.node_name = node_name
        self.previous: Snapshot | None = None

    def update(self, snap: Snapshot) -> list[Status]:
        """The statuses of this period: ``inputs``, ``samples``, then one per model."""
        statuses = [self._inputs(snap), self._samples(snap)]
        statuses += [self._model(name, fit, snap) for name, fit in snap.models]
        self.previous = snap
        return statuses

    def _status(self, name: str, level: int, message: str, values: list[tuple[str, object]]) -> Status:
        return Status(f"{self.node_name}: {name}", level, message, tuple((k, str(v)) for k, v in values),
                      hardware_id=self.node_name)

    def _received_before(self, kind: str) -> int:
        if self.previous is None:
            return 0
        stream = self.previous.counters["streams"].get(kind)
        return stream["received"] if stream else 0

    def _inputs(self, snap: Snapshot) -> Status:
        period = max(snap.elapsed_s, 1e-9)
        limit = stale_after(snap.max_gap)
        kv: list[tuple[str, object]] = []
        problems: list[str] = []
        for kind, s in snap.counters["streams"].items():
            needed = kind in snap.required
            rate = (s["received"] - self._received_before(kind)) / period
            newest = s["newest_stamp_ns"]
            age = (snap.now_ns - newest) * 1e-9 if newest is not None else None
            publishers = snap.publishers[kind]
            kv += [
                (f"{kind}.required", needed),
                (f"{kind}.publishers", publishers),
                (f"{kind}.rate_hz", f"{rate:.1f}"),
                (f"{kind}.age_s", "never received" if age is None else f"{age:.3f}"),
                (f"{kind}.received", s["received"]),
                (f"{kind}.accepted", s["accepted"]),
                (f"{kind}.expired", s["expired"]),
                (f"{kind}.missing", s["missing"]),
            ]
            kv += [(f"{kind}.rejected.{reason}", n) for reason, n in sorted(s["rejected"].items())]
            if needed and (age is None or age > limit):
                problems.append(f"{kind} {'silent' if age is None else f'stale ({age:.1f} s)'}")
                if publishers == 0:
                    problems.append(f"no publisher matched on {snap.topics[kind]} "
                                    f"(none running, or incompatible QoS: qos.reliable={snap.reliable})")
            if s["rejected"]:
                problems.append(f"{kind} rejected {sum(s['rejected'].values())}")
            if s["missing"]:
                problems.append(f"{kind} missing about {s['missing']} (stamp gaps: lost in transport?)")
        level = WARN if problems else OK
        return self._status("inputs", level, "; ".join(problems) or "all inputs fresh", kv)

    def _samples(self, snap: Snapshot) -> Status:
        c = snap.counters
        kv: list[tuple[str, object]] = [
            ("enabled", snap.enabled),
            ("samples_formed", c["samples_formed"]),
            ("samples_used", c["samples_used"]),
            ("samples_pending", c["samples_pending"]),
        ]
        kv += [(f"samples_rejected.{reason}", n) for reason, n in sorted(c["samples_rejected"].items())]
        kv += [(f"resets.{reason}", n) for reason, n in sorted(c["resets"].items())]
        kv += [(f"unknown_joint.{joint}", n) for joint, n in sorted(c["unknown_joints"].items())]
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
        kv.append(("state_file", snap.state_file))
        message = f"{c['samples_used']} of {c['samples_formed']} samples used"
        if not snap.enabled:
            message += "; estimation disabled"
        return self._status("samples", OK, message, kv)

    def _model(self, name: str, fit: Mapping, snap: Snapshot) -> Status:
        if fit["ready"]:
            text = f"R^2 {fit['r_squared']:.3f}, residual lag-1 correlation {fit['residual_rho1']:.2f}"
            level = OK
        else:
            text = "initializing: regressors not yet informative"
            level = OK if snap.counters["samples_used"] == 0 else WARN
        return self._status(f"model {name}", level, text, list(fit.items()))
