"""Named input streams -> samples on a fixed time grid, with every message accounted for.

Knows nothing about aircraft: a stream is a name and time-stamped tuples of numbers, and the
caller says which streams a sample needs. Pure Python (no numpy: the per-message path works on
Python ints and floats, which is faster for three-element tuples).

* **Buffers and accounting.** :meth:`Sampler.add` accepts a message into its stream's buffer
  or rejects it with a reason (``non_finite``, ``duplicate``, ``out_of_order``; the caller
  may count its own reasons with :meth:`Sampler.reject`). Stamps are integer nanoseconds.
  A stamp gap of more than 1.5 of the stream's usual interval (an exponential average) counts
  the messages presumably lost in transport as ``missing``. A stream that runs more than
  ``buffer_ns`` ahead of its oldest buffered message drops the old ones as ``expired``.
* **The grid.** Samples fall on ``t_k = k * period_ns`` (integer nanoseconds, so the grid does
  not depend on when sampling started). A sample at ``t_k`` is formed once every required
  stream has a message at or after ``t_k``; each is linearly interpolated between the two
  messages around ``t_k``, never extrapolated. If a required stream is silent for more than
  ``max_gap_ns`` around ``t_k``, or its message before ``t_k`` has expired, the grid points
  up to its next message are skipped together, with the reason ``gap_<stream>`` or
  ``expired_<stream>``.

The counters of each stream live in a :class:`StreamCounts` that outlives the sampler: a
reconfigured pipeline hands the same objects to its new sampler, so no count is lost.
"""

from __future__ import annotations

from bisect import bisect_left, bisect_right
from collections import Counter
from dataclasses import dataclass, field
from operator import attrgetter
from typing import Iterable, NamedTuple

__all__ = ["StreamCounts", "Stream", "Sample", "Skipped", "Sampler"]


@dataclass(slots=True)
class StreamCounts:
    """What happened to one stream's messages: every received message is accepted or rejected
    (with its reason); accepted ones may later expire unused. ``missing`` counts messages
    inferred from stamp gaps (never received). ``newest_ns`` is the newest accepted stamp,
    ``interval_ns`` the running estimate of the stream's stamp interval."""

    received: int = 0
    rejected: Counter = field(default_factory=Counter)
    expired: int = 0
    missing: int = 0
    newest_ns: int | None = None
    interval_ns: float = 0.0

    @property
    def accepted(self) -> int:
        return self.received - sum(self.rejected.values())

    def report(self) -> dict:
        """The counts as plain values (diagnostics, the replay's summary)."""
        return {
            "received": self.received,
            "accepted": self.accepted,
            "rejected": dict(self.rejected),
            "expired": self.expired,
            "missing": self.missing,
            "newest_stamp_ns": self.newest_ns,
        }


class Stream:
    """The time-ordered buffer of one stream: stamps (ns) and value tuples, oldest first;
    ``last`` is the newest buffered stamp (``None`` while the buffer is empty)."""

    __slots__ = ("name", "stamps", "values", "last", "counts")

    def __init__(self, name: str, counts: StreamCounts) -> None:
        self.name = name
        self.stamps: list[int] = []
        self.values: list[tuple] = []
        self.last: int | None = None
        self.counts = counts


class Sample(NamedTuple):
    """A formed grid point: each required stream's value tuple at ``stamp_ns`` (in the order of
    :attr:`Sampler.required`)."""

    stamp_ns: int
    values: list


class Skipped(NamedTuple):
    """``count`` consecutive grid points from ``stamp_ns`` that cannot be formed, and why."""

    stamp_ns: int
    count: int
    reason: str


_NEWEST = attrgetter("last")


