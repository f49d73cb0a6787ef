"""Stream buffers, the sample grid and message accounting (rls_uncertainty.datapath.sampling), against
independent computations: numpy's interpolation on random stamps, grids and counts worked
out by hand. Generic streams: nothing here knows about aircraft."""

import math
import os

import numpy as np
import pytest
from interleaving import interleave as interleave_queues

from rls_uncertainty.datapath.bookkeeping import StreamCounts
from rls_uncertainty.datapath.sampling import Restart, Sample, Sampler, Skipped

MS = 1_000_000
P = 20 * MS  # 50 Hz grid


def sampler(required=("a", "b"), names=("a", "b", "c"), max_gap=250 * MS, buffer=2000 * MS, counts=None, **kw):
    return Sampler(names, required, period_ns=P, max_gap_ns=max_gap, buffer_ns=buffer, counts=counts, **kw)


def feed(smp, events):
    """``(stamp, name, values)`` in the given order (``values`` None: a message the caller
    rejected as ``invalid``); returns every grid item, in order."""
    out = []
    for stamp, name, values in events:
        if values is None:
            due = smp.reject_invalid(smp.streams[name], stamp, "invalid")
        else:
            due = smp.add(smp.streams[name], stamp, tuple(values), all(math.isfinite(v) for v in values))
        if due:
            out += smp.due()
    return out


