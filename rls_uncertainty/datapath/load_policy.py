"""Whether the node keeps up with its inputs, why not, and what it sheds meanwhile (no ROS, no numpy).

**Measurements** (:class:`Timing`, one per diagnostics period): the estimator period, the
processing CPU of each output sample, how long the oldest input of each intake pass waited
before it was fed (in order: a growing wait is a growing queue), the messages counted missing
by stamp gaps, and per stream the offset of its newest stamp against its arrival (stamp age
minus arrival age, seconds; the node's clock against the sender's).

**The cause** (:func:`cause`), decided from those measurements, in this order:

* :data:`NODE` (:func:`behind`): an input queue was full when the node took it (the
  middleware dropped the oldest messages), the node's own processing per sample exceeds the
  period, or the median wait is a backlog (over ``max(50 ms, 5 periods)``), or the waits grow through the
  period by as much (the last third's median against the first third's);
* :data:`CLOCKS`: the required streams' stamp offsets differ by more than the tolerance and
  that difference stayed put since the previous period (a constant offset: another clock);
* :data:`TRANSPORT`: stamp gaps while the node was not behind;
* None otherwise.

:func:`blame` keeps a hint of the diagnostics ("lost in transport?", "different clocks?") only
when the measurements do not point at the node; when they do, it names the node instead, and
when they point at the clocks it states the measured offset (:func:`clock_text`).

**The degradation policy** (:class:`LoadPolicy`). While the node is behind, each diagnostics
period takes one step down the ladder; once it has kept up for ``recover_s`` seconds it takes
one step back, and so on until nothing is shed:

1. frequency-domain evaluations spaced out: ``frequency.every`` times 5 per step, at most one
   evaluation per second (``every`` = the rate), with ``estimator.method`` ``frequency`` or
   ``both``;
2. then the published full covariances decimated further: ``outputs.covariance_decimation``
   times 5 per step, at most one per second (when they are published at all).

Estimates and standard errors of every sample used stay as configured: only how often the
frequency-domain results and the covariances are computed and published changes. Each step is
one line (:attr:`LoadPolicy.said`, logged once by the node) and the current setting is in
``/diagnostics`` (``load.*`` and the samples status's text). Nothing is kept per sample: the
policy's memory is constant.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

__all__ = ["NODE", "TRANSPORT", "CLOCKS", "Timing", "behind", "cause", "blame", "clock_text", "keep_up_text",
           "LoadPolicy", "FACTOR"]

NODE, TRANSPORT, CLOCKS = "node", "transport", "clocks"
FACTOR = 5  # each step spaces the work out this many times


def _median(values: Sequence[float]) -> float:
    s = sorted(values)
    return s[len(s) // 2]


def _p99(values: Sequence[float]) -> float:
    s = sorted(values)
    return s[min(len(s) - 1, int(0.99 * len(s)))]


@dataclass(frozen=True)
class Timing:
    """One diagnostics period's timing (module docstring), seconds. ``offsets_s`` and
    ``previous_offsets_s``: per required stream, stamp age minus arrival age, this period and
    the one before (empty when unknown)."""

    period_s: float
    cpu_per_sample_s: Sequence[float] = ()
    waits_s: Sequence[float] = ()
    stamp_gaps: int = 0
    offsets_s: Mapping[str, float] = field(default_factory=dict)
    previous_offsets_s: Mapping[str, float] = field(default_factory=dict)
    clock_tolerance_s: float = 1.0
    # Per stream, the intake passes that found its queue full (``queue_depth`` messages): the
    # middleware dropped the oldest before the node took them.
    queues_full: Mapping[str, int] = field(default_factory=dict)
    queue_depth: int = 0


def behind(t: Timing) -> bool:
    """The node cannot keep up: an input queue was full when taken, its processing per sample
    (median) exceeds the period, its
    inputs wait a backlog (median wait over ``max(50 ms, 5 periods)``), or the waits grow
    through the period (a growing queue)."""
    if any(t.queues_full.values()):
        return True
    if t.period_s <= 0:
        return False
    if t.cpu_per_sample_s and _median(t.cpu_per_sample_s) > t.period_s:
        return True
    waits = list(t.waits_s)
    if not waits:
        return False
    backlog = max(0.05, 5 * t.period_s)
    if _median(waits) > backlog:
        return True
    third = len(waits) // 3
    if third < 2:
        return False
    first, last = _median(waits[:third]), _median(waits[-third:])
    return last - first > backlog


def _clock_spread(offsets: Mapping[str, float]) -> float:
    return max(offsets.values()) - min(offsets.values()) if len(offsets) > 1 else 0.0


def cause(t: Timing) -> str | None:
    """Why inputs are late, missing or never overlap: :data:`NODE`, :data:`CLOCKS`,
    :data:`TRANSPORT` or None (module docstring)."""
    if behind(t):
        return NODE
    spread = _clock_spread(t.offsets_s)
    if spread > t.clock_tolerance_s and set(t.previous_offsets_s) >= set(t.offsets_s):
        before = _clock_spread({k: t.previous_offsets_s[k] for k in t.offsets_s})
        if abs(spread - before) <= 0.1 * t.clock_tolerance_s:
            return CLOCKS
    if t.stamp_gaps > 0:
        return TRANSPORT
    return None


_HINTS = {
    "stamp gaps: lost in transport?": {NODE: "stamp gaps: dropped while the node was behind its inputs",
                                       CLOCKS: "stamp gaps, with the streams on different clocks"},
    "different clocks?": {NODE: "the node cannot keep up with its inputs"},
    "another stream lagging, or a reset": {NODE: "the node cannot keep up with its inputs"},
}


def blame(text: str, why: str | None, clocks: str | None = None) -> str:
    """``text`` (a diagnostic's message) with its guessed causes replaced by the measured one:
    with ``why`` :data:`NODE` the node is named; with :data:`CLOCKS` "different clocks?"
    becomes ``clocks`` (:func:`clock_text`) and stamp gaps are not put on the transport;
    unchanged otherwise."""
    for hint, by_cause in _HINTS.items():
        if why in by_cause and hint in text:
            text = text.replace(hint, by_cause[why])
    if why == CLOCKS and clocks:
        text = text.replace("different clocks?", clocks)
    return text


def clock_text(offsets: Mapping[str, float]) -> str:
    """``different clocks: S stamps X s behind R's, against their arrival``: of the streams'
    stamp offsets (stamp age minus arrival age, :class:`Timing`), the most delayed stream S
    against the least delayed R."""
    late, early = max(offsets, key=offsets.__getitem__), min(offsets, key=offsets.__getitem__)
    spread = offsets[late] - offsets[early]
    return f"different clocks: {late} stamps {spread:.1f} s behind {early}'s, against their arrival"


def keep_up_text(t: Timing) -> str:
    """``cannot keep up: N ms behind, X ms per sample against a period of Y ms`` (N: p99 of the
    waits; X: median processing CPU per sample)."""
    late = f"{1e3 * _p99(t.waits_s):.0f} ms behind" if t.waits_s else "behind"
    cpu = f"{1e3 * _median(t.cpu_per_sample_s):.1f} ms per sample" if t.cpu_per_sample_s else "no sample processed"
    text = f"cannot keep up: {late}, {cpu} against a period of {1e3 * t.period_s:.1f} ms"
    full = [f"{kind} {n} times" for kind, n in t.queues_full.items() if n]
    if full:
        text += f"; input queue full (qos.depth {t.queue_depth}, the oldest dropped): {', '.join(full)}"
    return text


class LoadPolicy:
    """The degradation ladder of one pipeline configuration (module docstring).
    ``frequency_every``: the configured ``frequency.every`` (0 without the frequency domain);
    ``covariance_decimation``: the configured one (0: never published); ``rate``: Hz."""

    def __init__(self, rate: float, frequency_every: int, covariance_decimation: int,
                 recover_s: float = 10.0) -> None:
        self.base = (int(frequency_every), int(covariance_decimation))
        self.cap = max(1, int(round(rate)))  # at most one per second
        self.recover_s = float(recover_s)
        self.frequency_every, self.covariance_decimation = self.base
        self.said: list[str] = []  # the lines of the last update, to log
        self._calm_s = 0.0  # how long the node has kept up since the last step

    @property
    def degraded(self) -> bool:
        return (self.frequency_every, self.covariance_decimation) != self.base

    def text(self) -> str:
        """The current degradation for ``/diagnostics`` (empty when nothing is shed)."""
        parts = []
        if self.frequency_every != self.base[0]:
            parts.append(f"frequency.every {self.base[0]} -> {self.frequency_every}")
        if self.covariance_decimation != self.base[1]:
            parts.append(f"outputs.covariance_decimation {self.base[1]} -> {self.covariance_decimation}")
        return f"degraded: {', '.join(parts)}" if parts else ""

    def values(self) -> list[tuple[str, object]]:
        return [("load.frequency_every", self.frequency_every),
                ("load.covariance_decimation", self.covariance_decimation)]

    def update(self, is_behind: bool, elapsed_s: float) -> list[str]:
        """One diagnostics period: a step down while behind, a step back after ``recover_s``
        seconds of keeping up; the lines saying so (also in :attr:`said`)."""
        self.said = []
        if is_behind:
            self._calm_s = 0.0
            step = self._down()
            if step:
                self.said.append(f"degraded: {step} (cannot keep up)")
            return self.said
        self._calm_s += elapsed_s
        if self.degraded and self._calm_s >= self.recover_s:
            self._calm_s = 0.0
            step = self._up()
            self.said.append(f"restored: {step} (kept up for {self.recover_s:g} s)")
        return self.said

    def _down(self) -> str | None:
        every, base = self.frequency_every, self.base[0]
        if base and every < self.cap:
            self.frequency_every = min(self.cap, every * FACTOR)
            return f"frequency.every {every} -> {self.frequency_every}"
        dec = self.covariance_decimation
        if self.base[1] and dec < self.cap:
            self.covariance_decimation = min(self.cap, dec * FACTOR)
            return f"outputs.covariance_decimation {dec} -> {self.covariance_decimation}"
        return None

    def _up(self) -> str:
        dec, base = self.covariance_decimation, self.base[1]
        if dec != base:
            self.covariance_decimation = max(base, dec // FACTOR)
            return f"outputs.covariance_decimation {dec} -> {self.covariance_decimation}"
        every = self.frequency_every
        self.frequency_every = max(self.base[0], every // FACTOR)
        return f"frequency.every {every} -> {self.frequency_every}"
