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
* **Missing messages.** The reference interval of a stream is the lower median of its last 9
  stamp intervals, recomputed when an interval leaves +-25% of it. An interval over 1.5 times
  the reference counts ``round(dt / reference) - 1`` messages as ``missing`` (lost before they
  arrived). A rate change (200 to 100 Hz) therefore counts at most 4 messages as missing, then
  the reference follows the new rate; an isolated dropout is counted in full.
* **Buffers.** A stream's buffer holds at most ``max_buffered`` messages and at most
  ``buffer_ns`` of stamps ahead of the message that brackets the next grid point; beyond
  either the oldest expire (``expired``), so memory is bounded whatever arrives.
* **The grid.** Samples fall on ``t_k = k * period_ns`` (integer nanoseconds, so the grid does
  not depend on when sampling started). A sample at ``t_k`` is formed once every required
  stream has a message at or after ``t_k``; each is linearly interpolated between the two
  messages around ``t_k``, never extrapolated. If a required stream is silent for more than
  ``max_gap_ns`` around ``t_k``, its message before ``t_k`` has expired, or a hole lies there,
  the grid points up to its next message are skipped together (``gap_<stream>``,
  ``expired_<stream>``, ``invalid_<stream>``). A gap is never longer than the stamps really
  advanced within one timeline: a jump starts a new timeline instead of skipping grid points.