def merged(*streams):
    """Events of several ``(name, stamps, values)`` streams in stamp order (stable by stream)."""
    events = [
        (int(t), rank, name, v)
        for rank, (name, stamps, values) in enumerate(streams)
        for t, v in zip(stamps, values, strict=True)
    ]
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
    events += [(30 * MS, "a", (0.0, 0.0))]  # duplicate of the newest stamp
    events += [(15 * MS, "a", (0.0, 0.0)), (25 * MS, "a", (0.0, 0.0))]  # 2 out of order
    events += [(40 * MS, "a", (math.nan, 0.0)), (41 * MS, "a", (0.0, math.inf))]  # 2 non-finite
    events += [(41 * MS, "a", (0.0, 0.0))]  # the stamp of a non-finite message: a duplicate too
    events += [(50 * MS, "a", (0.0, 1.0))]
    feed(smp, events)
    smp.reject(a, "mismatched_arrays")
    smp.reject(a, "mismatched_arrays")
    counts = smp.counts["a"]
    assert counts.received == 12
    assert counts.rejected == {"non_finite": 2, "duplicate": 2, "out_of_order": 2, "mismatched_arrays": 2}
    assert counts.accepted == 4
    assert a.stamps == [10 * MS, 20 * MS, 30 * MS, 50 * MS]
    assert counts.newest_ns == 50 * MS
    # The non-finite messages arrived: they are not missing (intervals 10, 10, 10, 1, 9 ms).
    assert counts.report() == {
        "received": 12, "accepted": 4, "rejected": dict(counts.rejected), "expired": 0, "missing": 0,
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


# ----------------------------------------------------------------------------- timelines
S = 1_000_000_000
T0 = 1_767_225_600 * S  # stamps near 2026-01-01, like the bundled bag


def recording(rng, start, seconds, offset=0.0):
    """Three streams of one run: a (5 ms, required), b (about 17 ms jittered, required),
    c (9 ms, not required); values differ per run (``offset``) so a mix-up shows."""
    end = start + int(seconds * S)
    t_a = np.arange(start, end, 5 * MS)
    t_b, _ = random_stream(rng, start, end, 17 * MS, 1)
    t_c = np.arange(start + 2 * MS, end, 9 * MS)
    return [("a", t_a, rng.standard_normal((t_a.size, 3)) + offset),
            ("b", t_b, rng.standard_normal((t_b.size, 1)) + offset),
            ("c", t_c, rng.standard_normal((t_c.size, 2)) + offset)]


def per_stream(run):
    return {name: [(int(t), name, tuple(v)) for t, v in zip(stamps, values, strict=True)]
            for name, stamps, values in run}


def interleave(rng, *runs, weighted=False):
    """The streams of consecutive runs, each stream in its own order (run after run), the
    streams randomly interleaved: uniformly among the streams with messages left (slow
    streams race ahead, as in a node that takes one message per topic per round) or weighted
    by the messages left. Returns the events and, per event, the run it belongs to."""
    queues = {}
    for r, run in enumerate(runs):
        for name, events in per_stream(run).items():
            queues.setdefault(name, []).extend((e, r) for e in events)
    return interleave_queues(rng, queues, weighted)


def split_at_restarts(items):
    parts, current = [], []
    for item in items:
        if type(item) is Restart:
            parts.append(current)
            current = []
        else:
            current.append(item)
    return [*parts, current]


@pytest.mark.parametrize("seed,weighted", [(1, False), (2, True), (3, False), (4, True)])
def test_a_looped_recording_restarts_cleanly_whatever_the_interleaving(seed, weighted):
    """Two consecutive runs with the same stamps (a looped replay), streams randomly
    interleaved: the sampler returns exactly what fresh samplers return for each run alone
    (fed in the same order), separated by one Restart."""
    rng = np.random.default_rng(seed)
    run1 = recording(rng, T0, 3.0)
    run2 = recording(rng, T0, 3.0, offset=10.0)  # the same stamps again, other values
    events = interleave(rng, run1, run2, weighted=weighted)
    kw = dict(buffer=10 * S, max_jump_ns=S)
    looped = feed(sampler(**kw), [e for e, _r in events])
    fresh = [feed(sampler(**kw), [e for e, r in events if r == run]) for run in (0, 1)]
    assert split_at_restarts(looped) == fresh
    assert looped.count(Restart("stamps_jumped_backwards")) == 1
    assert len(fresh[0]) > 100 and len(fresh[1]) > 100


def test_a_looped_recording_with_the_default_buffer_and_small_lags():
    rng = np.random.default_rng(11)
    runs = [recording(rng, T0, 6.0, offset=k) for k in range(3)]  # looped twice, longer than max_stamp_jump
    events = interleave(rng, *runs, weighted=True)
    looped = feed(sampler(), [e for e, _r in events])
    fresh = [feed(sampler(), [e for e, r in events if r == run]) for run in range(3)]
    assert split_at_restarts(looped) == fresh
    smp = sampler()
    feed(smp, [e for e, _r in events])
    # Every message of the required streams was used for its run; c (not required) may have
    # had messages of a run arrive after a and b closed it: stragglers, counted as such.
    assert not smp.counts["a"].rejected and not smp.counts["b"].rejected
    assert set(smp.counts["c"].rejected) <= {"previous_timeline"}


def test_stragglers_of_the_previous_run_are_rejected_and_cannot_wipe_the_new_one():
    """Run 1 goes on while a required stream still brings its data; once every sample of it
    is formed, late messages of run 1 (b's beyond the end of a's run 1; c is not required)
    are stragglers: counted as previous_timeline, and run 2 is the fresh run."""
    rng = np.random.default_rng(5)
    run1, run2 = recording(rng, T0, 3.0), recording(rng, T0, 3.0, offset=5.0)
    s1, s2 = per_stream(run1), per_stream(run2)
    a_end = s1["a"][-1][0]
    b_tail = [e for e in s1["b"] if e[0] > a_end - 30 * MS]  # b's last messages, around a's end
    c_tail = s1["c"][-20:]
    head = sorted([e for e in s1["a"] + s1["b"] + s1["c"] if e not in b_tail and e not in c_tail], key=lambda e: e[0])
    a2 = s2["a"][:50]  # a restarts first (confirmed after 6 messages): the next timeline opens
    rest2 = sorted(s2["a"][50:] + s2["b"] + s2["c"], key=lambda e: e[0])
    smp = sampler(max_jump_ns=S)
    order = head + a2 + b_tail + c_tail + rest2
    out = feed(smp, order)
    parts = split_at_restarts(out)
    assert len(parts) == 2
    assert parts[0] == feed(sampler(max_jump_ns=S), head + b_tail + c_tail)
    assert parts[1] == feed(sampler(max_jump_ns=S), a2 + rest2)
    # b's first message at or after the last grid point of run 1 completed it; its later ones
    # (past a's last stamp, no sample could use them) and all of c's tail are stragglers.
    last_point = a_end // P * P
    used_b = [e for e in b_tail if e[0] <= last_point] + [next(e for e in b_tail if e[0] >= last_point)]
    assert smp.counts["b"].rejected == {"previous_timeline": len(b_tail) - len(set(used_b))}
    assert smp.counts["c"].rejected == {"previous_timeline": 20}
    assert not smp.counts["a"].rejected


def test_a_single_stamp_years_ahead_or_zero_changes_nothing():
    rng = np.random.default_rng(6)
    events = merged(*recording(rng, T0, 2.0))
    want = feed(sampler(), events)
    i = len(events) // 2
    for bad in (T0 + 3 * 365 * 86400 * S, 0, T0 - 600 * S, T0 + 20 * S):
        smp = sampler()
        out = feed(smp, [*events[:i], (bad, "a", (7.0, 7.0, 7.0)), *events[i:]])
        assert out == want, bad
        assert smp.counts["a"].rejected == {"stamp_jump": 1}
        assert smp.counts["a"].newest_ns == events[-1][0] if events[-1][1] == "a" else True
    # A stream whose first message is stamped 0 (its clock was not set yet), the others running.
    smp = sampler()
    first_b = next(k for k, e in enumerate(events) if e[1] == "b")
    out = feed(smp, [*events[:first_b], (0, "b", (7.0,)), *events[first_b:]])
    assert out == want and smp.counts["b"].rejected == {"stamp_jump": 1}


def test_every_stream_starting_at_stamp_zero_is_one_forward_restart_not_1e10_skipped_points():
    rng = np.random.default_rng(7)
    events = merged(*recording(rng, T0, 2.0))
    zeros = [(0, "a", (0.0, 0.0, 0.0)), (0, "b", (0.0,)), (0, "c", (0.0, 0.0))]
    smp = sampler()
    out = feed(smp, zeros + events)
    # One sample at stamp 0 (all streams had a message there), then the real timeline, exactly
    # as a fresh sampler forms it; no grid point in between is counted.
    assert out[0] == Sample(0, [(0.0, 0.0, 0.0), (0.0,)])
    assert out[1] == Restart("stamps_jumped_forward")
    assert out[2:] == feed(sampler(), events)
    assert not any(type(x) is Skipped for x in out)


def test_a_burst_of_bad_stamps_shorter_than_the_confirmation_is_rejected():
    rng = np.random.default_rng(8)
    events = merged(*recording(rng, T0, 2.0))
    want = feed(sampler(confirm=5), events)
    i = len(events) // 2
    burst = [(T0 + 3600 * S + k * 5 * MS, "a", (1.0, 1.0, 1.0)) for k in range(5)]  # candidate + 4
    smp = sampler(confirm=5)
    assert feed(smp, events[:i] + burst + events[i:]) == want
    assert smp.counts["a"].rejected == {"stamp_jump": 5}


def test_dropouts_are_gaps_and_only_a_jump_beyond_max_stamp_jump_restarts():
    def streams(start, seconds):
        end = start + int(seconds * S)
        return [("a", np.arange(start, end, 5 * MS), None), ("b", np.arange(start + MS, end, 10 * MS), None)]

    def events_of(*parts):
        ev = []
        for part in parts:
            ev += merged(*[(n, t, np.zeros((t.size, 1))) for n, t, _ in part])
        return ev

    # Every stream silent for 3 s (< max_stamp_jump): a gap, counted honestly.
    smp = sampler(max_jump_ns=5 * S)
    out = feed(smp, events_of(streams(T0, 1.0), streams(T0 + 4 * S, 1.0)))
    skipped = [x for x in out if type(x) is Skipped]
    # Last messages 0.995 s (a) and 0.991 s (b); next 4.000 s and 4.001 s. a is checked first:
    # grid points 1.000 ... 3.980 s lie in a's gap (150); at 4.000 s a has a message, b's
    # neighbours are 0.991 and 4.001 s (1 point); from 4.020 s on samples are formed.
    assert skipped == [Skipped(T0 + 1000 * MS, 150, "gap_a"), Skipped(T0 + 4000 * MS, 1, "gap_b")]
    assert [x.stamp_ns for x in out if type(x) is Sample][49] == T0 + 4020 * MS
    assert smp.counts["a"].missing == round(3005 / 5) - 1 and smp.counts["b"].missing == round(3010 / 10) - 1
    assert not smp.counts["a"].rejected and not smp.counts["b"].rejected
    assert Restart("stamps_jumped_forward") not in out
    # Silent for 10 s: a restart, and no grid point of the silence is counted.
    smp = sampler(max_jump_ns=5 * S)
    out = feed(smp, events_of(streams(T0, 1.0), streams(T0 + 11 * S, 1.0)))
    assert Restart("stamps_jumped_forward") in out
    assert not any(type(x) is Skipped for x in out)
    # One stream silent for 10 s while the other goes on: a gap of that stream, no restart.
    smp = sampler(max_jump_ns=5 * S, buffer=20 * S)
    ev = events_of([("a", np.arange(T0, T0 + 12 * S, 5 * MS), None), ("b", np.arange(T0 + MS, T0 + S, 10 * MS), None)],
                   [("b", np.arange(T0 + 11 * S + MS, T0 + 12 * S, 10 * MS), None)])
    ev.sort(key=lambda e: e[0])
    out = feed(smp, ev)
    assert [x for x in out if type(x) is Skipped] == [Skipped(T0 + S, len(range(1000, 11001, 20)), "gap_b")]
    assert not any(type(x) is Restart for x in out) and not smp.counts["b"].rejected


def test_a_message_far_from_the_clock_is_rejected():
    smp = sampler(required=("a",), max_clock_ns=60 * S)
    smp.clock_ns = T0
    out = feed(smp, [(T0 - 61 * S, "a", (1.0,)), (T0 + 61 * S, "a", (1.0,)), (0, "a", (1.0,))]
               + [(T0 + k * 10 * MS, "a", (float(k),)) for k in range(5)])
    assert smp.counts["a"].rejected == {"far_from_clock": 3}
    assert [x.stamp_ns for x in out] == [T0, T0 + 20 * MS, T0 + 40 * MS]
    smp.clock_ns = None  # no clock (the offline replay): nothing is checked
    feed(smp, [(T0 + 200 * S, "a", (1.0,))])
    assert smp.counts["a"].rejected == {"far_from_clock": 3, }
    assert smp.streams["a"].held  # held as a jump candidate, not rejected for the clock


def test_a_clock_jump_back_restarts_a_loop_shorter_than_max_stamp_jump():
    """A 2 s replay looped under /clock: its stamps step back by 2 s only, which alone would
    be out of order. After time_jumped the step back near the new clock time is the new run;
    messages of run 1 arriving after the clock jump still complete run 1."""
    rng = np.random.default_rng(9)
    run1, run2 = recording(rng, T0, 2.0), recording(rng, T0, 2.0, offset=3.0)
    e1 = sorted([e for s in per_stream(run1).values() for e in s], key=lambda e: e[0])
    e2 = sorted([e for s in per_stream(run2).values() for e in s], key=lambda e: e[0])
    smp = sampler(max_jump_ns=5 * S)
    k = len(e1) - 40
    out = feed(smp, e1[:k])
    assert smp.time_jumped(T0, T0 + 2 * S)
    out += feed(smp, e1[k:] + e2)  # 40 messages of run 1 were still queued
    parts = split_at_restarts(out)
    assert parts == [feed(sampler(), e1), feed(sampler(), e2)]
    assert out.count(Restart("time_jumped_backwards")) == 1
    assert all(not c.rejected for c in smp.counts.values())
    # The stamps already restarted by themselves before the clock jump arrived: nothing to do.
    smp = sampler(max_jump_ns=S)
    feed(smp, e1 + e2[:150])  # run 2 restarted by its stamps alone, 0.4 s into it
    assert not smp.time_jumped(T0, T0 + 2 * S)


def test_clear_forgets_every_input_state():
    smp = sampler(max_jump_ns=S)
    rng = np.random.default_rng(10)
    run = merged(*recording(rng, T0, 1.0))
    feed(smp, [*run, (T0 - 3 * S, "a", (0.0, 0.0, 0.0))])  # ends with a held jump candidate
    assert smp.streams["a"].held
    received = {n: c.received for n, c in smp.counts.items()}
    smp.clear(forget_newest=True)
    assert smp.buffered() == 0 and smp.next_ns is None
    assert all(c.newest_ns is None for c in smp.counts.values())
    # Older stamps are accepted again, exactly as by a fresh sampler.
    older = merged(*recording(rng, T0 - 10 * S, 1.0))
    assert feed(smp, older) == feed(sampler(max_jump_ns=S), older)
    for n, c in smp.counts.items():
        assert c.received == received[n] + sum(e[1] == n for e in older)
        assert c.accepted + sum(c.rejected.values()) == c.received


# ----------------------------------------------------------------------------- invalid holes
def test_no_sample_is_interpolated_across_an_invalid_message():
    smp = sampler(required=("a", "b"))
    a = [(t * MS, "a", (float(t),)) for t in range(0, 400, 5)]
    b = [(t * MS, "b", (float(t),)) for t in range(3, 400, 10)]
    events = sorted(a + b, key=lambda e: e[0])
    bad = next(i for i, e in enumerate(events) if e[0] == 153 * MS and e[1] == "b")
    events[bad] = (153 * MS, "b", None)  # b's message at 153 ms: values rejected
    out = feed(smp, events)
    # b's valid neighbours are 143 and 163 ms: the grid point between them (160 ms) is not
    # formed; 140 and 180 ms are (bracketed by valid messages on both sides).
    assert Skipped(160 * MS, 1, "invalid_b") in out
    formed = [x.stamp_ns for x in out if type(x) is Sample]
    assert formed == [t * MS for t in range(20, 400, 20) if t != 160 and t <= 393]
    assert smp.counts["b"].rejected == {"invalid": 1} and smp.counts["b"].missing == 0
    # A hole on a grid point with a valid message exactly there: that one is still used.
    smp = sampler(required=("a",))
    out = feed(smp, [(0, "a", (0.0,)), (10 * MS, "a", None), (20 * MS, "a", (2.0,)), (30 * MS, "a", (3.0,)),
                     (40 * MS, "a", (4.0,))])
    assert out == [Sample(0, [(0.0,)]), Sample(20 * MS, [(2.0,)]), Sample(40 * MS, [(4.0,)])]
    # Two holes in a row and a non-finite one: the grid points from the last valid message
    # before them (45 ms) to the first after (105 ms) are skipped together.
    smp = sampler(required=("a",))
    holes = [(55 * MS, "a", None), (65 * MS, "a", None), (75 * MS, "a", (math.nan,)), (85 * MS, "a", None),
             (95 * MS, "a", None)]
    valid = [(t * MS, "a", (1.0,)) for t in (5, 15, 25, 35, 45, 105, 115)]
    out = feed(smp, valid[:5] + holes + valid[5:])
    assert [x for x in out if type(x) is Skipped] == [Skipped(60 * MS, 3, "invalid_a")]
    assert smp.counts["a"].rejected == {"invalid": 4, "non_finite": 1}


# ----------------------------------------------------------------------------- intervals, memory
def _stamps(*segments):
    """Consecutive segments ``(count, interval_ms)`` of a stream's stamps."""
    out, t = [], T0
    for n, step in segments:
        for _ in range(n):
            t += step * MS
            out.append(t)
    return out


@pytest.mark.parametrize("before,after", [(5, 10), (10, 5), (5, 20)])
def test_missing_counts_follow_a_change_of_rate(before, after):
    smp = sampler(required=("a",))
    feed(smp, [(t, "a", (0.0,)) for t in _stamps((1000, before), (1000, after))])
    c = smp.counts["a"]
    # A slower rate is miscounted as losses for at most 4 intervals (the median's memory),
    # then the reference follows: not 999 of every 1000 messages.
    slower = after > before
    assert (0 < c.missing <= 4 * (after // before - 1)) if slower else c.missing == 0
    assert c.interval_ns == after * MS
    # A real dropout at the new rate is counted in full: 7 messages lost.
    missing = c.missing
    feed(smp, [(t, "a", (0.0,)) for t in [T0 + 1000 * (before + after) * MS + 8 * after * MS]])
    assert c.missing == missing + 7


def _rss_bytes() -> int:
    with open("/proc/self/statm") as fh:
        return int(fh.read().split()[1]) * os.sysconf("SC_PAGE_SIZE")


def test_a_flood_on_one_stream_while_another_stalls_keeps_memory_bounded():
    bound = 2000
    smp = sampler(max_buffered=bound, buffer=60 * S)
    a = smp.streams["a"]
    feed(smp, [(T0, "b", (0.0,))])  # b stalls: the grid waits for it, a's buffer would grow
    values = (1.0, 2.0, 3.0)
    n = 1_000_000
    longest = 0
    for k in range(100_000):
        smp.add(a, T0 + k, values)
        longest = max(longest, len(a.stamps))
    before = _rss_bytes()
    for k in range(100_000, n):  # a million messages 1 ns apart (all within buffer_duration)
        smp.add(a, T0 + k, values)
        if len(a.stamps) > longest:
            longest = len(a.stamps)
    grown = _rss_bytes() - before
    assert longest == bound
    assert smp.counts["a"].expired + len(a.stamps) == n and smp.counts["a"].received == n
    # Unbounded, the 900k later messages would hold about 130 MB (150 bytes each).
    assert grown < 10_000_000, grown


def test_a_confirmed_burst_of_bad_stamps_costs_a_restart_not_the_stream():
    """Six messages of a required stream an hour ahead (the candidate and 5 confirmations) are
    taken as a jump; when the stream and the others go on with the real stamps, the data
    returns to them: samples resume, nothing is wedged."""
    rng = np.random.default_rng(12)
    events = merged(*recording(rng, T0, 20.0))
    i = next(k for k, e in enumerate(events) if e[0] > T0 + 3 * S)
    burst = [(T0 + 3600 * S + k * 5 * MS, "a", (1.0, 1.0, 1.0)) for k in range(6)]
    smp = sampler(confirm=5, max_jump_ns=5 * S)
    out = feed(smp, events[:i] + burst + events[i:])
    parts = split_at_restarts(out)
    want = feed(sampler(), events)
    late = [x for x in parts[-1] if type(x) is Sample]
    # The last run of samples is the clean one's from some point on, and that point is
    # within about max_stamp_jump of the burst (the others' stamps re-confirm the timeline).
    assert late and late[-1] == want[-1]
    assert late[0].stamp_ns < T0 + 3 * S + 5 * S + 2 * S
    assert late == [x for x in want if type(x) is Sample and x.stamp_ns >= late[0].stamp_ns]
    for c in smp.counts.values():
        assert set(c.rejected) <= {"previous_timeline", "stamp_jump", "out_of_order"}
