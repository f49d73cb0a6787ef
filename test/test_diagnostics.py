"""The /diagnostics policy without DDS: levels, messages and key-values from hand-made
snapshots (and from a real pipeline's counters), checked against values worked out here."""

from __future__ import annotations

import random
import subprocess
import sys
from pathlib import Path

import pytest

from rls_uncertainty.datapath import diagnostics as dg
from rls_uncertainty.datapath.diagnostics import OK, WARN, DiagnosticsPolicy, Snapshot
from rls_uncertainty.datapath.inputs import STREAMS as INPUTS
from rls_uncertainty.datapath.outputs import NODE_NAME

SEC = 1_000_000_000
NOW = 1_700_000_000 * SEC
REQUIRED = ("imu", "airspeed", "control_surfaces", "dynamic_pressure", "thrust")
STREAM_KEYS = ("required", "publishers", "rate_hz", "age_s", "received", "accepted", "expired", "missing")


def stream(received=0, rejected=None, expired=0, missing=0, newest=NOW):
    rejected = dict(rejected or {})
    return {"received": received, "accepted": received - sum(rejected.values()), "rejected": rejected,
            "expired": expired, "missing": missing, "newest_stamp_ns": newest if received else None}


def counters(streams=None, formed=0, used=0, pending=0, samples_rejected=None, resets=None, unknown=None):
    all_streams = {k: stream(received=10) for k in INPUTS}
    all_streams.update(streams or {})
    return {"streams": all_streams, "samples_formed": formed, "samples_used": used,
            "samples_rejected": dict(samples_rejected or {}), "samples_pending": pending,
            "resets": dict(resets or {}), "unknown_joints": dict(unknown or {})}


def snapshot(c=None, *, models=(), required=REQUIRED, max_gap=0.25, now=NOW, elapsed=1.0, publishers=None,
             reliable=False, enabled=True, state="no state file", latencies=(), cpu=(), namesakes=0):
    return Snapshot(counters=c or counters(), models=list(models), required=required, max_gap=max_gap, now_ns=now,
                    elapsed_s=elapsed, publishers=dict.fromkeys(INPUTS, 1) | dict(publishers or {}),
                    topics={k: f"/{k}" for k in INPUTS}, reliable=reliable, enabled=enabled, state_file=state,
                    latencies_s=list(latencies), cpu_times_s=list(cpu), namesakes=namesakes)


def statuses(snap, policy=None):
    out = (policy or DiagnosticsPolicy()).update(snap)
    return {s.name.removeprefix(f"{NODE_NAME}: "): s for s in out}


def values(status):
    return dict(status.values)


# ------------------------------------------------------------------ structure
def test_levels_are_the_diagnostic_msgs_levels():
    from diagnostic_msgs.msg import DiagnosticStatus

    assert [dg.OK, dg.WARN, dg.ERROR, dg.STALE] == [
        int.from_bytes(v, "little") for v in (DiagnosticStatus.OK, DiagnosticStatus.WARN, DiagnosticStatus.ERROR,
                                             DiagnosticStatus.STALE)]


def test_the_module_imports_no_ros_package():
    code = ("import sys, rls_uncertainty.datapath.diagnostics; "
            "print(sorted(m for m in sys.modules if m.split('.')[0] in ('rclpy', 'diagnostic_msgs', 'rosbags')))")
    root = Path(__file__).resolve().parents[1]
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, cwd=root)
    assert out.stdout.strip() == "[]"


def test_statuses_are_inputs_samples_then_one_per_model_named_after_the_node():
    fit = {"ready": False, "samples": 0}
    out = DiagnosticsPolicy().update(snapshot(models=[("CZ", fit), ("Cm", fit)]))
    assert [s.name for s in out] == [f"{NODE_NAME}: {n}" for n in ("inputs", "samples", "model CZ", "model Cm")]
    assert {s.hardware_id for s in out} == {NODE_NAME}
    for s in out:  # every value is text, keys unique
        assert all(isinstance(k, str) and isinstance(v, str) for k, v in s.values)
        assert len({k for k, _ in s.values}) == len(s.values)


@pytest.mark.parametrize("node,prefix", [
    ("rls_estimator", "rls_estimator"), ("/rls_estimator", "rls_estimator"), ("/my_name", "my_name"),
    ("/ns/rls_estimator", "/ns/rls_estimator"), ("/a/b/rls_estimator", "/a/b/rls_estimator"),
])
def test_a_node_under_a_namespace_names_its_statuses_with_its_full_name(node, prefix):
    """The root namespace keeps the names consumers have always matched; two namespaced
    nodes never share a status name on /diagnostics."""
    assert dg.status_prefix(node) == prefix
    out = DiagnosticsPolicy(node).update(snapshot(models=[("CZ", {"ready": False, "samples": 0})]))
    assert [s.name for s in out] == [f"{prefix}: {n}" for n in ("inputs", "samples", "model CZ")]
    assert {s.hardware_id for s in out} == {prefix}


