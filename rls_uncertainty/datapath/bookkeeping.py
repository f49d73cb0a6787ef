"""Every counter of a :class:`.pipeline.Pipeline` behind one small API, what the refused
inputs carried, and the fit statistics it reports (numpy only).

**Counting.** Every input message is accepted or rejected with its reason, and every formed
sample ends used or rejected with its reason; nothing else writes a count:

- :class:`Tally`, counts by name (a rejection's reason, a reset's, an unknown joint, a model
  whose outputs were withheld): written only by :meth:`Tally.count`, read as a mapping (a name
  never counted reads 0), summed by :meth:`Tally.total`. It keeps at most :data:`KEYS_KEPT`
  names cut to :data:`KEY_CHARS` characters; later new names count under its overflow name,
  so every table keyed by what arrives stays bounded whatever arrives.
- :class:`StreamCounts`, one input stream: messages received, rejected by reason
  (:meth:`StreamCounts.reject`), expired unused, missing (inferred from stamp gaps).
- :class:`Bookkeeping`, all of a pipeline's: the streams', samples formed, used and rejected
  by reason (:meth:`Bookkeeping.reject_samples`), estimator resets, JointState joints that no
  surface uses, model outputs withheld as non-finite, and :attr:`Bookkeeping.evidence`: per
  stream and reason, what the newest refused input carried (the joint names, the frame, the
  value beyond a limit), so that a misconfiguration can be reported in the user's terms
  (:mod:`.alerts`). It outlives a reconfiguration (a reconfigured pipeline takes over the same
  object, and its sampler the same :class:`StreamCounts`).

**Reading.** :meth:`Bookkeeping.report` gives the counters as plain values (``/diagnostics``,
the replay's summary and ``run.json``). :class:`Totals` is what such a report adds up to, and
:class:`Window` the totals of a sliding window of steady time: the baseline of the recent
counts of ``/diagnostics`` and of the alerts; :func:`increase` and :func:`growth` what grew
since (a count that went down restarted, and counts from zero).

:func:`model_fit` is the fit of one model that ``/diagnostics`` and the replay report: R^2
(:mod:`.identifiability`) and the residual whiteness from the autocorrelation of Eq. 17.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Iterator, Mapping
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Generic, TypeVar

import numpy as np

if TYPE_CHECKING:  # annotations only
    from ..estimator import EstimatorBank

__all__ = [
    "Tally", "StreamCounts", "Bookkeeping", "Totals", "NO_TOTALS", "Window", "increase", "growth", "model_fit",
    "SAMPLES", "KEYS_KEPT", "KEY_CHARS", "OTHER_JOINTS", "OTHER_REASONS", "EVIDENCE_ITEMS",
]

# Bounds of the tables keyed by what arrives: a flood of distinct JointState names or
# caller-given reasons adds one overflow key, not a key each.
KEYS_KEPT = 32  # distinct keys per table, the overflow key aside
KEY_CHARS = 64  # longer keys (a JointState name is any string) are cut to this length
OTHER_JOINTS = "<others>"  # unknown joints beyond the first KEYS_KEPT names
OTHER_REASONS = "other"  # rejection reasons beyond the first KEYS_KEPT of a table
SAMPLES = "samples"  # the evidence key of the formed samples (beside the input streams)
EVIDENCE_ITEMS = 8  # names kept of a refused JointState (the rest is counted)
_EVIDENCE_KEYS = 256  # (stream, reason) pairs with evidence, at most


class Tally(Mapping[str, int]):
    """Counts by name, in the order the names first came: :meth:`count` is the only writer;
    read it as a mapping (a name never counted reads 0) or :meth:`total`. At most
    :data:`KEYS_KEPT` names (cut to :data:`KEY_CHARS` characters) are kept; once the table is
    full, new names count under ``overflow``."""

    __slots__ = ("_counts", "overflow")

    def __init__(self, overflow: str = OTHER_REASONS) -> None:
        self._counts: dict[str, int] = {}
        self.overflow = overflow

    def count(self, name: str, n: int = 1) -> str:
        """Count ``n`` under ``name``; returns the name counted under (cut, or the overflow)."""
        counts = self._counts
        if name not in counts:
            name = name[:KEY_CHARS]
            if name not in counts and len(counts) - (self.overflow in counts) >= KEYS_KEPT:
                name = self.overflow
        counts[name] = counts.get(name, 0) + n
        return name

    def total(self) -> int:
        return sum(self._counts.values())

    def __getitem__(self, name: str) -> int:
        return self._counts.get(name, 0)

    def __contains__(self, name: object) -> bool:
        return name in self._counts

    def get(self, name: str, default: Any = None) -> Any:
        return self._counts.get(name, default)

    def __iter__(self) -> Iterator[str]:
        return iter(self._counts)

    def __len__(self) -> int:
        return len(self._counts)

    def __repr__(self) -> str:
        return f"Tally({self._counts!r})"


@dataclass(slots=True)
class StreamCounts:
    """What happened to one stream's messages: every received message is accepted or rejected
    (with its reason, :meth:`reject`); accepted ones may later expire unused. ``missing``
    counts messages inferred from stamp gaps (never received). ``newest_ns`` is the newest
    stamp of the stream's own timeline (the stamp order is checked against it),
    ``interval_ns`` the reference interval (lower median of the recent stamp intervals)."""

    received: int = 0
    rejected: Tally = field(default_factory=Tally)
    expired: int = 0
    missing: int = 0
    newest_ns: int | None = None
    interval_ns: float = 0.0

    def reject(self, reason: str, n: int = 1) -> str:
        """Count ``n`` received messages as rejected for ``reason`` (the name counted under)."""
        return self.rejected.count(reason, n)

    @property
    def accepted(self) -> int:
        return self.received - self.rejected.total()

    def report(self) -> dict[str, Any]:
        """The counts as plain values (diagnostics, the replay's summary)."""
        return {
            "received": self.received,
            "accepted": self.accepted,
            "rejected": dict(self.rejected),
            "expired": self.expired,
            "missing": self.missing,
            "newest_stamp_ns": self.newest_ns,
        }


@dataclass
class Bookkeeping:
    """Every counter of a pipeline, kept across reconfigurations: the messages of each input
    stream, samples formed, used and rejected (by reason), estimator resets (by reason),
    JointState joints that no surface uses (by name, the overflow :data:`OTHER_JOINTS`),
    model outputs withheld because they were not finite (by model), and the evidence of the
    newest refusal per ``(stream, reason)`` (:meth:`note`)."""

    streams: dict[str, StreamCounts]
    samples_formed: int = 0
    samples_used: int = 0
    samples_rejected: Tally = field(default_factory=Tally)
    resets: Tally = field(default_factory=Tally)
    unknown_joints: Tally = field(default_factory=lambda: Tally(OTHER_JOINTS))
    outputs_withheld: Tally = field(default_factory=Tally)
    evidence: dict[tuple[str, str], Any] = field(default_factory=dict)

    @classmethod
    def for_streams(cls, names: tuple[str, ...]) -> Bookkeeping:
        return cls({name: StreamCounts() for name in names})

    def reject_samples(self, reason: str, n: int = 1, evidence: Any = None) -> None:
        """Count ``n`` formed samples as rejected for ``reason``; ``evidence`` (when not None):
        what the newest of them carried (:meth:`note`)."""
        reason = self.samples_rejected.count(reason, n)
        if evidence is not None:
            self.note(SAMPLES, reason, evidence)

    def note(self, stream: str, reason: str, what: Any) -> None:
        """Keep ``what`` (small: a tuple of a few names or numbers, a short string) as the
        evidence of the newest input of ``stream`` (or :data:`SAMPLES`) refused for ``reason``.
        At most a fixed number of pairs are kept; later new pairs are not."""
        key = (stream, reason)
        if key in self.evidence or len(self.evidence) < _EVIDENCE_KEYS:
            self.evidence[key] = what

    def report(self, pending: int) -> dict:
        """The counters as plain values (``/diagnostics``, the replay's summary); ``pending``:
        samples waiting in the differentiator's delay line."""
        return {
            "streams": {name: counts.report() for name, counts in self.streams.items()},
            "samples_formed": self.samples_formed,
            "samples_used": self.samples_used,
            "samples_rejected": dict(self.samples_rejected),
            "samples_pending": pending,
            "resets": dict(self.resets),
            "unknown_joints": dict(self.unknown_joints),
            "outputs_withheld": dict(self.outputs_withheld),
        }


@dataclass(frozen=True)
class Totals:
    """What a :meth:`Bookkeeping.report` adds up to, to compare two moments: per stream
    received, accepted, rejected (by reason), missing and expired; samples formed, used and
    rejected (by reason)."""

    received: Mapping[str, int]
    accepted: Mapping[str, int]
    rejected: Mapping[str, Mapping[str, int]]
    missing: Mapping[str, int]
    expired: Mapping[str, int]
    formed: int
    used: int
    samples_rejected: Mapping[str, int]

    @classmethod
    def of(cls, report: Mapping) -> Totals:
        streams = report["streams"]
        return cls({k: s["received"] for k, s in streams.items()}, {k: s["accepted"] for k, s in streams.items()},
                   {k: dict(s["rejected"]) for k, s in streams.items()},
                   {k: s["missing"] for k, s in streams.items()}, {k: s["expired"] for k, s in streams.items()},
                   report["samples_formed"], report["samples_used"], dict(report["samples_rejected"]))

    def rejected_total(self, stream: str) -> int:
        """The messages of ``stream`` rejected, whatever the reason."""
        return sum(self.rejected.get(stream, {}).values())


NO_TOTALS = Totals({}, {}, {}, {}, {}, 0, 0, {})  # before anything was counted


def increase(now: int, before: int) -> int:
    """How much a count grew since ``before``: counts only grow, so one that went down
    restarted (a new node, a reset replay) and counts from zero."""
    return now - before if now >= before else now


def growth(now: Mapping[str, int], before: Mapping[str, int]) -> list[tuple[str, int]]:
    """The counts of a table that grew (:func:`increase`), largest first (ties by name)."""
    grew = [(k, increase(n, before.get(k, 0))) for k, n in now.items()]
    return sorted(((k, d) for k, d in grew if d > 0), key=lambda kv: (-kv[1], kv[0]))


T = TypeVar("T")


class Window(Generic[T]):
    """Totals over a sliding window of steady time. :meth:`advance` takes the time since its
    previous call and the totals now, and returns the newest totals at least ``window_s`` old
    (before the first ``window_s`` seconds, ``start``: every total zero), so the window spans
    ``window_s`` to ``window_s`` plus one period; it holds about ``window_s / period`` totals."""

    def __init__(self, start: T) -> None:
        self.time = 0.0  # steady seconds since the start (the sum of the elapsed times)
        self._history: deque[tuple[float, T]] = deque([(0.0, start)])

    def advance(self, elapsed_s: float, now: T, window_s: float) -> tuple[T, bool]:
        """The totals ``window_s`` ago, and whether a whole window has passed since the start."""
        self.time += max(elapsed_s, 0.0)
        history, cut = self._history, self.time - window_s
        while len(history) > 1 and history[1][0] <= cut:
            history.popleft()
        start, before = history[0]
        history.append((self.time, now))
        return before, start <= cut


# Why a model's fit is not ready although it is past the publication rule.
WITHHELD_PROBLEM = "outputs not finite or standard errors at rounding level: withheld"


def model_fit(bank: EstimatorBank, j: int, r2: float, withheld_now: bool, withheld: int) -> dict:
    """Model ``j`` of ``bank``'s fit: ``r2``, its R^2 (:meth:`.identifiability.
    IdentifiabilityMonitor.fit`: 1 - residual variance / output variance, both since the
    estimator started) and the residual whiteness: the lag-1 autocorrelation coefficient and
    the fraction of lags whose coefficient lies outside the 2-sigma white-noise bound 2/sqrt(n)
    (Eq. 17's R). ``ready`` is false, with a ``problem``, when R^2 is undefined (NaN: a constant
    output) or the model's outputs were withheld as non-finite or with a standard error at
    rounding level (``withheld_now``: the newest sample's; ``withheld``: how many so far).
    Before the model publishes (:attr:`.estimator.EstimatorBank.ready`): ``ready`` false,
    ``published`` false and ``publish_at_samples``, the samples it needs
    (:attr:`.estimator.EstimatorBank.publish_at`, after its burn-in when it has one)."""
    if not bank.ready[j]:
        return {"ready": False, "samples": bank.k, "published": False,
                "publish_count": int(bank.publish_count[j]), "publish_at_samples": int(bank.publish_at[j])}
    n = bank.k  # samples since the estimator (re)started
    R = bank.autocorrelation(j)
    # A constant output (variance at rounding level) leaves R^2 undefined; a non-finite
    # estimator state (withheld outputs) leaves it NaN: either way the fit is reported as
    # not ready, with the problem, never as an OK "nan".
    if not math.isfinite(r2) or withheld_now:
        problem = WITHHELD_PROBLEM if withheld_now or not np.isfinite(R).all() else "output constant: R^2 undefined"
        return {"ready": False, "samples": bank.k, "problem": problem, "outputs_withheld": withheld}
    rho = R[1:] / R[0] if R[0] > 0 else np.zeros(0)
    bound = 2.0 / math.sqrt(max(n, 1))
    return {
        "ready": True,
        "samples": bank.k,
        # The largest lag of Eq. 22 the corrected covariance uses now (at most
        # the lag span times the rate; chosen per model with automatic lags).
        "lags": int(bank.lags_used[j]),
        "r_squared": float(r2),
        "residual_rho1": float(rho[0]) if rho.size else float("nan"),
        "lags_outside_2sigma": float(np.mean(np.abs(rho) > bound)) if rho.size else float("nan"),
        "repairs": int(bank.repairs[j]),
        "outputs_withheld": withheld,
    }
