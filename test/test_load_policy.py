"""Why inputs are late or missing, and the degradation ladder, on synthetic timing series (no ROS)."""

from __future__ import annotations

import random

from test_diagnostics import NOW, counters, snapshot, statuses, stream

from rls_uncertainty.datapath.diagnostics import WARN, DiagnosticsPolicy, Snapshot
from rls_uncertainty.datapath.load_policy import (
    CLOCKS,
    FACTOR,
    NODE,
    TRANSPORT,
    LoadPolicy,
    Timing,
    behind,
    blame,
    cause,
    clock_text,
    keep_up_text,
)

MS = 1e-3


def jitter(n, mean, spread, seed=1):
    rng = random.Random(seed)
    return [mean + rng.uniform(-spread, spread) for _ in range(n)]


# ------------------------------------------------------------------ the cause
def test_processing_slower_than_the_period_is_the_node_even_before_a_queue_shows():
    t = Timing(period_s=1 * MS, cpu_per_sample_s=jitter(200, 1.6 * MS, 0.3 * MS), waits_s=jitter(200, 2 * MS, 1 * MS))
    assert behind(t) and cause(t) == NODE
    fast = Timing(period_s=1 * MS, cpu_per_sample_s=jitter(200, 0.4 * MS, 0.3 * MS), waits_s=t.waits_s)
    assert not behind(fast)


def test_a_growing_queue_is_the_node_a_single_stall_is_not():
    period = 10 * MS
    growing = [2 * MS + i * 1 * MS for i in range(90)]  # 2 ms ... 91 ms, the median under the backlog threshold
    assert sorted(growing)[45] < max(0.05, 5 * period)
    assert cause(Timing(period, jitter(50, 1 * MS, 0.1 * MS), growing, stamp_gaps=30)) == NODE
    stall = jitter(90, 2 * MS, 1 * MS)
    stall[45] = 0.4  # one 400 ms pause: the queue drained after it
    assert not behind(Timing(period, jitter(50, 1 * MS, 0.1 * MS), stall))
    backlog = jitter(90, 120 * MS, 5 * MS)  # a standing backlog over max(50 ms, 5 periods)
    assert behind(Timing(period, (), backlog))


def test_stamp_gaps_while_the_node_keeps_up_are_transport():
    t = Timing(5 * MS, jitter(100, 1 * MS, 0.2 * MS), jitter(100, 2 * MS, 1 * MS), stamp_gaps=12)
    assert cause(t) == TRANSPORT
    assert cause(Timing(5 * MS, t.cpu_per_sample_s, t.waits_s)) is None


def test_a_constant_stamp_offset_between_streams_is_clocks_a_drifting_one_is_not():
    now = {"imu": 0.002, "air_data": 3.502}  # air data's clock 3.5 s behind the IMU's
    before = {"imu": 0.001, "air_data": 3.503}
    quiet = jitter(100, 1 * MS, 0.2 * MS)
    assert cause(Timing(5 * MS, quiet, quiet, 4, now, before, clock_tolerance_s=2.0)) == CLOCKS
    drifting = {"imu": 0.001, "air_data": 1.5}  # the spread moved 2 s in a period: not a clock
    assert cause(Timing(5 * MS, quiet, quiet, 4, now, drifting, clock_tolerance_s=2.0)) == TRANSPORT
    close = {"imu": 0.002, "air_data": 0.8}
    assert cause(Timing(5 * MS, quiet, quiet, 0, close, close, clock_tolerance_s=2.0)) is None
    slow = Timing(5 * MS, jitter(100, 9 * MS, 1 * MS), quiet, 4, now, before, clock_tolerance_s=2.0)
    assert cause(slow) == NODE  # the node's own slowness comes first


def test_blame_names_the_node_only_when_it_is_the_cause():
    gaps = "imu missing about 40 in the last 10 s (stamp gaps: lost in transport?)"
    clocks = "samples: none formed ...: the needed streams' stamps never overlap (different clocks?)"
    for why in (None, TRANSPORT, CLOCKS):
        assert blame(clocks, why) == clocks
    for why in (None, TRANSPORT):
        assert blame(gaps, why) == gaps
    assert "transport" not in blame(gaps, CLOCKS) and "different clocks" in blame(gaps, CLOCKS)
    assert "transport" not in blame(gaps, NODE) and "behind" in blame(gaps, NODE)
    assert "clocks" not in blame(clocks, NODE) and "cannot keep up" in blame(clocks, NODE)