def test_another_node_with_the_full_name_is_an_error_and_a_throttled_warning():
    policy = DiagnosticsPolicy("/ns/rls_estimator")
    want = ("1 other node(s) named /ns/rls_estimator on the ROS graph: their outputs mix with this node's on "
            "/ns/rls_estimator/..., so every consumer receives each sample 2 times, and /ns/rls_estimator/reset and "
            "/ns/rls_estimator/enable reach any of them; start each node with its own name or namespace "
            "(--ros-args -r __node:=NAME or -r __ns:=/NAMESPACE)")
    logged = []
    for t in range(70):  # one period a second; the other node stays 60 s
        out = {s.name: s for s in policy.update(snapshot(c=counters(formed=10, used=10), namesakes=int(t < 60)))}
        samples = out["/ns/rls_estimator: samples"]
        logged.append(policy.alerts.due())
        if t < 60:
            assert (samples.level, samples.message) == (dg.ERROR, f"{want}; 10 of 10 samples used")
            assert values(samples)["nodes_with_this_name"] == "2"
        else:
            assert (samples.level, samples.message) == (OK, "10 of 10 samples used")
        assert out["/ns/rls_estimator: inputs"].level == OK  # the inputs are fine
    assert [t for t, lines in enumerate(logged) if lines] == [0, 30]  # once per repeat_s (30 s)
    assert logged[0] == [want]


def test_input_keys_per_stream_in_order_with_rejections_sorted():
    c = counters({"imu": stream(received=7, rejected={"out_of_order": 2, "duplicate": 1}, expired=1, missing=0,
                                newest=NOW - 20_000_000)})
    s = statuses(snapshot(c, elapsed=0.5))["inputs"]
    imu = [(k, v) for k, v in s.values if k.startswith("imu.")]
    assert imu == [("imu.required", "True"), ("imu.publishers", "1"), ("imu.rate_hz", "14.0"),
                   ("imu.age_s", "0.020"), ("imu.received", "7"), ("imu.accepted", "4"), ("imu.expired", "1"),
                   ("imu.missing", "0"), ("imu.recent.rejected", "3"), ("imu.recent.missing", "0"),
                   ("imu.recent.expired", "1"), ("imu.recent.queue_full", "0"),
                   ("imu.rejected.duplicate", "1"), ("imu.rejected.out_of_order", "2")]
    assert s.values[0] == ("recent_window_s", "10")
    # Streams in the counters' order, each block starting with its required flag.
    firsts = [k.split(".")[0] for k, _ in s.values if k.endswith(".required")]
    assert firsts == list(INPUTS)


def test_all_fresh_is_ok():
    s = statuses(snapshot())["inputs"]
    assert (s.level, s.message) == (OK, "all inputs fresh")


# ------------------------------------------------------------------ stale and silent streams
@pytest.mark.parametrize("max_gap,age_s,stale", [
    (0.25, 1.0, False), (0.25, 1.001, True),  # at least one second
    (2.0, 3.9, False), (2.0, 4.01, True),  # twice max_gap when that is longer
    (0.25, -0.5, False),  # stamps ahead of the node clock are not stale
])
def test_a_required_stream_older_than_the_limit_is_stale(max_gap, age_s, stale):
    assert dg.stale_after(max_gap) == max(1.0, 2 * max_gap)
    c = counters({"airspeed": stream(received=5, newest=NOW - round(age_s * SEC))})
    s = statuses(snapshot(c, max_gap=max_gap))["inputs"]
    assert values(s)["airspeed.age_s"] == f"{age_s:.3f}"
    if stale:
        assert (s.level, s.message) == (WARN, f"airspeed stale ({age_s:.1f} s)")
    else:
        assert (s.level, s.message) == (OK, "all inputs fresh")


