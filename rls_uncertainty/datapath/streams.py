"""One input stream of the sampler: its counters, its time-ordered buffers and its interval
statistics (pure Python; see :mod:`.sampling` for the rules they serve).

* **Accounting.** A stream counts what happened to its messages in a
  :class:`.bookkeeping.StreamCounts`: received, rejected by reason, expired unused, missing
  (inferred from stamp gaps). It outlives the sampler: a reconfigured pipeline hands the same
  objects to its new sampler.
* **Missing messages.** The reference interval of a stream is the lower median of its last 9
  stamp intervals, recomputed when an interval leaves +-25% of it
  (:meth:`Stream.interval`). An interval over 1.5 times the reference counts
  ``round(dt / reference) - 1`` messages as ``missing``. A rate change (200 to 100 Hz)
  therefore counts at most 4 messages as missing, then the reference follows the new rate;
  an isolated dropout is counted in full.
* **Buffers.** A stream's buffer holds at most ``max_buffered`` messages and at most
  ``buffer_ns`` of stamps ahead of the message that brackets the next grid point; beyond
  either the oldest expire (:func:`expire`), so memory is bounded whatever arrives.
"""

from __future__ import annotations

from bisect import bisect_left

from .bookkeeping import StreamCounts

__all__ = ["Stream", "Values", "RING", "NEVER", "expire", "drop_front"]

RING = 9  # stamp intervals in the median reference interval
NEVER = -(1 << 62)  # "no stamp yet" for a timeline's newest stamp (keeps the hot path int-only)

# One message's values (the caller's tuple of floats); ``None`` where a message is a hole.
Values = tuple[float, ...]


class Stream:
    """One stream: the time-ordered buffer of the current timeline (``stamps``, ``values``,
    oldest first; ``last`` the newest buffered stamp, ``None`` while empty; ``broken`` the
    buffered stamps after which a hole lies), its timeline state (``epoch``, the timeline of
    its newest message; held jump candidates ``held``; ``segs``, its buffers of later
    timelines by epoch) and its interval statistics. ``max_gap_ns`` and ``max_jump_ns`` bound
    ``hold_ns``: how far ahead of its newest stamp a message still continues the stream,
    ``max(max_gap_ns, 3 intervals)``, at most ``max_jump_ns``."""

    __slots__ = ("name", "stamps", "values", "last", "counts", "broken", "epoch", "slow", "held", "segs",
                 "rewound", "left_at", "ring", "ring_i", "band_lo", "band_hi", "hold_ns", "max_gap_ns",
                 "max_jump_ns")

    def __init__(self, name: str, counts: StreamCounts, max_gap_ns: int, max_jump_ns: int) -> None:
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
        self.max_gap_ns = max_gap_ns
        self.max_jump_ns = max_jump_ns
        known = int(counts.interval_ns)
        self.ring = [known] * RING
        self.ring_i = 0
        self.band_lo, self.band_hi = 0, -1
        self.hold_ns = max_gap_ns
        if known:
            self.set_band(known)

    def set_band(self, ref: int) -> None:
        """A new reference interval ``ref``: the band of intervals that keep it, and ``hold_ns``."""
        self.band_lo = ref - ref // 4
        self.band_hi = ref + ref // 4
        self.hold_ns = min(max(self.max_gap_ns, 3 * ref), self.max_jump_ns)

    def interval(self, dt: int) -> None:
        """An interval outside the reference band: recompute the reference (lower median of
        the recent intervals, this one included) and count messages missing before this one."""
        recent = sorted(x for x in self.ring if x > 0)
        ref = recent[(len(recent) - 1) // 2]
        counts = self.counts
        counts.interval_ns = float(ref)
        if dt > 1.5 * ref:
            counts.missing += int(round(dt / ref)) - 1
        self.set_band(ref)


def drop_front(stamps: list[int], values: list[Values], broken: list[int], cut: int) -> None:
    """Drop the ``cut`` oldest messages of a buffer, and the holes before what remains."""
    del stamps[:cut]
    del values[:cut]
    if broken:
        first = stamps[0] if stamps else None
        while broken and (first is None or broken[0] < first):
            del broken[0]


def expire(stream: Stream, stamps: list[int], values: list[Values], broken: list[int], newest: int,
           buffer_ns: int, max_buffered: int) -> None:
    """Drop messages more than ``buffer_ns`` older than the newest (another stream holds the
    grid back), keeping the one just before the cut (it may still bracket a later sample),
    and beyond ``max_buffered`` (then an eighth more, so a flood costs O(1) per message).
    They are counted as expired, never used."""
    cut = bisect_left(stamps, newest - buffer_ns) - 1
    over = len(stamps) - max_buffered
    if over > 0:
        cut = max(cut, over + max_buffered // 8)
    if cut > 0:
        drop_front(stamps, values, broken, cut)
        stream.counts.expired += cut