class Sampler:
    """Buffers of the streams ``names`` and the grid of samples that need the ``required``
    ones. ``counts`` (by stream name) carries counters over from an earlier sampler."""

    def __init__(
        self,
        names: Iterable[str],
        required: Iterable[str],
        *,
        period_ns: int,
        max_gap_ns: int,
        buffer_ns: int,
        counts: dict[str, StreamCounts] | None = None,
    ) -> None:
        names = tuple(names)
        self.required = tuple(required)
        unknown = [n for n in self.required if n not in names]
        if unknown or not self.required:
            raise ValueError(f"required streams must be some of {names}, got {self.required}")
        if period_ns <= 0 or max_gap_ns <= 0 or buffer_ns <= 0:
            raise ValueError("period_ns, max_gap_ns and buffer_ns must be positive")
        counts = counts if counts is not None else {}
        self.streams = {n: Stream(n, counts[n] if n in counts else StreamCounts()) for n in names}
        self.period_ns = int(period_ns)
        self.max_gap_ns = int(max_gap_ns)
        self.buffer_ns = int(buffer_ns)
        self._needed = [self.streams[n] for n in self.required]
        self._all = list(self.streams.values())
        self.next_ns: int | None = None  # the next grid point to form
        self._frontier: Stream | None = None  # the required stream that has not reached it

    @property
    def counts(self) -> dict[str, StreamCounts]:
        return {name: s.counts for name, s in self.streams.items()}

    def buffered(self) -> int:
        """Messages in the buffers."""
        return sum(len(s.stamps) for s in self._all)

    # ------------------------------------------------------------------ messages
    def reject(self, stream: Stream, reason: str) -> None:
        """Count a received message of ``stream`` that the caller could not use."""
        counts = stream.counts
        counts.received += 1
        counts.rejected[reason] += 1

    def reject_invalid(self, stream: Stream, stamp: int, reason: str) -> None:
        """Count a received message of ``stream`` stamped ``stamp`` whose values the caller
        found unusable (implausible, another frame).

        MINIMAL STUB (h-sanity): it only counts, like :meth:`reject`. The stream-timelines
        work replaces it with a version that also keeps samples from being interpolated
        across the invalid message; callers already pass the stamp for that."""
        del stamp  # used by the full implementation
        self.reject(stream, reason)

    def add(self, stream: Stream, stamp: int, values: tuple, finite: bool = True) -> bool:
        """Accept a message (``finite``: the caller found every value finite) or count why not.
        Returns whether samples may be due (:meth:`due`): false while the required stream the
        grid waits for has not reached the next grid point, the usual case."""
        counts = stream.counts
        counts.received += 1
        if not finite:
            counts.rejected["non_finite"] += 1
            return False
        newest = counts.newest_ns
        if newest is not None:
            dt = stamp - newest
            if dt <= 0:
                counts.rejected["duplicate" if dt == 0 else "out_of_order"] += 1
                return False
            # Messages lost before they reached us (a best-effort DDS drop, a recorder gap)
            # leave a hole in the stamps: count the missing ones against the usual interval.
            interval = counts.interval_ns
            if interval == 0.0:
                counts.interval_ns = float(dt)
            elif dt > 1.5 * interval:
                counts.missing += int(round(dt / interval)) - 1
            else:
                counts.interval_ns = interval + 0.05 * (dt - interval)
        stamps = stream.stamps
        stamps.append(stamp)
        stream.values.append(values)
        stream.last = counts.newest_ns = stamp
        if stamp - stamps[0] > self.buffer_ns:
            self._expire(stream, stamp)
        frontier = self._frontier
        return frontier is None or frontier.last >= self.next_ns

    def _expire(self, stream: Stream, newest: int) -> None:
        """Drop messages older than ``buffer_ns`` (another stream holds the grid back); they
        are counted as expired, never used."""
        cut = bisect_left(stream.stamps, newest - self.buffer_ns)
        cut -= 1  # keep the message just before the cut: it may still bracket a later sample
        if cut > 0:
            del stream.stamps[:cut]
            del stream.values[:cut]
            stream.counts.expired += cut

    # ------------------------------------------------------------------ the grid
    def due(self) -> list[Sample | Skipped]:
        """Every grid point that the buffered messages decide, in time order."""
        out: list[Sample | Skipped] = []
        needed = self._needed
        P = self.period_ns
        t = self.next_ns
        if t is not None and self._frontier is not None and self._frontier.last < t:
            return out
        for s in needed:
            if not s.stamps:
                return out
        if t is None:
            start = max(s.stamps[0] for s in needed)
            t = -(-start // P) * P
        t_start = t
        while True:
            lagging = min(needed, key=_NEWEST)  # every needed stream holds a message here
            if lagging.last < t:
                self._frontier = lagging
                break
            values, reason, skip_to = self._interpolate(t)
            if values is None:
                # Every grid point up to skip_to shares the problem: report them at once.
                n_skip = max(1, -(-(skip_to - t) // P))
                out.append(Skipped(t, n_skip, reason))
                t += n_skip * P
            else:
                out.append(Sample(t, values))
                t += P
        if t != t_start:
            self._trim(t)
        self.next_ns = t
        return out

    def _interpolate(self, t: int):
        """``(values, None, None)`` at ``t``, or ``(None, reason, skip_to)``."""
        vals = []
        max_gap = self.max_gap_ns
        for s in self._needed:
            stamps = s.stamps
            i = bisect_left(stamps, t)
            t1 = stamps[i]
            if t1 == t:
                vals.append(s.values[i])
                continue
            if i == 0:
                return None, f"expired_{s.name}", stamps[0]
            t0 = stamps[i - 1]
            if t1 - t0 > max_gap:
                return None, f"gap_{s.name}", t1
            w = (t - t0) / (t1 - t0)
            vals.append([x + w * (y - x) for x, y in zip(s.values[i - 1], s.values[i])])
        return vals, None, None

    def _trim(self, t_next: int) -> None:
        """Drop messages no later sample can need (keep the last one at or before ``t_next``)."""
        for s in self._all:
            stamps = s.stamps
            if len(stamps) > 1 and stamps[1] <= t_next:
                i = bisect_right(stamps, t_next) - 1
                del stamps[:i]
                del s.values[:i]

    # ------------------------------------------------------------------ restart
    def clear(self, *, forget_newest: bool) -> None:
        """Drop every buffered message (counted as expired) and restart the grid at the next
        messages. ``forget_newest`` (time jumped backwards) also forgets the newest accepted
        stamps, so that older stamps are accepted again."""
        for s in self._all:
            s.counts.expired += len(s.stamps)
            s.stamps.clear()
            s.values.clear()
            s.last = None
            if forget_newest:
                s.counts.newest_ns = None
        self.next_ns = None
        self._frontier = None