@pytest.mark.parametrize("max_gap,arrived_s,stale", [(0.25, 1.0, False), (0.25, 1.001, True), (2.0, 4.01, True)])
def test_with_arrival_ages_a_stream_is_as_old_as_its_newest_arrival_whatever_its_stamps(max_gap, arrived_s, stale):
    """The node hands in when each stream's newest message arrived: a bag's stamps, a year
    behind the node's clock (a replay without /clock), do not make it stale; a stream that
    stopped arriving is stale after the same limit; one never heard from is silent."""
    year = 365 * 86400 * SEC
    c = counters({k: stream(received=5, newest=NOW - year) for k in ("imu", "airspeed")}
                 | {"control_surfaces": stream(received=0)})
    ages = {"imu": 0.02, "airspeed": arrived_s, "dynamic_pressure": 0.1, "thrust": 0.1}
    snap = snapshot(c, max_gap=max_gap, required=("imu", "airspeed", "control_surfaces"))
    s = statuses(Snapshot(**{**snap.__dict__, "arrival_ages_s": ages}))["inputs"]
    assert values(s)["imu.age_s"] == "0.020" and values(s)["airspeed.age_s"] == f"{arrived_s:.3f}"
    assert values(s)["control_surfaces.age_s"] == "never received"
    want = ([f"airspeed stale ({arrived_s:.1f} s)"] if stale else []) + ["control_surfaces silent"]
    assert (s.level, s.message) == (WARN, "; ".join(want))
    # Without arrival ages (the offline replay) the same stamps are a year old.
    s = statuses(snap)["inputs"]
    assert values(s)["imu.age_s"] == f"{year / SEC:.3f}" and s.message.startswith("imu stale (")


def test_a_silent_required_stream_warns_and_hints_when_no_publisher_matched():
    c = counters({"imu": stream(received=0)})
    s = statuses(snapshot(c, publishers={"imu": 1}))["inputs"]
    assert (s.level, s.message) == (WARN, "imu silent")
    assert values(s)["imu.age_s"] == "never received"
    for reliable in (False, True):
        s = statuses(snapshot(c, publishers={"imu": 0}, reliable=reliable))["inputs"]
        assert s.message == ("imu silent; no publisher matched on /imu (none running, or incompatible QoS: "
                             f"qos.reliable={reliable})")
        assert values(s)["imu.publishers"] == "0"


def test_optional_streams_may_be_silent():
    c = counters({"thrust": stream(received=0), "dynamic_pressure": stream(received=3, newest=NOW - 60 * SEC)})
    s = statuses(snapshot(c, required=("imu", "airspeed", "control_surfaces"), publishers={"thrust": 0}))["inputs"]
    assert (s.level, s.message) == (OK, "all inputs fresh")
    assert values(s)["thrust.required"] == "False" and values(s)["dynamic_pressure.age_s"] == "60.000"


# ------------------------------------------------------------------ rejected and missing
def test_rejected_and_missing_messages_warn_with_totals_in_stream_order():
    c = counters({"imu": stream(received=30, rejected={"non_finite": 2, "malformed: error": 1}),
                  "airspeed": stream(received=9, missing=4),
                  "control_surfaces": stream(received=8, rejected={"mismatched_arrays": 1})})
    s = statuses(snapshot(c))["inputs"]
    assert s.level == WARN
    assert s.message == ("imu rejected 3 in the last 10 s; airspeed missing about 4 in the last 10 s (stamp gaps: "
                         "lost in transport?); control_surfaces rejected 1 in the last 10 s")
    v = values(s)
    assert (v["imu.rejected.malformed: error"], v["imu.rejected.non_finite"], v["imu.accepted"]) == ("1", "2", "27")
    assert v["airspeed.missing"] == "4"


def test_problems_of_one_stream_are_listed_together():
    c = counters({"airspeed": stream(received=4, rejected={"duplicate": 1}, missing=2, newest=NOW - 5 * SEC)})
    s = statuses(snapshot(c, publishers={"airspeed": 0}))["inputs"]
    assert s.message == ("airspeed stale (5.0 s); no publisher matched on /airspeed (none running, or incompatible "
                         "QoS: qos.reliable=False); airspeed rejected 1 in the last 10 s; airspeed missing about 2 in "
                         "the last 10 s (stamp gaps: lost in transport?)")


# ------------------------------------------------------------------ rates
def test_rates_are_received_differences_over_the_elapsed_period():
    policy = DiagnosticsPolicy()
    received = [(0, 1.0), (200, 1.0), (700, 2.5), (700, 0.2), (703, 0.0)]
    want = ["0.0", "200.0", "200.0", "0.0", "3000000000.0"]  # a zero period is taken as 1 ns
    got = []
    for (n, elapsed) in received:
        s = statuses(snapshot(counters({"imu": stream(received=n)}), elapsed=elapsed), policy)["inputs"]
        got.append(values(s)["imu.rate_hz"])
    assert got == want
    assert policy.previous.counters["streams"]["imu"]["received"] == 703