**Timelines.** Each stream checks its own stamps (per-stream FIFO order holds for one
publisher; the interleaving of different streams is arbitrary, so no rule compares a stamp with
another stream's order of arrival).

* A stamp ahead of the stream's newest by at most ``hold_ns`` (``max(max_gap_ns, 3 intervals)``,
  at most ``J``), or not beyond the newest stamp of the whole timeline by more than
  ``max_gap_ns``, continues the stream. A stamp further ahead, or more than ``J`` behind, is a
  *jump candidate*: held, not used. If the stream then continues its previous stamps, the held
  candidates are rejected as ``stamp_jump`` and nothing changed: one message cannot move a
  stream's notion of "now" further than ``hold_ns`` past its own newest stamp and
  ``max_gap_ns`` past every stream's newest, so it can refuse no more valid data than that
  (a message stamped years ahead, or 0, refuses none). If the next ``confirm`` messages continue
  the candidate's stamps (increasing, steps of at most ``J``), the candidates are confirmed:
  a forward step of at most ``J`` (or to within ``J`` of the timeline's newest stamp) is a
  dropout, taken as a gap; anything else is a *jump* to a new timeline.
* The first stream that jumps opens a *later* timeline (at most :data:`MAX_PENDING` are open
  at once; a stream may run whole runs ahead of another when an executor drains a slow
  topic's queue first). Its messages go to separate buffers, and every other stream whose
  stamps then leave its own and land near that timeline (within ``J`` of its stamp range)
  joins it at once, without confirmation. The current timeline goes on forming samples from
  the streams still on it until no further sample is possible (every required stream moved
  on, or the grid passed the last stamp a required stream that moved on had there): exactly
  the samples a fresh sampler fed that timeline alone forms. Then :meth:`Sampler.due` returns
  a :class:`Restart` and the next timeline becomes current, its buffered messages the first
  of it: nothing of either timeline is lost, whatever the interleaving of the streams.
* A stream that had not moved on by then is *behind*: its messages that continue its own
  stamps are stragglers, rejected as ``previous_timeline`` (they cannot wipe the new run); its
  first message that leaves them for the current or a later timeline joins it. A behind
  stream whose stamps go on for more than ``J`` past the switch shows that its timeline is
  alive (the others left it after a confirmed burst of bad stamps): it opens (or joins) a
  timeline again, so a burst of bad stamps costs a restart, never the stream.
* :meth:`Sampler.time_jumped` (a backwards ``/clock`` jump) tells the streams still on the
  current timeline that a backward step of their stamps to within ``J`` of the new clock time
  needs no confirmation (so a replay looped by less than ``J`` restarts too); the restart
  itself happens when the stamps follow, so messages sent before the jump that arrive after it
  still complete the run they belong to.
* :meth:`Sampler.clear` forgets everything about the inputs (buffers, newest stamps,
  candidates, timelines, grid): afterwards older stamps are accepted again.

The counters of each stream live in a :class:`StreamCounts` that outlives the sampler: a
reconfigured pipeline hands the same objects to its new sampler, so no count is lost.
"""

from __future__ import annotations

from bisect import bisect_left, bisect_right
from collections import Counter
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from operator import attrgetter
from typing import Any, NamedTuple

__all__ = ["StreamCounts", "Stream", "Sample", "Skipped", "Restart", "Sampler", "CURRENT", "AHEAD", "BEHIND"]

# Where a stream stands with respect to the timelines.
CURRENT, AHEAD, BEHIND = 0, 1, 2
MAX_PENDING = 4  # timelines opened after the current one and not yet reached (bounds memory)
_RING = 9  # stamp intervals in the median reference interval
_NEVER = -(1 << 62)  # "no stamp yet" for the timeline's newest stamp (keeps the hot path int-only)

# One message's values (the caller's tuple of floats); ``None`` where a message is a hole.
Values = tuple[float, ...]


@dataclass(slots=True)
class StreamCounts:
    """What happened to one stream's messages: every received message is accepted or rejected
    (with its reason); accepted ones may later expire unused. ``missing`` counts messages
    inferred from stamp gaps (never received). ``newest_ns`` is the newest stamp of the
    stream's own timeline (the stamp order is checked against it), ``interval_ns`` the
    reference interval (lower median of the recent stamp intervals)."""

    received: int = 0
    rejected: Counter[str] = field(default_factory=Counter)
    expired: int = 0
    missing: int = 0
    newest_ns: int | None = None
    interval_ns: float = 0.0

    @property
    def accepted(self) -> int:
        return self.received - sum(self.rejected.values())

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


class Stream:
    """One stream: the time-ordered buffer of the current timeline (``stamps``, ``values``,
    oldest first; ``last`` the newest buffered stamp, ``None`` while empty; ``broken`` the
    buffered stamps after which a hole lies), its timeline state (``epoch``, the timeline of
    its newest message; held jump candidates ``held``; ``segs``, its buffers of later
    timelines by epoch) and its interval statistics."""

    __slots__ = ("name", "stamps", "values", "last", "counts", "broken", "epoch", "slow", "held", "segs",
                 "rewound", "left_at", "ring", "ring_i", "band_lo", "band_hi", "hold_ns")

    def __init__(self, name: str, counts: StreamCounts, hold_ns: int) -> None:
        self.name = name
        self.stamps: list[int] = []
        self.values: list[Values] = []
        self.last: int | None = None
        self.counts = counts
        self.broken: list[int] = []
        self.epoch = 0
        self.slow = True  # the message path needs more than the in-order fast path
        self.held: list[tuple[int, Values | None]] = []
        self.segs: dict[int, tuple[list[int], list[Values], list[int]]] = {}
        self.left_at = 0  # behind: its newest stamp when the data left its timeline
        self.rewound = False
        known = int(counts.interval_ns)
        self.ring = [known] * _RING
        self.ring_i = 0
        self.band_lo, self.band_hi = (known - known // 4, known + known // 4) if known else (0, -1)
        self.hold_ns = hold_ns


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


_NEWEST = attrgetter("last")


def _drop_front(stamps: list[int], values: list[Values], broken: list[int], cut: int) -> None:
    del stamps[:cut]
    del values[:cut]
    if broken:
        first = stamps[0] if stamps else None
        while broken and (first is None or broken[0] < first):
            del broken[0]


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
        self.confirm = int(confirm)
        self.max_buffered = int(max_buffered)
        self.max_clock_ns = int(max_clock_ns)
        self.clock_ns: int | None = None  # the caller's clock; 0 or None: unknown (not checked)
        counts = counts if counts is not None else {}
        self.streams = {n: Stream(n, counts[n] if n in counts else StreamCounts(), self.max_gap_ns) for n in names}
        for s in self.streams.values():
            if s.counts.interval_ns:
                self._set_band(s, int(s.counts.interval_ns))
        self._needed = [self.streams[n] for n in self.required]
        self._all = list(self.streams.values())
        self.next_ns: int | None = None  # the next grid point to form
        self._frontier: Stream | None = None  # the required stream that has not reached it
        # The current timeline's stamp range (lo None: nothing on it yet), the next one's.
        self.lo: int | None = None
        self.hi = _NEVER
        self.epoch = 0  # the current timeline
        # Later timelines by epoch: [lo (int), hi (int), restart reason (str)], updated in place.
        self.pending: dict[int, list[Any]] = {}
        self.rewind_ns: int | None = None  # the clock time a /clock jump went back to

    @property
    def counts(self) -> dict[str, StreamCounts]:
        return {name: s.counts for name, s in self.streams.items()}

    def buffered(self) -> int:
        """Messages in the buffers (both timelines) and held as jump candidates."""
        return sum(len(s.stamps) + len(s.held) + sum(len(g[0]) for g in s.segs.values()) for s in self._all)

    def mode(self, stream: Stream) -> int:
        """:data:`CURRENT`, :data:`AHEAD` (on a later timeline) or :data:`BEHIND` (on an
        earlier one: its next messages that continue its stamps are stragglers)."""
        return CURRENT if stream.epoch == self.epoch else AHEAD if stream.epoch > self.epoch else BEHIND

    # ------------------------------------------------------------------ messages
    def reject(self, stream: Stream, reason: str) -> None:
        """Count a received message of ``stream`` that the caller could not use (no stamp)."""
        counts = stream.counts
        counts.received += 1
        counts.rejected[reason] += 1

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
                counts.rejected["duplicate" if dt == 0 else "out_of_order"] += 1
                return False
            return self._slow(stream, stamp, values, "")
        if dt > stream.hold_ns:
            return self._slow(stream, stamp, values, "")
        # The usual case: the next message of a stream on the current timeline.
        ring = stream.ring
        i = stream.ring_i
        ring[i] = dt
        stream.ring_i = i + 1 if i < _RING - 1 else 0
        if dt > stream.band_hi or dt < stream.band_lo:
            self._interval(stream, dt)
        stamps = stream.stamps
        stamps.append(stamp)
        stream.values.append(values)
        stream.last = counts.newest_ns = stamp
        if stamp > self.hi:
            self.hi = stamp
        if stamp - stamps[0] > self.buffer_ns or len(stamps) > self.max_buffered:
            self._expire(stream, stamps, stream.values, stream.broken, stamp)
        frontier = self._frontier
        # The frontier is a needed stream that has messages, and next_ns is set once it is.
        return frontier is None or frontier.last >= self.next_ns  # type: ignore[operator]

    def _far_from_clock(self, counts: StreamCounts, stamp: int) -> bool:
        """Whether ``stamp`` lies more than ``max_clock_ns`` from the caller's clock (when it
        is known): then the message is counted as ``far_from_clock``, and goes no further.
        The one clock check of every received message (:meth:`add`, :meth:`reject_invalid`)."""
        clock = self.clock_ns
        if clock and abs(stamp - clock) > self.max_clock_ns:
            counts.rejected["far_from_clock"] += 1
            return True
        return False

    def _interval(self, stream: Stream, dt: int) -> None:
        """An interval outside the reference band: recompute the reference (lower median of
        the recent intervals, this one included) and count messages missing before this one."""
        recent = sorted(x for x in stream.ring if x > 0)
        ref = recent[(len(recent) - 1) // 2]
        counts = stream.counts
        counts.interval_ns = float(ref)
        if dt > 1.5 * ref:
            counts.missing += int(round(dt / ref)) - 1
        self._set_band(stream, ref)

    def _set_band(self, stream: Stream, ref: int) -> None:
        stream.band_lo = ref - ref // 4
        stream.band_hi = ref + ref // 4
        stream.hold_ns = min(max(self.max_gap_ns, 3 * ref), self.max_jump_ns)

    def _expire(self, stream: Stream, stamps: list[int], values: list[Values], broken: list[int], newest: int) -> None:
        """Drop messages more than ``buffer_ns`` older than the newest (another stream holds the
        grid back), keeping the one just before the cut (it may still bracket a later sample),
        and beyond ``max_buffered`` (then an eighth more, so a flood costs O(1) per message).
        They are counted as expired, never used."""
        cut = bisect_left(stamps, newest - self.buffer_ns) - 1
        over = len(stamps) - self.max_buffered
        if over > 0:
            cut = max(cut, over + self.max_buffered // 8)
        if cut > 0:
            _drop_front(stamps, values, broken, cut)
            stream.counts.expired += cut

    # ------------------------------------------------------------------ timelines (slow path)
    @staticmethod
    def _drop_held(counts: StreamCounts, n: int) -> None:
        """Held candidates the stream did not confirm (no key for none: diagnostics warn on any)."""
        if n:
            counts.rejected["stamp_jump"] += n

    def _update_slow(self, s: Stream) -> None:
        s.slow = s.epoch != self.epoch or bool(s.held) or s.rewound or s.counts.newest_ns is None

    def _near(self, epoch: int, m: int) -> bool:
        """Whether ``m`` lies within ``J`` of the stamps seen on timeline ``epoch``."""
        J = self.max_jump_ns
        if epoch == self.epoch:
            return self.lo is None or self.lo - J <= m <= self.hi + J
        lo: int
        hi: int
        lo, hi, _ = self.pending[epoch]
        return lo - J <= m <= hi + J

    def _later(self, s: Stream, m: int) -> int | None:
        """The first pending timeline after the stream's own that ``m`` lands near."""
        J = self.max_jump_ns
        for e, (lo, hi, _) in self.pending.items():
            if e > s.epoch and lo - J <= m <= hi + J:
                return e
        return None

    def _present(self, s: Stream) -> int:
        return self.hi if s.epoch == self.epoch else self.pending[s.epoch][1]

    def _slow(self, s: Stream, m: int, values: Values | None, reason: str) -> bool:
        """Every message that is not the in-order next one of a stream on the current
        timeline: first messages, holes (``values`` None, counted as ``reason``), jumps,
        candidates, streams on a later or an earlier timeline."""
        counts = s.counts
        if s.epoch < self.epoch:
            return self._behind(s, m, values, reason)
        own = counts.newest_ns
        J = self.max_jump_ns
        if own is None:  # the stream's first message (start, ~/reset): on the current timeline
            near_cur = self._near(self.epoch, m)
            later = self._later(s, m) if self.pending else None
            if near_cur and later is not None:  # the timelines overlap (a looped replay): the closer
                near_cur = abs(m - self.hi) <= abs(m - self.pending[later][1])
            if near_cur:
                return self._take(s, m, values, reason, None)
            if later is not None:
                return self._join(s, later, [(m, values)], reason)
            return self._candidate(s, m, values, reason)
        dt = m - own
        if s.rewound and dt < 0 and abs(m - self.rewind_ns) <= J:  # type: ignore[operator]
            # The clock went back and this stream follows it: no confirmation needed.
            later = self._later(s, m)
            if later is not None or not self.pending:
                rewind = self.rewind_ns
                held = [h for h in s.held if abs(h[0] - rewind) <= J and h[0] < m]  # type: ignore[operator]
                self._drop_held(counts, len(s.held) - len(held))
                s.held = []
                if later is not None:
                    return self._join(s, later, [*held, (m, values)], reason)
                return self._open(s, [*held, (m, values)], reason, "time_jumped_backwards")
        if dt > 0 and (dt <= s.hold_ns or m <= self._present(s) + self.max_gap_ns):
            held = s.held
            if held:
                s.held = []
                if dt > s.hold_ns and held[0][0] > own and 0 < m - held[-1][0] <= J:
                    # The held run leads to the timeline's present: a dropout of this stream.
                    prev = own
                    for h, v in held:
                        self._take(s, h, v, "", h - prev)
                        prev = h
                    return self._take(s, m, values, reason, m - prev)
                self._drop_held(counts, len(held))  # the stream goes on: they were wrong
            return self._take(s, m, values, reason, dt)
        if dt <= 0 and dt >= -J:
            counts.rejected["duplicate" if dt == 0 else "out_of_order"] += 1
            return False
        later = self._later(s, m) if self.pending else None
        if later is not None:  # another stream opened that timeline: join it at once
            held = [h for h in s.held if self._near(later, h[0]) and h[0] < m]
            self._drop_held(counts, len(s.held) - len(held))
            s.held = []
            return self._join(s, later, [*held, (m, values)], reason)
        return self._candidate(s, m, values, reason)

    def _take(self, s: Stream, m: int, values: Values | None, reason: str, dt: int | None) -> bool:
        """Accept ``m`` on the stream's timeline (the current one or a later one); a hole
        (``values`` None) is counted as ``reason`` and marks the interval after the newest
        buffered message. ``dt``: the interval from the stream's previous message, if one."""
        counts = s.counts
        if dt is not None:
            ring = s.ring
            ring[s.ring_i] = dt
            s.ring_i = (s.ring_i + 1) % _RING
            if dt > s.band_hi or dt < s.band_lo:
                self._interval(s, dt)
        counts.newest_ns = m
        current = s.epoch == self.epoch
        if current:
            stamps, vals, broken = s.stamps, s.values, s.broken
            if self.lo is None or m < self.lo:
                self.lo = m
            if m > self.hi:
                self.hi = m
        else:
            stamps, vals, broken = s.segs[s.epoch]
            r = self.pending[s.epoch]
            r[0] = min(r[0], m)
            r[1] = max(r[1], m)
        self._update_slow(s)
        if values is None:
            counts.rejected[reason] += 1
            if stamps and (not broken or broken[-1] != stamps[-1]):
                broken.append(stamps[-1])
            return False
        stamps.append(m)
        vals.append(values)
        if current:
            s.last = m
        if m - stamps[0] > self.buffer_ns or len(stamps) > self.max_buffered:
            self._expire(s, stamps, vals, broken, m)
        return True

    def _candidate(self, s: Stream, m: int, values: Values | None, reason: str) -> bool:
        """Hold ``m`` as a jump candidate, or continue the held ones; confirm when enough."""
        counts = s.counts
        if values is None:  # a message with bad values never starts or continues a jump
            counts.rejected[reason] += 1
            return False
        held = s.held
        if held:
            d = m - held[-1][0]
            if 0 < d <= self.max_jump_ns:
                held.append((m, values))
                return self._confirm(s) if len(held) > self.confirm else False
            if -self.max_jump_ns <= d <= 0:
                counts.rejected["duplicate" if d == 0 else "out_of_order"] += 1
                return False
            self._drop_held(counts, len(held))
            held.clear()
        held.append((m, values))
        s.slow = True
        return self._confirm(s) if self.confirm == 0 else False

    def _confirm(self, s: Stream) -> bool:
        """The held candidates continued each other ``confirm`` times: where do they go?"""
        counts = s.counts
        held, s.held = s.held, []
        first = held[0][0]
        own = counts.newest_ns
        if s.epoch >= self.epoch and own is not None and first > own and (
                first - own <= self.max_jump_ns or first <= self._present(s) + self.max_jump_ns):
            # A dropout on the stream's own timeline, not a jump: a gap.
            prev = own
            for m, v in held:
                self._take(s, m, v, "", m - prev)
                prev = m
            return True
        later = self._later(s, first) if self.pending else None
        if later is not None:
            return self._join(s, later, held, "")
        if len(self.pending) >= MAX_PENDING:
            self._drop_held(counts, len(held))
            self._update_slow(s)
            return False
        ref = own if own is not None else (self.hi if self.lo is not None else None)
        opens = "stamps_jumped_backwards" if ref is not None and first < ref else "stamps_jumped_forward"
        return self._open(s, held, "", opens)

    def _open(self, s: Stream, msgs: list[tuple[int, Values | None]], reason: str, opens: str) -> bool:
        """Stream ``s`` opens a new timeline with ``msgs``; the restart that reaches it is
        counted as ``opens``. Other streams' held candidates that land near it join it."""
        if msgs[-1][1] is None:  # a hole (only ever the last) moves nothing
            s.counts.rejected[reason] += 1
            msgs = msgs[:-1]
            if not msgs:
                return False
        e = (max(self.pending) if self.pending else self.epoch) + 1
        self.pending[e] = [msgs[0][0], msgs[0][0], opens]
        self._join(s, e, msgs, "")
        for o in self._all:
            if o is not s and o.held and o.epoch < e and self._near(e, o.held[0][0]):
                self._join(o, e, o.held, "")
        return True

    def _join(self, s: Stream, e: int, msgs: list[tuple[int, Values | None]], reason: str) -> bool:
        """Stream ``s`` moves on to timeline ``e`` with ``msgs`` (increasing)."""
        if msgs[-1][1] is None:
            s.counts.rejected[reason] += 1
            msgs = msgs[:-1]
            if not msgs:
                return False
        s.epoch = e
        if e > self.epoch:
            s.segs[e] = ([], [], [])
        s.held = []
        s.rewound = False
        prev = None
        for m, v in msgs:
            self._take(s, m, v, "", None if prev is None else m - prev)
            prev = m
        return True

    def _behind(self, s: Stream, m: int, values: Values | None, reason: str) -> bool:
        """A message of a stream still on a timeline the data has left (``newest_ns`` is its
        last stamp there)."""
        counts = s.counts
        old = counts.newest_ns
        J = self.max_jump_ns
        d = m - old  # type: ignore[operator]
        if 0 < d <= J:  # it continues its stamps: a straggler of the earlier timeline...
            self._drop_held(counts, len(s.held))
            s.held = []
            if m - s.left_at > J and len(self.pending) < MAX_PENDING:
                # ...unless its timeline goes on for longer than J after the data left it: it
                # is alive (the others left it after a confirmed burst of bad stamps).
                later = self._later(s, m)
                if later is not None:
                    return self._join(s, later, [(m, values)], reason)
                opens = "stamps_jumped_backwards" if m < self.hi else "stamps_jumped_forward"
                return self._open(s, [(m, values)], reason, opens)
            counts.rejected["previous_timeline"] += 1
            counts.newest_ns = m
            return False
        later = self._later(s, m) if self.pending else None
        if d != 0 and not 0 < d <= J and self._near(self.epoch, m):  # joins the current timeline
            self._drop_held(counts, len(s.held))
            s.held = []
            s.epoch = self.epoch
            return self._take(s, m, values, reason, None)
        if later is not None:
            held = [h for h in s.held if self._near(later, h[0]) and h[0] < m]
            self._drop_held(counts, len(s.held) - len(held))
            s.held = []
            return self._join(s, later, [*held, (m, values)], reason)
        if -J <= d <= 0:
            counts.rejected["previous_timeline"] += 1
            return False
        return self._candidate(s, m, values, reason)

    def time_jumped(self, new_ns: int, old_ns: int) -> bool:
        """The caller's clock jumped back from ``old_ns`` to ``new_ns`` (``/clock`` restarted).
        Streams whose stamps then step back to within ``J`` of ``new_ns`` move to the new
        timeline without confirmation. Returns False when there is nothing to restart: no
        data yet, or the data already moved to a timeline nearer the new time than the old."""
        if self.lo is None:
            return False
        if not self.pending and abs(self.hi - new_ns) < abs(self.hi - old_ns):
            return False
        self.rewind_ns = int(new_ns)
        for s in self._all:
            if s.epoch == self.epoch and s.counts.newest_ns is not None:
                s.rewound = True
                s.slow = True
        return True

    # ------------------------------------------------------------------ the grid
    def due(self) -> list[Sample | Skipped | Restart]:
        """Every grid point that the buffered messages decide, in time order, and a
        :class:`Restart` where the data moved to a new timeline."""
        out: list[Sample | Skipped | Restart] = []
        while True:
            self._form(out)
            if not (self.pending and self._timeline_over()):
                return out
            out.append(Restart(self.pending[self.epoch + 1][2]))
            self._next_timeline()

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
            values, reason, skip_to = self._interpolate(t)
            if values is None:
                # Every grid point up to skip_to shares the problem: report them at once.
                # (values None comes with a reason and skip_to, see _interpolate's return type;
                # mypy does not narrow the unpacked tuple's other items.)
                n_skip = max(1, -(-(skip_to - t) // P))  # type: ignore[operator]
                out.append(Skipped(t, n_skip, reason))  # type: ignore[arg-type]
                t += n_skip * P
            else:
                out.append(Sample(t, values))
                t += P
        if t != t_start:
            self._trim(t)
        self.next_ns = t

    def _interpolate(self, t: int) -> tuple[list[Sequence[float]], None, None] | tuple[None, str, int]:
        """``(values, None, None)`` at ``t``, or ``(None, reason, skip_to)``."""
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
                return None, f"expired_{s.name}", stamps[0]
            t0 = stamps[i - 1]
            broken = s.broken
            if broken:
                j = bisect_left(broken, t0)
                if j < len(broken) and broken[j] == t0:
                    return None, f"invalid_{s.name}", t1
            if t1 - t0 > max_gap:
                return None, f"gap_{s.name}", t1
            w = (t - t0) / (t1 - t0)
            vals.append([x + w * (y - x) for x, y in zip(s.values[i - 1], s.values[i], strict=True)])
        return vals, None, None

    def _trim(self, t_next: int) -> None:
        """Drop messages no later sample can need (keep the last one at or before ``t_next``)."""
        for s in self._all:
            stamps = s.stamps
            if len(stamps) > 1 and stamps[1] <= t_next:
                i = bisect_right(stamps, t_next) - 1
                _drop_front(stamps, s.values, s.broken, i)

    def _timeline_over(self) -> bool:
        """With a later timeline open: can the current one form no further sample?"""
        cutoff = None
        moved = True
        for s in self._needed:
            if s.epoch > self.epoch:
                if s.last is not None and (cutoff is None or s.last < cutoff):
                    cutoff = s.last
            else:
                moved = False
        if moved:
            return True
        return cutoff is not None and self.next_ns is not None and self.next_ns > cutoff

    def _next_timeline(self) -> None:
        """The next timeline becomes current: its buffers replace the old ones (those still
        buffered expire), streams still on the old one are behind, the grid restarts."""
        new = self.epoch + 1
        lo, hi, _ = self.pending.pop(new)
        self.epoch = new
        for s in self._all:
            counts = s.counts
            counts.expired += len(s.stamps)
            seg = s.segs.pop(new, None)
            if seg is not None:
                s.stamps, s.values, s.broken = seg
            else:
                s.stamps, s.values, s.broken = [], [], []
            s.last = s.stamps[-1] if s.stamps else None
            if s.epoch < new:
                if counts.newest_ns is None:
                    s.epoch = new  # it never had a message: simply on the new timeline
                elif s.epoch == new - 1:
                    s.left_at = counts.newest_ns
            s.rewound = False
            self._update_slow(s)
        self.lo, self.hi = lo, hi
        self.rewind_ns = None
        self.next_ns = None
        self._frontier = None

    # ------------------------------------------------------------------ restart
    def clear(self, *, forget_newest: bool) -> None:
        """Drop every buffered and held message (counted as expired) and restart the grid and
        the timelines at the next messages. ``forget_newest`` (``~/reset``) also forgets the
        streams' newest stamps, so that older stamps are accepted again."""
        self.epoch = 0
        self.pending = {}
        for s in self._all:
            counts = s.counts
            counts.expired += len(s.stamps) + len(s.held) + sum(len(g[0]) for g in s.segs.values())
            s.stamps, s.values, s.broken, s.last = [], [], [], None
            s.held, s.segs, s.epoch, s.rewound = [], {}, 0, False
            if forget_newest:
                counts.newest_ns = None
            self._update_slow(s)
        self.lo, self.hi = None, _NEVER
        self.rewind_ns = None
        self.next_ns = None
        self._frontier = None