def test_with_the_clocks_measured_the_hint_becomes_the_measured_offset():
    offsets = {"imu": 0.002, "airspeed": 3.502, "thrust": 0.012}  # air data's clock 3.5 s behind
    said = clock_text(offsets)
    assert said == "different clocks: airspeed stamps 3.5 s behind imu's, against their arrival"
    clocks = "samples: none formed ...: the needed streams' stamps never overlap (different clocks?)"
    assert blame(clocks, CLOCKS, said) == clocks.replace("different clocks?", said)
    for why in (None, TRANSPORT):  # a guess stays a guess unless the clocks were measured
        assert blame(clocks, why, said) == clocks


def test_the_keep_up_text_has_the_p99_wait_the_median_cpu_and_the_period():
    waits = [i * MS for i in range(1, 201)]  # p99 = the element at index 198: 199 ms
    cpu = [2.5 * MS] * 3 + [0.1 * MS] * 2  # median 2.5 ms
    assert keep_up_text(Timing(1 * MS, cpu, waits)) == (
        "cannot keep up: 199 ms behind, 2.5 ms per sample against a period of 1.0 ms")


# ------------------------------------------------------------------ the ladder
def test_the_ladder_spaces_frequency_evaluations_out_first_then_covariances_and_comes_back():
    rate, every, dec = 1000.0, 1, 10
    p = LoadPolicy(rate, every, dec, recover_s=10.0)
    expected_every = [every]
    while expected_every[-1] < rate:
        expected_every.append(min(int(rate), expected_every[-1] * FACTOR))
    expected_dec = [dec]
    while expected_dec[-1] < rate:
        expected_dec.append(min(int(rate), expected_dec[-1] * FACTOR))
    seen = []
    for _ in range(len(expected_every) + len(expected_dec) + 3):  # a few periods past the end of the ladder
        lines = p.update(True, 1.0)
        assert len(lines) <= 1
        seen.append((p.frequency_every, p.covariance_decimation))
    assert [e for e, d in seen if d == dec] == expected_every[1:]  # every first, decimation untouched
    assert sorted({d for e, d in seen}) == expected_dec and seen[-1] == (int(rate), int(rate))
    assert p.update(True, 1.0) == [] and p.degraded  # at the bound: nothing more to shed, nothing said
    assert p.text() == "degraded: frequency.every 1 -> 1000, outputs.covariance_decimation 10 -> 1000"
    # Catching up: one step back per recover_s of keeping up, decimation first.
    said = []
    for _ in range(400):
        said += p.update(False, 1.0)
        if not p.degraded:
            break
    assert not p.degraded and (p.frequency_every, p.covariance_decimation) == (every, dec) and p.text() == ""
    assert all(line.startswith("restored: ") for line in said)
    assert said[0].startswith("restored: outputs.covariance_decimation") and said[-1].startswith(
        "restored: frequency.every")


def test_a_relapse_restarts_the_recovery_clock_and_nothing_is_shed_without_the_options():
    p = LoadPolicy(100.0, 5, 0, recover_s=10.0)
    assert p.update(True, 1.0) == ["degraded: frequency.every 5 -> 25 (cannot keep up)"]
    assert p.update(False, 9.0) == []
    assert p.update(True, 1.0) == ["degraded: frequency.every 25 -> 100 (cannot keep up)"]
    assert p.update(True, 1.0) == []  # one per second reached; no covariances published: nothing else
    assert p.update(False, 9.0) == [] and p.update(False, 1.0) == ["restored: frequency.every 100 -> 20 (kept up "
                                                                   "for 10 s)"]
    none = LoadPolicy(50.0, 0, 0)
    assert none.update(True, 1.0) == [] and not none.degraded


# ------------------------------------------------------------------ in /diagnostics
def _behind_snapshot(c, **extra):
    base = snapshot(c, cpu=[0.004] * 10)
    return Snapshot(**{**base.__dict__, "waits_s": [0.3 + 0.01 * i for i in range(100)], "period_s": 0.02,
                       "frequency_every": 1, "shed": True, **extra})