def test_the_first_period_counts_from_zero():
    s = statuses(snapshot(counters({"imu": stream(received=123)}), elapsed=2.0))["inputs"]
    assert values(s)["imu.rate_hz"] == "61.5"


# ------------------------------------------------------------------ samples, latency
def test_sample_keys_in_order_and_sorted_reasons():
    c = counters(formed=120, used=100, pending=4, samples_rejected={"gap_airspeed": 15, "differentiator_warmup": 5},
                 resets={"service": 1, "parameters_changed": 2}, unknown={"flap": 3, "canard": 1})
    s = statuses(snapshot(c, state="resumed from /tmp/s.npz (5 samples)"))["samples"]
    assert (s.level, s.message) == (OK, "100 of 120 samples used")
    assert s.values == (("enabled", "True"), ("samples_formed", "120"), ("samples_used", "100"),
                        ("samples_pending", "4"), ("samples_rejected.differentiator_warmup", "5"),
                        ("samples_rejected.gap_airspeed", "15"), ("resets.parameters_changed", "2"),
                        ("resets.service", "1"), ("unknown_joint.canard", "1"), ("unknown_joint.flap", "3"),
                        ("state_file", "resumed from /tmp/s.npz (5 samples)"), ("nodes_with_this_name", "1"))


def test_disabled_estimation_is_said_and_stays_ok():
    s = statuses(snapshot(counters(formed=10, used=0), enabled=False))["samples"]
    assert (s.level, s.message, values(s)["enabled"]) == (OK, "0 of 10 samples used; estimation disabled", "False")


def test_latency_percentiles_are_observed_values():
    lat = [i * 1e-3 for i in range(1, 101)]  # 1 ... 100 ms
    cpu = [i * 1e-4 for i in range(1, 101)]
    random.Random(0).shuffle(lat)
    random.Random(1).shuffle(cpu)
    v = values(statuses(snapshot(latencies=lat, cpu=cpu))["samples"])
    # p50 is the 51st smallest of 100 (index 50), p99 the 100th (index 99).
    assert (v["latency_ms.p50"], v["latency_ms.p99"], v["latency_ms.max"]) == ("51.000", "100.000", "100.000")
    assert (v["processing_cpu_ms.p50"], v["processing_cpu_ms.p99"]) == ("5.100", "10.000")
    keys = [k for k, _ in statuses(snapshot(latencies=lat, cpu=cpu))["samples"].values]
    assert keys[-7:] == ["latency_ms.p50", "latency_ms.p99", "latency_ms.max", "processing_cpu_ms.p50",
                         "processing_cpu_ms.p99", "state_file", "nodes_with_this_name"]


@pytest.mark.parametrize("lat,p50,p99", [
    ([0.002], 0.002, 0.002),
    ([0.003, 0.001, 0.002], 0.002, 0.003),  # indices 1 and min(2, int(2.97)) = 2
    ([0.001] * 99 + [0.5], 0.001, 0.5),  # 100 values: p99 is index 99, the outlier
    ([0.001] * 100 + [0.5], 0.001, 0.001),  # 101 values: index int(99.99) = 99; max shows it
])
def test_percentiles_are_the_element_at_index_q_n(lat, p50, p99):
    assert (dg.percentile(sorted(lat), 0.5), dg.percentile(sorted(lat), 0.99)) == (p50, p99)
    v = values(statuses(snapshot(latencies=lat, cpu=lat))["samples"])
    assert (v["latency_ms.p50"], v["latency_ms.p99"], v["latency_ms.max"]) == (
        f"{1e3 * p50:.3f}", f"{1e3 * p99:.3f}", f"{1e3 * max(lat):.3f}")


def test_no_latency_keys_in_a_period_without_outputs():
    keys = {k for k, _ in statuses(snapshot())["samples"].values}
    assert not {k for k in keys if k.startswith(("latency_ms", "processing_cpu_ms"))}
    with pytest.raises(ValueError):
        dg.percentile([], 0.5)


# ------------------------------------------------------------------ models
FIT = {"ready": True, "samples": 512, "r_squared": 0.91234, "residual_rho1": 0.1234, "lags_outside_2sigma": 0.04,
       "repairs": 0}


def test_a_ready_model_reports_its_fit():
    s = statuses(snapshot(counters(used=512), models=[("CZ", FIT)]))["model CZ"]
    assert (s.level, s.message) == (OK, "R^2 0.912, residual lag-1 correlation 0.12")
    assert s.values == (("ready", "True"), ("samples", "512"), ("r_squared", "0.91234"), ("residual_rho1", "0.1234"),
                        ("lags_outside_2sigma", "0.04"), ("repairs", "0"))


