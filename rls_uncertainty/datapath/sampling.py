"""Named input streams -> samples on a fixed time grid, with every message accounted for.

Knows nothing about aircraft: a stream is a name and time-stamped tuples of numbers, and the
caller says which streams a sample needs. Pure Python (no numpy: the per-message path works on
Python ints and floats, which is faster for three-element tuples). Stamps are integer
nanoseconds; ``J`` below is ``max_jump_ns`` (``inputs.max_stamp_jump``).

* **Accounting.** Every message :meth:`Sampler.add` receives is accepted, held as a jump
  candidate (counted as accepted until decided), or rejected with one reason:
  ``far_from_clock`` (more than ``max_clock_ns`` from :attr:`Sampler.clock_ns`, when both are
  set), ``duplicate`` / ``out_of_order`` (a stamp at or up to ``J`` before the stream's newest),
  ``previous_timeline`` (a straggler of a timeline the data has left), ``stamp_jump`` (held
  candidates the stream did not confirm), or a value reason (``non_finite``, or the caller's
  through :meth:`Sampler.reject_invalid`); callers count their own reasons with
  :meth:`Sampler.reject`. Accepted messages may later expire unused (``expired``).
* **Invalid messages leave holes.** A message rejected for its values whose stamp continues
  the stream is a hole: no sample is interpolated across it. The grid points between the last
  valid message before it and the first valid one after it are skipped as ``invalid_<stream>``
  (a valid message exactly on a grid point is still used), and like any skip this restarts the
  caller's differentiator. A message with bad values and a bad stamp is rejected for its stamp.
* **Missing messages, buffers.** Each stream's interval statistics and bounded buffers are
  in :mod:`.streams`.
* **The grid.** Samples fall on ``t_k = k * period_ns`` (integer nanoseconds, so the grid does
  not depend on when sampling started). A sample at ``t_k`` is formed once every required
  stream has a message at or after ``t_k``; each is linearly interpolated between the two
  messages around ``t_k``, never extrapolated. If a required stream is silent for more than
  ``max_gap_ns`` around ``t_k``, its message before ``t_k`` has expired, or a hole lies there,
  the grid points up to its next message are skipped together (``gap_<stream>``,
  ``expired_<stream>``, ``invalid_<stream>``). A gap is never longer than the stamps really
  advanced within one timeline: a jump starts a new timeline instead of skipping grid points.

**Timelines.** Each stream checks its own stamps; a stamp that does not continue them is
held as a jump candidate and, once confirmed, either a dropout or a new timeline
(:mod:`.timelines`). When the data moved to a new timeline, :meth:`Sampler.due` first forms
every sample of the current one that its data allows, then returns a :class:`Restart` and
starts the grid afresh on the next. :meth:`Sampler.time_jumped` (a backwards ``/clock``
jump) and :meth:`Sampler.clear` (``~/reset``: afterwards older stamps are accepted again)
reach the timelines the same way.

The counters of each stream live in a :class:`.bookkeeping.StreamCounts` that outlives the
sampler: a reconfigured pipeline hands the same objects to its new sampler, so no count is lost.
"""

from __future__ import annotations

from bisect import bisect_left, bisect_right
from collections.abc import Iterable, Sequence
from operator import attrgetter
from typing import NamedTuple

from .bookkeeping import StreamCounts
from .streams import RING, Stream, Values, drop_front, expire
from .timelines import Timelines

__all__ = ["Sample", "Skipped", "Restart", "Sampler", "CURRENT", "AHEAD", "BEHIND"]

# Where a stream stands with respect to the timelines.
CURRENT, AHEAD, BEHIND = 0, 1, 2


class Sample(NamedTuple):
    """A formed grid point: each required stream's value tuple at ``stamp_ns`` (in the order of
    :attr:`Sampler.required`)."""

    stamp_ns: int
    values: list[Sequence[float]]


class Skipped(NamedTuple):
    """``count`` consecutive grid points from ``stamp_ns`` that cannot be formed, and why."""

    stamp_ns: int
    count: int  # type: ignore[assignment]  # shadows tuple.count; the field name is the API
    reason: str


class Restart(NamedTuple):
    """The data moved to a new timeline, why: ``stamps_jumped_backwards`` (a stream's stamps
    went back more than ``J``, confirmed: a looped replay), ``stamps_jumped_forward`` (ahead of
    every stream by more than ``J``, confirmed: a clock set late, a long dropout of every
    stream) or ``time_jumped_backwards`` (the stamps followed a backwards clock jump). Every
    sample of the previous timeline was returned before it."""

    reason: str