def test_a_node_behind_blames_itself_not_the_transport_and_says_its_step():
    c = counters({"imu": stream(received=100, missing=40, newest=NOW)}, formed=100, used=60)
    policy = DiagnosticsPolicy()
    late = dict.fromkeys(c["streams"], 0.01) | {"airspeed": 4.5}  # air data not taken for 4.5 s
    out = statuses(_behind_snapshot(c, arrival_ages_s=late), policy)
    assert policy.cause == NODE
    assert "lost in transport" not in out["inputs"].message and "dropped while the node was behind" in \
        out["inputs"].message
    assert "airspeed not taken for 4.5 s (the node is behind its inputs)" in out["inputs"].message
    assert "stale" not in out["inputs"].message
    s = out["samples"]
    assert s.level == WARN and s.message.startswith("cannot keep up: 1290 ms behind")
    assert "degraded: frequency.every 1 -> 5" in s.message and dict(s.values)["load.frequency_every"] == "5"
    assert policy.load is not None and policy.load.said == ["degraded: frequency.every 1 -> 5 (cannot keep up)"]
    quiet = DiagnosticsPolicy()
    out = statuses(Snapshot(**{**snapshot(c).__dict__, "waits_s": [0.001] * 50, "period_s": 0.02,
                               "frequency_every": 1, "shed": True}), quiet)
    assert quiet.cause == TRANSPORT and "lost in transport?" in out["inputs"].message
    out = statuses(Snapshot(**{**snapshot(c).__dict__, "waits_s": [0.001] * 50, "period_s": 0.02,
                               "arrival_ages_s": late}), DiagnosticsPolicy())
    assert "airspeed stale (4.5 s)" in out["inputs"].message
    assert "degraded" not in out["samples"].message and quiet.load is not None and quiet.load.said == []


def test_a_node_that_does_not_shed_says_it_is_behind_and_keeps_its_settings():
    policy = DiagnosticsPolicy()
    for _ in range(3):
        out = statuses(_behind_snapshot(counters(formed=100, used=100), shed=False), policy)
    assert out["samples"].message.startswith("cannot keep up: ") and "degraded" not in out["samples"].message
    assert policy.load is not None and not policy.load.degraded and policy.load.said == []
    assert dict(out["samples"].values)["load.frequency_every"] == "1"


# ------------------------------------------------------------------ a full input queue
def test_a_full_input_queue_is_the_node_whatever_its_cpu_and_waits_say():
    # The middleware drops the oldest messages of a full queue before the node takes them: the
    # node took too seldom, though the messages it did take were fed quickly.
    quiet = jitter(100, 1 * MS, 0.2 * MS)
    full = Timing(20 * MS, quiet, quiet, stamp_gaps=300, queues_full={"imu": 3, "airspeed": 0}, queue_depth=1000)
    assert behind(full) and cause(full) == NODE
    assert cause(Timing(20 * MS, quiet, quiet, stamp_gaps=300, queues_full={"imu": 0})) == TRANSPORT
    text = keep_up_text(full)
    assert text.startswith("cannot keep up: ") and "against a period of 20.0 ms" in text
    assert text.endswith("; input queue full (qos.depth 1000, the oldest dropped): imu 3 times")
    assert keep_up_text(Timing(20 * MS, (), [0.8])) == (
        "cannot keep up: 800 ms behind, no sample processed against a period of 20.0 ms")


def test_gaps_from_a_full_queue_are_said_to_be_the_nodes_not_the_transports():
    c = counters({"imu": stream(received=100, missing=40, newest=NOW, expired=7)}, formed=100, used=60)
    snap = Snapshot(**{**snapshot(c).__dict__, "waits_s": [0.001] * 50, "period_s": 0.02,
                       "queues_full": {"imu": 4}, "queue_depth": 1000})
    policy = DiagnosticsPolicy()
    out = statuses(snap, policy)
    msg = out["inputs"].message
    assert policy.cause == NODE and "transport" not in msg and "clocks" not in msg
    assert "imu missing about 40 in the last 10 s (dropped from the node's full input queue, qos.depth 1000: " \
           "the node is behind its inputs)" in msg
    assert "imu expired 7 in the last 10 s (buffered, never used: the node cannot keep up with its inputs)" in msg
    assert dict(out["inputs"].values)["imu.recent.queue_full"] == "4"
    assert out["samples"].message.startswith("cannot keep up: ") and "imu 4 times" in out["samples"].message
    # The same gaps without a full queue stay a question about the transport.
    out = statuses(Snapshot(**{**snap.__dict__, "queues_full": {}}), DiagnosticsPolicy())
    assert "lost in transport?" in out["inputs"].message and "another stream lagging" in out["inputs"].message