def test_an_initializing_model_is_ok_before_any_sample_is_used_and_warns_after():
    fit = {"ready": False, "samples": 0}
    s = statuses(snapshot(counters(formed=3, used=0), models=[("Cm", fit)]))["model Cm"]
    assert (s.level, s.message) == (OK, "initializing: regressors not yet informative")
    assert s.values == (("ready", "False"), ("samples", "0"))
    s = statuses(snapshot(counters(formed=50, used=40), models=[("Cm", {"ready": False, "samples": 40})]))["model Cm"]
    assert (s.level, s.message) == (WARN, "initializing: regressors not yet informative")


# ------------------------------------------------------------------ malformed messages
def test_malformed_reason_and_warning_name_topic_type_and_text():
    exc = ValueError("sensor_msgs/msg/Imu: malformed 7-byte payload: too short")
    assert dg.malformed_reason(exc) == "malformed: ValueError"
    text = dg.malformed_warning("/imu", exc)
    assert text.startswith("malformed message on /imu: ValueError: sensor_msgs/msg/Imu: malformed 7-byte payload")
    assert "rejected.malformed: ValueError" in text


# ------------------------------------------------------------------ with a real pipeline
def test_statuses_from_a_real_pipeline():
    from rls_uncertainty.datapath.pipeline import Pipeline
    from rls_uncertainty.settings import load_parameters_file, pipeline_config

    config = pipeline_config(load_parameters_file("t2"))
    p = Pipeline(config)
    t0 = 100 * SEC
    for i in range(5):
        p.add_imu(t0 + i * 5_000_000, (0.0, 0.01, 0.0), (0.0, 0.0, 9.8))
    p.add_imu(t0 + 25_000_000, (float("nan"), 0.0, 0.0), (0.0, 0.0, 9.8))  # rejected, but its stamp is the newest
    p.add_imu(t0 + 25_000_000, (0.0, 0.0, 0.0), (0.0, 0.0, 9.8))  # the newest stamp again
    snap = snapshot(p.counters(), models=[(m.output, p.model_fit(j)) for j, m in enumerate(config.models)],
                    required=tuple(p.required), now=t0 + 25_000_000, elapsed=0.5)
    out = statuses(snap)
    v = values(out["inputs"])
    assert (v["imu.received"], v["imu.accepted"], v["imu.rejected.non_finite"]) == ("7", "5", "1")
    assert v["imu.rejected.duplicate"] == "1" and v["imu.rate_hz"] == "14.0" and v["imu.age_s"] == "0.000"
    assert v["airspeed.age_s"] == "never received"
    assert out["inputs"].level == WARN
    assert out["inputs"].message.startswith("imu rejected 2 in the last 10 s; airspeed silent")
    assert out["samples"].message == "0 of 0 samples used"
    assert [n for n in out if n.startswith("model")] == [f"model {m.output}" for m in config.models]
    assert all(s.level == OK for n, s in out.items() if n.startswith("model"))


# ------------------------------------------------------------------ levels from a recent window
def _run(policy, periods, *, elapsed=1.0):
    """Feed one snapshot per entry of ``periods`` (each a counters dict) of a pipeline that
    uses a sample every period (no data-path alert); the inputs statuses."""
    used = policy.previous.counters["samples_used"] if policy.previous else 0
    return [statuses(snapshot({**c, "samples_formed": used + i + 1, "samples_used": used + i + 1}, elapsed=elapsed),
                     policy)["inputs"] for i, c in enumerate(periods)]


def test_one_dropped_packet_warns_for_the_window_then_clears_with_the_cumulative_count_kept():
    """A long flight: one IMU packet lost at the start; WARN for exactly the window (10
    periods of 1 s), OK for the rest of the hour, and imu.missing keeps saying 1."""
    policy = DiagnosticsPolicy(window_s=10.0)
    clean = counters({"imu": stream(received=100)})
    dropped = counters({"imu": stream(received=100, missing=1)})
    out = _run(policy, [clean] + [dropped] * 3600)
    levels = [s.level for s in out]
    assert levels[0] == OK
    assert levels[1:11] == [WARN] * 10  # the drop happened in period 1; baselines t <= now - 10 s
    assert set(levels[11:]) == {OK}
    assert out[5].message == "imu missing about 1 in the last 10 s (stamp gaps: lost in transport?)"
    end = values(out[-1])
    assert (end["imu.missing"], end["imu.recent.missing"], out[-1].message) == ("1", "0", "all inputs fresh")
    assert len(policy._window._history) <= 12  # the window's snapshots, not the flight's


