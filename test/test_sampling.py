"""Stream buffers, the sample grid and message accounting (rls_uncertainty.sampling), against
independent computations: numpy's interpolation on random stamps, grids and counts worked
out by hand. Generic streams: nothing here knows about aircraft."""

import math

import numpy as np
import pytest

from rls_uncertainty.sampling import Sample, Sampler, Skipped, StreamCounts

MS = 1_000_000
P = 20 * MS  # 50 Hz grid


def sampler(required=("a", "b"), names=("a", "b", "c"), max_gap=250 * MS, buffer=2000 * MS, counts=None):
    return Sampler(names, required, period_ns=P, max_gap_ns=max_gap, buffer_ns=buffer, counts=counts)


def feed(smp, events):
    """``(stamp, name, values)`` in the given order; returns every grid item, in order."""
    out = []
    for stamp, name, values in events:
        finite = all(math.isfinite(v) for v in values)
        if smp.add(smp.streams[name], stamp, tuple(values), finite):
            out += smp.due()
    return out


def merged(*streams):
    """Events of several ``(name, stamps, values)`` streams in stamp order (stable by stream)."""
    events = [(int(t), rank, name, v) for rank, (name, stamps, values) in enumerate(streams) for t, v in zip(stamps, values)]
    events.sort(key=lambda e: (e[0], e[1]))
    return [(t, name, v) for t, _rank, name, v in events]