class _Hole(NamedTuple):
    """No sample at a grid point, ``reason`` (``gap_<stream>``, ``expired_<stream>``,
    ``invalid_<stream>``), nor at the later ones before ``until`` (ns)."""

    reason: str
    until: int


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
        max_jump_ns: int = 5_000_000_000,
        confirm: int = 5,
        max_buffered: int = 20_000,
        max_clock_ns: int = 0,
        counts: dict[str, StreamCounts] | None = None,
    ) -> None:
        names = tuple(names)
        self.required = tuple(required)
        unknown = [n for n in self.required if n not in names]
        if unknown or not self.required:
            raise ValueError(f"required streams must be some of {names}, got {self.required}")
        if period_ns <= 0 or max_gap_ns <= 0 or buffer_ns <= 0 or max_buffered < 2:
            raise ValueError("period_ns, max_gap_ns and buffer_ns must be positive, max_buffered at least 2")
        if max_jump_ns < max_gap_ns or confirm < 0 or max_clock_ns < 0:
            raise ValueError("max_jump_ns must be at least max_gap_ns; confirm and max_clock_ns not negative")
        self.period_ns = int(period_ns)
        self.max_gap_ns = int(max_gap_ns)
        self.buffer_ns = int(buffer_ns)
        self.max_jump_ns = int(max_jump_ns)
        self._back = -self.max_jump_ns
        self.max_buffered = int(max_buffered)
        self.max_clock_ns = int(max_clock_ns)
        self.clock_ns: int | None = None  # the caller's clock; 0 or None: unknown (not checked)
        counts = counts if counts is not None else {}
        self.streams = {n: Stream(n, counts[n] if n in counts else StreamCounts(), self.max_gap_ns, self.max_jump_ns)
                        for n in names}
        self._needed = [self.streams[n] for n in self.required]
        self._all = list(self.streams.values())
        self.timelines = Timelines(self._all, max_gap_ns=self.max_gap_ns, max_jump_ns=self.max_jump_ns,
                                   confirm=int(confirm), buffer_ns=self.buffer_ns, max_buffered=self.max_buffered)
        self._slow = self.timelines.slow  # every message the fast path of add() does not take
        self.next_ns: int | None = None  # the next grid point to form
        self._frontier: Stream | None = None  # the required stream that has not reached it

    @property
    def counts(self) -> dict[str, StreamCounts]:
        return {name: s.counts for name, s in self.streams.items()}

    def buffered(self) -> int:
        """Messages in the buffers (both timelines) and held as jump candidates."""
        return sum(len(s.stamps) + len(s.held) + sum(len(g[0]) for g in s.segs.values()) for s in self._all)

    def mode(self, stream: Stream) -> int:
        """:data:`CURRENT`, :data:`AHEAD` (on a later timeline) or :data:`BEHIND` (on an
        earlier one: its next messages that continue its stamps are stragglers)."""
        epoch = self.timelines.epoch
        return CURRENT if stream.epoch == epoch else AHEAD if stream.epoch > epoch else BEHIND

    # ------------------------------------------------------------------ messages
    def reject(self, stream: Stream, reason: str) -> str:
        """Count a received message of ``stream`` that the caller could not use (no stamp);
        returns the reason it is counted under (:meth:`.bookkeeping.Tally.count`)."""
        counts = stream.counts
        counts.received += 1
        return counts.reject(reason)

    def reject_invalid(self, stream: Stream, stamp: int, reason: str) -> bool:
        """Count a received message of ``stream`` stamped ``stamp`` whose values the caller
        found unusable (``reason``: implausible, another frame). When its stamp continues the
        stream it is a hole: no sample is interpolated across it. Returns whether samples may
        be due (:meth:`due`)."""
        counts = stream.counts
        counts.received += 1
        if self.max_clock_ns and self._far_from_clock(counts, stamp):
            return False
        return self._slow(stream, stamp, None, reason)

    def add(self, stream: Stream, stamp: int, values: Values, finite: bool = True) -> bool:
        """Accept a message (``finite``: the caller found every value finite; if not, it is a
        ``non_finite`` hole, see :meth:`reject_invalid`) or count why not. Returns whether
        samples may be due (:meth:`due`): false while the required stream the grid waits for
        has not reached the next grid point, the usual case."""
        counts = stream.counts
        counts.received += 1
        if self.max_clock_ns and self._far_from_clock(counts, stamp):  # (checked only when on)
            return False
        if stream.slow or not finite:
            return self._slow(stream, stamp, values if finite else None, "non_finite")
        dt = stamp - counts.newest_ns  # type: ignore[operator]  # not slow: newest_ns is set (_update_slow)
        if dt <= 0:
            if dt >= self._back:
                counts.reject("duplicate" if dt == 0 else "out_of_order")
                return False
            return self._slow(stream, stamp, values, "")
        if dt > stream.hold_ns:
            return self._slow(stream, stamp, values, "")
        # The usual case: the next message of a stream on the current timeline.
        ring = stream.ring
        i = stream.ring_i
        ring[i] = dt
        stream.ring_i = i + 1 if i < RING - 1 else 0
        if dt > stream.band_hi or dt < stream.band_lo:
            stream.interval(dt)
        stamps = stream.stamps
        stamps.append(stamp)
        stream.values.append(values)
        stream.last = counts.newest_ns = stamp
        timelines = self.timelines
        if stamp > timelines.hi:
            timelines.hi = stamp
        if stamp - stamps[0] > self.buffer_ns or len(stamps) > self.max_buffered:
            expire(stream, stamps, stream.values, stream.broken, stamp, self.buffer_ns, self.max_buffered)
        frontier = self._frontier
        # The frontier is a needed stream that has messages, and next_ns is set once it is.
        return frontier is None or frontier.last >= self.next_ns  # type: ignore[operator]

    def _far_from_clock(self, counts: StreamCounts, stamp: int) -> bool:
        """Whether ``stamp`` lies more than ``max_clock_ns`` from the caller's clock (when it
        is known): then the message is counted as ``far_from_clock``, and goes no further.
        The one clock check of every received message (:meth:`add`, :meth:`reject_invalid`)."""
        clock = self.clock_ns
        if clock and abs(stamp - clock) > self.max_clock_ns:
            counts.reject("far_from_clock")
            return True
        return False

    # ------------------------------------------------------------------ the grid
    def due(self) -> list[Sample | Skipped | Restart]:
        """Every grid point that the buffered messages decide, in time order, and a
        :class:`Restart` where the data moved to a new timeline."""
        out: list[Sample | Skipped | Restart] = []
        while True:
            self._form(out)
            timelines = self.timelines
            if not (timelines.pending and self._timeline_over()):
                return out
            out.append(Restart(timelines.pending[timelines.epoch + 1][2]))
            timelines.next_timeline()
            self._restart_grid()

    def _form(self, out: list[Sample | Skipped | Restart]) -> None:
        needed = self._needed
        P = self.period_ns
        t = self.next_ns
        # The frontier keeps at least one message (_trim and _expire never empty a buffer).
        if t is not None and self._frontier is not None and self._frontier.last < t:  # type: ignore[operator]
            return
        for s in needed:
            if not s.stamps:
                return
        if t is None:
            start = max(s.stamps[0] for s in needed)
            t = -(-start // P) * P
        t_start = t
        while True:
            lagging = min(needed, key=_NEWEST)  # every needed stream holds a message here
            if lagging.last < t:  # type: ignore[operator]  # (last is set: it holds a message)
                self._frontier = lagging
                break
            values = self._interpolate(t)
            if isinstance(values, _Hole):
                # Every grid point up to the hole's end shares the problem: report them at once.
                n_skip = max(1, -(-(values.until - t) // P))
                out.append(Skipped(t, n_skip, values.reason))
                t += n_skip * P
            else:
                out.append(Sample(t, values))
                t += P
        if t != t_start:
            self._trim(t)
        self.next_ns = t

    def _interpolate(self, t: int) -> list[Sequence[float]] | _Hole:
        """The required streams' values at ``t``, or why there are none and until when."""
        vals: list[Sequence[float]] = []
        max_gap = self.max_gap_ns
        for s in self._needed:
            stamps = s.stamps
            i = bisect_left(stamps, t)
            t1 = stamps[i]
            if t1 == t:
                vals.append(s.values[i])
                continue
            if i == 0:
                return _Hole(f"expired_{s.name}", stamps[0])
            t0 = stamps[i - 1]
            broken = s.broken
            if broken:
                j = bisect_left(broken, t0)
                if j < len(broken) and broken[j] == t0:
                    return _Hole(f"invalid_{s.name}", t1)
            if t1 - t0 > max_gap:
                return _Hole(f"gap_{s.name}", t1)
            w = (t - t0) / (t1 - t0)
            vals.append([x + w * (y - x) for x, y in zip(s.values[i - 1], s.values[i], strict=True)])
        return vals

    def _trim(self, t_next: int) -> None:
        """Drop messages no later sample can need (keep the last one at or before ``t_next``)."""
        for s in self._all:
            stamps = s.stamps
            if len(stamps) > 1 and stamps[1] <= t_next:
                i = bisect_right(stamps, t_next) - 1
                drop_front(stamps, s.values, s.broken, i)

    def _timeline_over(self) -> bool:
        """With a later timeline open: can the current one form no further sample?"""
        cutoff = None
        moved = True
        epoch = self.timelines.epoch
        for s in self._needed:
            if s.epoch > epoch:
                if s.last is not None and (cutoff is None or s.last < cutoff):
                    cutoff = s.last
            else:
                moved = False
        if moved:
            return True
        return cutoff is not None and self.next_ns is not None and self.next_ns > cutoff

    def _restart_grid(self) -> None:
        """The grid starts afresh at the next samples the buffered messages allow."""
        self.next_ns = None
        self._frontier = None

    # ------------------------------------------------------------------ timelines
    def time_jumped(self, new_ns: int, old_ns: int) -> bool:
        """The caller's clock jumped back from ``old_ns`` to ``new_ns`` (``/clock`` restarted):
        :meth:`.timelines.Timelines.time_jumped`."""
        return self.timelines.time_jumped(new_ns, old_ns)

    def clear(self, *, forget_newest: bool) -> None:
        """Drop every buffered and held message (counted as expired) and restart the grid and
        the timelines at the next messages. ``forget_newest`` (``~/reset``) also forgets the
        streams' newest stamps, so that older stamps are accepted again."""
        self.timelines.clear(forget_newest=forget_newest)
        self._restart_grid()