def test_rejections_and_expiries_in_the_window_warn_and_are_counted_beside_the_totals():
    policy = DiagnosticsPolicy(window_s=3.0)
    seq = [counters({"imu": stream(received=10 * (i + 1), rejected={"out_of_order": r}, expired=e)})
           for i, (r, e) in enumerate([(0, 0), (2, 0), (2, 0), (2, 0), (2, 0), (5, 4), (5, 4), (5, 4), (5, 4), (5, 4)])]
    out = _run(policy, seq)
    recent = [(values(s)["imu.recent.rejected"], values(s)["imu.recent.expired"]) for s in out]
    assert recent == [("0", "0"), ("2", "0"), ("2", "0"), ("2", "0"), ("0", "0"), ("3", "4"), ("3", "4"),
                      ("3", "4"), ("0", "0"), ("0", "0")]
    assert [s.level for s in out] == [OK, WARN, WARN, WARN, OK, WARN, WARN, WARN, OK, OK]
    assert out[5].message == ("imu rejected 3 in the last 3 s; imu expired 4 in the last 3 s (buffered, never used: "
                              "another stream lagging, or a reset)")
    assert values(out[-1])["imu.rejected.out_of_order"] == "5" and values(out[-1])["imu.expired"] == "4"


def test_the_window_follows_the_steady_time_of_irregular_periods():
    policy = DiagnosticsPolicy(window_s=10.0)
    _run(policy, [counters({"airspeed": stream(received=5, rejected={"duplicate": 1})})], elapsed=0.5)
    # 9 s later: still inside the window; 10.5 s after the rejection: the baseline holds it.
    s = _run(policy, [counters({"airspeed": stream(received=9, rejected={"duplicate": 1})})], elapsed=9.0)[0]
    assert s.level == WARN and values(s)["airspeed.recent.rejected"] == "1"
    s = _run(policy, [counters({"airspeed": stream(received=9, rejected={"duplicate": 1})})], elapsed=1.5)[0]
    assert s.level == OK and values(s)["airspeed.recent.rejected"] == "0"


def test_a_counter_that_restarted_counts_from_zero():
    policy = DiagnosticsPolicy(window_s=100.0)
    _run(policy, [counters({"imu": stream(received=50, missing=7)})])
    s = _run(policy, [counters({"imu": stream(received=3, missing=2)})])[0]
    assert values(s)["imu.recent.missing"] == "2"


def test_stale_streams_warn_whatever_the_window():
    policy = DiagnosticsPolicy(window_s=0.5)
    c = counters({"airspeed": stream(received=5, newest=NOW - 3 * SEC)})
    assert [s.level for s in _run(policy, [c] * 5)] == [WARN] * 5


@pytest.mark.parametrize("bad", [dict(window_s=0.0), dict(window_s=-1.0), dict(max_keys=0)])
def test_policy_settings_are_checked(bad):
    with pytest.raises(ValueError):
        DiagnosticsPolicy(**bad)


# ------------------------------------------------------------------ bounded size
def _size(status):
    return len(status.name) + len(status.message) + sum(len(k) + len(v) for k, v in status.values)


def test_every_status_stays_bounded_whatever_arrives():
    """10 000 unknown joints with 10 kB names, 500 rejection reasons on every stream, 300
    sample-rejection and reset reasons: each table shows MAX_KEYS entries (the largest
    counts) and the rest as two overflow keys; each status stays a few kB."""
    joints = {f"joint_{i:05d}_" + "x" * 10_000: 1 + i % 7 for i in range(10_000)}
    reasons = {f"malformed: Error{i}": 1 + i for i in range(500)}
    c = counters({k: stream(received=10_000, rejected=reasons) for k in INPUTS},
                 samples_rejected={f"reason_{i}": i + 1 for i in range(300)}, resets={f"r{i}": 1 for i in range(300)},
                 unknown=joints)
    out = statuses(snapshot(c, state="x" * 100_000))
    inputs, samples = out["inputs"], out["samples"]
    assert len(inputs.values) <= 1 + len(INPUTS) * (14 + dg.MAX_KEYS)
    assert len(samples.values) <= 13 + 3 * (2 + dg.MAX_KEYS)
    assert _size(inputs) < 20_000 and _size(samples) < 10_000
    for s in (inputs, samples):
        assert len({k for k, _ in s.values}) == len(s.values)  # keys unique
    v = values(inputs)
    shown = [k for k in v if k.startswith("imu.rejected.")]
    assert len(shown) == dg.MAX_KEYS
    assert sorted(int(v[k]) for k in shown) == list(range(485, 501))  # the largest counts
    assert v["imu.rejected_other_reasons"] == "484"
    assert int(v["imu.rejected_other_count"]) == sum(range(1, 485))
    assert "imu rejected " + str(sum(reasons.values())) in inputs.message  # the total, not the shown part
    w = values(samples)
    assert w["unknown_joint_other_names"] == str(10_000 - dg.MAX_KEYS)
    assert int(w["unknown_joint_other_count"]) + sum(int(w[k]) for k in w if k.startswith("unknown_joint.")) == \
        sum(joints.values())
    assert all(len(k) <= len("unknown_joint.") + dg.MAX_NAME for k in w if k.startswith("unknown_joint."))
    assert len(w["state_file"]) == dg.MAX_VALUE and w["state_file"].endswith("...")