def random_stream(rng, start, end, mean_step, width):
    steps = rng.integers(mean_step // 2, 3 * mean_step // 2, size=int((end - start) / mean_step) + 2)
    stamps = start + np.cumsum(steps)
    stamps = stamps[stamps <= end]
    return stamps, rng.standard_normal((stamps.size, width))


def test_samples_equal_numpy_interpolation_on_random_stamps():
    rng = np.random.default_rng(7)
    start = 10**12 + 3  # not on the grid
    t_a, v_a = random_stream(rng, start, start + 3000 * MS, 5 * MS, 3)
    t_b, v_b = random_stream(rng, start, start + 3000 * MS, 17 * MS, 1)
    t_c, v_c = random_stream(rng, start, start + 1000 * MS, 9 * MS, 2)  # not required
    smp = sampler()
    out = feed(smp, merged(("a", t_a, v_a), ("b", t_b, v_b), ("c", t_c, v_c)))
    assert all(type(item) is Sample for item in out)
    # The grid: every multiple of P from the first point both streams cover to the last one.
    first, last = max(t_a[0], t_b[0]), min(t_a[-1], t_b[-1])
    grid = np.arange(-(-first // P) * P, last + 1, P)
    assert [item.stamp_ns for item in out] == grid.tolist()
    a = np.array([item.values[0] for item in out])
    b = np.array([item.values[1] for item in out])
    for i in range(3):
        np.testing.assert_allclose(a[:, i], np.interp(grid, t_a, v_a[:, i]), rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(b[:, 0], np.interp(grid, t_b, v_b[:, 0]), rtol=1e-12, atol=1e-15)
    c = smp.counts
    assert c["a"].received == c["a"].accepted == t_a.size
    assert c["c"].received == t_c.size


def test_a_message_on_a_grid_point_is_taken_as_it_is():
    smp = sampler(required=("a",))
    out = feed(smp, [(0, "a", (1.0,)), (P, "a", (2.5,)), (P + 1, "a", (9.0,))])
    assert out == [Sample(0, [(1.0,)]), Sample(P, [(2.5,)])]


def test_the_grid_is_multiples_of_the_period_whatever_the_first_stamp():
    for offset in (1, 7 * MS, P - 1):
        smp = sampler(required=("a",))
        stamps = [5 * P + offset + k * 3 * MS for k in range(40)]
        out = feed(smp, [(t, "a", (float(t),)) for t in stamps])
        assert [s.stamp_ns for s in out] == list(range(6 * P, stamps[-1] + 1, P))
        # A linear signal is reproduced exactly by linear interpolation.
        assert all(s.values[0][0] == pytest.approx(s.stamp_ns, abs=1e-3) for s in out)


def test_samples_wait_for_every_required_stream_and_are_never_extrapolated():
    smp = sampler()
    events = [(k * 5 * MS, "a", (1.0,)) for k in range(200)]  # a: 0 ... 995 ms
    events += [(k * 10 * MS, "b", (2.0,)) for k in range(31)]  # b: 0 ... 300 ms, then silent
    events.sort(key=lambda e: e[0])
    out = feed(smp, events)
    assert [s.stamp_ns for s in out] == list(range(0, 300 * MS + 1, P))
    assert smp.next_ns == 320 * MS
    # b comes back: the grid points in between are formed now, not before.
    out = feed(smp, [(400 * MS, "b", (4.0,))])
    assert [s.stamp_ns for s in out] == list(range(320 * MS, 400 * MS + 1, P))
    assert out[0].values[1][0] == pytest.approx(2.0 + 2.0 * 20 / 100)


def test_a_silent_stream_skips_the_grid_points_of_its_gap():
    smp = sampler(max_gap=50 * MS)
    events = [(k * 5 * MS, "a", (0.0,)) for k in range(400)]
    b = [0, 10, 20, 30, 40, 183, 190]  # ms: a gap of 143 ms after 40 ms
    events += [(t * MS, "b", (0.0,)) for t in b]
    events.sort(key=lambda e: e[0])
    out = feed(smp, events)
    # Grid points 60 ... 180 ms lie in the gap (hand-counted: 60, 80, ..., 180 = 7 points).
    skipped = [item for item in out if type(item) is Skipped]
    assert skipped == [Skipped(60 * MS, 7, "gap_b")]
    assert [s.stamp_ns for s in out if type(s) is Sample] == [0, 20 * MS, 40 * MS]
    # 183 and 190 ms bracket no grid point: the next one, 200 ms, waits for b.
    assert smp.next_ns == 200 * MS


def test_a_stream_running_ahead_expires_its_oldest_messages():
    smp = sampler(buffer=100 * MS)
    out = feed(smp, [(0, "b", (0.0,))] + [(k * 5 * MS, "a", (0.0,)) for k in range(101)])  # a: 0 ... 500 ms
    assert [s.stamp_ns for s in out] == [0]  # b has not reached 20 ms
    a = smp.streams["a"]
    # Kept: the messages within 100 ms of the newest (400 ... 500 ms) and the one before them.
    assert a.stamps == [k * 5 * MS for k in range(79, 101)]
    # Received 101: every one before 395 ms expired (the one at 0 ms formed the 0 ms sample
    # but was still the last one at or before the next grid point, so it stayed buffered).
    assert smp.counts["a"].expired == 101 - len(a.stamps) == 79
    # b resumes at 500 ms. The grid points whose a-message before them has expired are
    # skipped together up to a's oldest remaining one (20 ... 380 ms: 19 points); then b's
    # own silence (0 ... 500 ms, longer than max_gap) skips 400 ... 480 ms (5 points).
    out = feed(smp, [(500 * MS, "b", (0.0,))])
    assert out == [Skipped(20 * MS, 19, "expired_a"), Skipped(400 * MS, 5, "gap_b"), Sample(500 * MS, [(0.0,), (0.0,)])]


def test_every_message_is_accepted_or_rejected_with_its_reason():
    smp = sampler()
    a = smp.streams["a"]
    events = [(t * MS, "a", (0.0, 1.0)) for t in (10, 20, 30)]
    events += [(40 * MS, "a", (math.nan, 0.0)), (41 * MS, "a", (0.0, math.inf))]  # 2 non-finite
    events += [(30 * MS, "a", (0.0, 0.0))]  # duplicate of the newest stamp
    events += [(15 * MS, "a", (0.0, 0.0)), (25 * MS, "a", (0.0, 0.0))]  # 2 out of order
    events += [(50 * MS, "a", (0.0, 1.0))]
    feed(smp, events)
    smp.reject(a, "mismatched_arrays")
    smp.reject(a, "mismatched_arrays")
    counts = smp.counts["a"]
    assert counts.received == 11
    assert counts.rejected == {"non_finite": 2, "duplicate": 1, "out_of_order": 2, "mismatched_arrays": 2}
    assert counts.accepted == 4
    assert a.stamps == [10 * MS, 20 * MS, 30 * MS, 50 * MS]
    assert counts.newest_ns == 50 * MS
    assert counts.report() == {
        "received": 11, "accepted": 4, "rejected": dict(counts.rejected), "expired": 0, "missing": 1,
        "newest_stamp_ns": 50 * MS,
    }


def test_messages_lost_in_transport_are_counted_from_stamp_gaps():
    smp = sampler(required=("a",))
    rng = np.random.default_rng(3)
    lost = {120, 121, 122, 300, 555}  # of a 10 ms stream with 1% stamp jitter
    stamps = [k * 10 * MS + int(rng.integers(-MS // 10, MS // 10)) for k in range(1000) if k not in lost]
    feed(smp, [(t, "a", (0.0,)) for t in stamps])
    assert smp.counts["a"].missing == len(lost)
    assert smp.counts["a"].interval_ns == pytest.approx(10 * MS, rel=0.01)


def test_clear_counts_the_buffers_as_expired_and_restarts_the_grid():
    smp = sampler(required=("a",))
    feed(smp, [(t * MS, "a", (0.0,)) for t in range(0, 105, 5)])
    buffered = smp.buffered()
    assert buffered > 0
    smp.clear(forget_newest=False)
    assert smp.counts["a"].expired == buffered and smp.buffered() == 0 and smp.next_ns is None
    feed(smp, [(50 * MS, "a", (0.0,))])  # older than the newest accepted stamp
    assert smp.counts["a"].rejected == {"out_of_order": 1}
    smp.clear(forget_newest=True)  # time jumped back: older stamps are accepted again
    out = feed(smp, [(t * MS, "a", (1.0,)) for t in (50, 60, 70)])
    assert [s.stamp_ns for s in out] == [60 * MS]
    assert smp.counts["a"].accepted == 21 + 3


def test_a_new_sampler_continues_the_counts_it_is_given():
    counts = {"a": StreamCounts(received=5, expired=2, newest_ns=100 * MS, interval_ns=float(10 * MS))}
    smp = sampler(required=("a",), names=("a", "b"), counts=counts)
    assert smp.counts["a"] is counts["a"]
    feed(smp, [(90 * MS, "a", (0.0,)), (110 * MS, "a", (0.0,))])
    assert counts["a"].received == 7 and counts["a"].rejected == {"out_of_order": 1}
    assert smp.counts["b"].received == 0


def test_required_streams_must_be_known():
    with pytest.raises(ValueError, match="required"):
        sampler(required=("a", "z"))
    with pytest.raises(ValueError, match="required"):
        sampler(required=())
