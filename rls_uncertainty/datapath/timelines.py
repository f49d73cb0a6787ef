"""Timelines: which stamps continue a stream, and where the data moved when they do not
(pure Python; the slow path of :class:`.sampling.Sampler`, every message that is not the
in-order next one of a stream on the current timeline). ``J`` below is ``max_jump_ns``
(``inputs.max_stamp_jump``).

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
  the samples a fresh sampler fed that timeline alone forms. Then :meth:`.sampling.Sampler.due`
  returns a :class:`.sampling.Restart` and the next timeline becomes current, its buffered messages the first
  of it: nothing of either timeline is lost, whatever the interleaving of the streams.
* A stream that had not moved on by then is *behind*: its messages that continue its own
  stamps are stragglers, rejected as ``previous_timeline`` (they cannot wipe the new run); its
  first message that leaves them for the current or a later timeline joins it. A behind
  stream whose stamps go on for more than ``J`` past the switch shows that its timeline is
  alive (the others left it after a confirmed burst of bad stamps): it opens (or joins) a
  timeline again, so a burst of bad stamps costs a restart, never the stream.
* :meth:`Timelines.time_jumped` (a backwards ``/clock`` jump) tells the streams still on the
  current timeline that a backward step of their stamps to within ``J`` of the new clock time
  needs no confirmation (so a replay looped by less than ``J`` restarts too); the restart
  itself happens when the stamps follow, so messages sent before the jump that arrive after it
  still complete the run they belong to.
* :meth:`Timelines.clear` forgets everything about the inputs (buffers, newest stamps,
  candidates, timelines, grid): afterwards older stamps are accepted again.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from .bookkeeping import StreamCounts
from .streams import NEVER, RING, Stream, Values, expire

__all__ = ["Timelines", "MAX_PENDING"]

MAX_PENDING = 4  # timelines opened after the current one and not yet reached (bounds memory)


class Timelines:
    """The timelines of the streams ``streams``: the current one (``epoch``; its stamp range
    ``lo`` .. ``hi``, ``lo`` None while it has no message) and the later ones opened by
    streams that jumped (``pending``). Accepted messages go to the buffers of their stream
    and timeline (:mod:`.streams`: ``buffer_ns``, ``max_buffered``)."""

    def __init__(self, streams: Sequence[Stream], *, max_gap_ns: int, max_jump_ns: int, confirm: int,
                 buffer_ns: int, max_buffered: int) -> None:
        self._all = list(streams)
        self.max_gap_ns = max_gap_ns
        self.max_jump_ns = max_jump_ns
        self.confirm = confirm
        self.buffer_ns = buffer_ns
        self.max_buffered = max_buffered
        self.lo: int | None = None
        self.hi = NEVER
        self.epoch = 0  # the current timeline
        # Later timelines by epoch: [lo (int), hi (int), restart reason (str)], updated in place.
        self.pending: dict[int, list[Any]] = {}
        self.rewind_ns: int | None = None  # the clock time a /clock jump went back to

    @staticmethod
    def _drop_held(counts: StreamCounts, n: int) -> None:
        """Held candidates the stream did not confirm (no key for none: diagnostics warn on any)."""
        if n:
            counts.reject("stamp_jump", n)

    def update_slow(self, s: Stream) -> None:
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

    def slow(self, s: Stream, m: int, values: Values | None, reason: str) -> bool:
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
            counts.reject("duplicate" if dt == 0 else "out_of_order")
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
            s.ring_i = (s.ring_i + 1) % RING
            if dt > s.band_hi or dt < s.band_lo:
                s.interval(dt)
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
        self.update_slow(s)
        if values is None:
            counts.reject(reason)
            if stamps and (not broken or broken[-1] != stamps[-1]):
                broken.append(stamps[-1])
            return False
        stamps.append(m)
        vals.append(values)
        if current:
            s.last = m
        if m - stamps[0] > self.buffer_ns or len(stamps) > self.max_buffered:
            expire(s, stamps, vals, broken, m, self.buffer_ns, self.max_buffered)
        return True

    def _candidate(self, s: Stream, m: int, values: Values | None, reason: str) -> bool:
        """Hold ``m`` as a jump candidate, or continue the held ones; confirm when enough."""
        counts = s.counts
        if values is None:  # a message with bad values never starts or continues a jump
            counts.reject(reason)
            return False
        held = s.held
        if held:
            d = m - held[-1][0]
            if 0 < d <= self.max_jump_ns:
                held.append((m, values))
                return self._confirm(s) if len(held) > self.confirm else False
            if -self.max_jump_ns <= d <= 0:
                counts.reject("duplicate" if d == 0 else "out_of_order")
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
            self.update_slow(s)
            return False
        ref = own if own is not None else (self.hi if self.lo is not None else None)
        opens = "stamps_jumped_backwards" if ref is not None and first < ref else "stamps_jumped_forward"
        return self._open(s, held, "", opens)

    def _open(self, s: Stream, msgs: list[tuple[int, Values | None]], reason: str, opens: str) -> bool:
        """Stream ``s`` opens a new timeline with ``msgs``; the restart that reaches it is
        counted as ``opens``. Other streams' held candidates that land near it join it."""
        if msgs[-1][1] is None:  # a hole (only ever the last) moves nothing
            s.counts.reject(reason)
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
            s.counts.reject(reason)
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
            counts.reject("previous_timeline")
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
            counts.reject("previous_timeline")
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

    def next_timeline(self) -> None:
        """The next timeline becomes current: its buffers replace the old ones (those still
        buffered expire), streams still on the old one are behind (the caller restarts its
        grid)."""
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
            self.update_slow(s)
        self.lo, self.hi = lo, hi
        self.rewind_ns = None

    def clear(self, *, forget_newest: bool) -> None:
        """Drop every buffered and held message (counted as expired) and restart the
        timelines at the next messages. ``forget_newest`` (``~/reset``) also forgets the
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
            self.update_slow(s)
        self.lo, self.hi = None, NEVER
        self.rewind_ns = None