def test_tables_within_the_limit_are_shown_whole_and_sorted():
    c = counters(unknown={"flap": 3, "canard": 1})
    kv = statuses(snapshot(c))["samples"].values
    assert [k for k, _ in kv if "joint" in k] == ["unknown_joint.canard", "unknown_joint.flap"]


def test_names_are_printable_short_and_unique():
    long_a, long_b = "a" * 100 + "1", "a" * 100 + "2"
    c = counters(unknown={long_a: 1, long_b: 1, "tab\there": 1, "tab\nhere": 1, "ok_name": 1})
    keys = [k for k, _ in statuses(snapshot(c))["samples"].values if k.startswith("unknown_joint.")]
    assert len(set(keys)) == 5 and "unknown_joint.ok_name" in keys
    assert all(k.isprintable() and len(k) <= len("unknown_joint.") + dg.MAX_NAME for k in keys)


# ------------------------------------------------------------------ convergence in the model status
@pytest.mark.parametrize("conv,suffix", [
    ({"converged": True, "converged_parameters": "CZ_0,CZ_alpha"}, "; converged"),
    ({"converged": False, "converged_parameters": "CZ_0"}, "; converged: CZ_0"),
    ({"converged": False, "converged_parameters": ""}, "; not converged"),
    ({}, ""),
])
def test_a_ready_model_says_which_parameters_converged(conv, suffix):
    s = statuses(snapshot(counters(used=512), models=[("CZ", {**FIT, **conv})]))["model CZ"]
    assert (s.level, s.message) == (OK, "R^2 0.912, residual lag-1 correlation 0.12" + suffix)
    assert dict(s.values).get("converged_parameters") == conv.get("converged_parameters")


# ------------------------------------------------------------------ the node's round in steps
def test_periodic_step_maximum_is_reported():
    v = values(statuses(snapshot())["samples"])
    assert "periodic_ms.max" not in v
    snap = Snapshot(**{**snapshot().__dict__, "periodic_s": [0.0004, 0.0021, 0.0009]})
    assert values(statuses(snap)["samples"])["periodic_ms.max"] == "2.100"


def test_the_node_reports_the_sample_topics_it_publishes_on_only_when_it_knows_them():
    """``outputs_subscribed`` as the node writes it is read back as written; the offline replay
    (no count) leaves it out, which reads as not reported."""
    snap = Snapshot(**{**snapshot().__dict__, "outputs_subscribed": 9})
    samples = statuses(snap)["samples"].values
    assert ("outputs_subscribed", "9") in samples and dg.outputs_subscribed(samples) == 9
    assert dg.outputs_discovered(samples, 9, 9) and not dg.outputs_discovered(samples, 9, 10)
    offline = statuses(snapshot())["samples"].values
    assert dg.OUTPUTS_SUBSCRIBED not in dict(offline) and dg.outputs_subscribed(offline) == -1
    assert not dg.outputs_discovered(offline, 9, 9)


@pytest.mark.parametrize(("value", "count"), [("5", 5), ("0", 0), ("12", 12), (None, -1), ("x", -1), ("-1", -1),
                                              ("-3", -1), ("", -1), ("2.5", -1), ("5 topics", -1)])
@pytest.mark.parametrize("as_pairs", [False, True])
@pytest.mark.parametrize(("matched", "subscriptions"), [(5, 5), (4, 5), (0, 0), (11, 11)])
def test_outputs_are_discovered_when_both_ends_matched_and_never_on_a_missing_or_garbled_count(
        value, count, as_pairs, matched, subscriptions):
    """Hand-made ``samples`` key-values (a mapping, or pairs as a DiagnosticStatus holds them):
    the count read back (-1 when missing or not a count), and discovered only when every
    subscription here matched and the node publishes on at least as many sample topics."""
    kv = {"enabled": "True", "samples_used": "3"} | ({} if value is None else {"outputs_subscribed": value})
    values = list(kv.items()) if as_pairs else kv
    assert dg.outputs_subscribed(values) == count
    want = matched == subscriptions and count >= 0 and count >= subscriptions
    assert dg.outputs_discovered(values, matched, subscriptions) is want


def _fed_pipeline(n_messages):
    from rls_uncertainty.datapath.inputs import feed
    from rls_uncertainty.datapath.pipeline import Pipeline
    from rls_uncertainty.offline.bags import read_inputs
    from rls_uncertainty.settings import load_parameters_file, pipeline_config

    root = Path(__file__).resolve().parents[1]
    messages, _ = read_inputs(root / "bags" / "t2_maneuver")
    pipe = Pipeline(pipeline_config(load_parameters_file("t2")))
    for kind, _stamp, msg in messages[:n_messages]:
        feed(pipe, kind, msg)
    return pipe


@pytest.mark.parametrize("n_messages", [0, 900, 4000])
def test_a_round_in_steps_reports_what_the_one_shot_report_does(n_messages):
    """The node's DiagnosticsRound, stepped one part at a time, publishes the statuses and the
    fit arrays that Snapshot + DiagnosticsPolicy.update and OutputLayout.encode_fit give for
    the same pipeline state (before the first sample, while initializing, converged), and
    the policy's window advances the same way over successive rounds."""
    from rls_uncertainty.datapath.diagnostics_round import DiagnosticsRound
    from rls_uncertainty.datapath.outputs import OutputLayout

    pipe = _fed_pipeline(n_messages)
    layout = OutputLayout.of(pipe)
    facts = {k: v for k, v in snapshot(latencies=[0.002, 0.001], cpu=[0.001, 0.001]).__dict__.items()
             if k not in ("counters", "models")}
    one_shot, stepped = DiagnosticsPolicy(), DiagnosticsPolicy()
    for _period in range(3):
        want = one_shot.update(Snapshot(counters=pipe.counters(), models=[
            (m.output, pipe.model_report(j)) for j, m in enumerate(pipe.config.models)], **facts))
        fits, published = [], []
        r = DiagnosticsRound(pipe, layout, stepped, facts, lambda i, raw, fits=fits: fits.append((i, raw)),
                             published.append)
        steps = 1
        while not r.step():
            steps += 1
            assert not published
        assert steps == 2 * len(pipe.config.models) + 2 and r.done and r.step()
        assert published == [want]
        assert fits == layout.encode_fit(pipe)
        ready = [j for j in range(len(pipe.config.models)) if pipe.model_fit(j)["ready"]]
        assert sorted({i // 2 for i, _raw in fits}) == ready  # two fit arrays per model whose fit is ready


def test_a_node_behind_its_inputs_says_so_first_and_names_what_to_change():
    """The intake waits of the period (how long each pass's oldest message waited) against the
    estimator period: a backlog (median wait over max(50 ms, 5 periods)) is WARN, the text first,
    with the p99 wait, the median CPU per sample and the period; a single stall is not."""
    base = snapshot(counters(formed=100, used=100), cpu=[0.004] * 9 + [0.2])
    period = 0.02  # 50 Hz

    def samples(waits):
        snap = Snapshot(**{**base.__dict__, "waits_s": waits, "period_s": period})
        policy = DiagnosticsPolicy()
        return statuses(snap, policy)["samples"], policy

    behind = [0.3 + 0.01 * i for i in range(100)]  # 300 ... 1290 ms
    s, policy = samples(behind)
    want = "cannot keep up: 1290 ms behind, 4.0 ms per sample against a period of 20.0 ms"
    assert s.level == WARN and s.message.startswith(want) and "rate" in s.message
    assert policy.overload == s.message.split("; 100 of")[0]
    assert values(s)["intake_wait_ms.p99"] == "1290.000"
    stall = [0.001] * 99 + [2.0]  # one long pass: not behind
    s, policy = samples(stall)
    assert (s.level, policy.overload) == (OK, None) and s.message == "100 of 100 samples used"
    assert values(s)["intake_wait_ms.p99"] == "2000.000"
    s, policy = samples([0.101] * 10)  # the threshold is max(50 ms, 5 periods) = 100 ms
    assert s.level == WARN
    s, policy = samples([0.099] * 10)
    assert s.level == OK
