"""Maneuvers cut from one stream (rls_uncertainty.datapath.maneuvers): the estimator restarts at a
test point's start, its end is recorded; replay's maneuvers.csv, campaign RECORDING and the node's
way of feeding the pipeline give the same rows; bad events are counted, never acted on."""

import csv
import io
import math
from pathlib import Path

import numpy as np
import pytest

from rls_uncertainty import cli
from rls_uncertainty.datapath.inputs import feed
from rls_uncertainty.datapath.maneuver_detector import ManeuverDetector
from rls_uncertainty.datapath.maneuvers import (
    MANEUVER_COLUMNS,
    ManeuverSettings,
    ManeuverTracker,
    tracker_for,
)
from rls_uncertainty.datapath.pipeline import Pipeline
from rls_uncertainty.offline.bags import read_inputs, typestore
from rls_uncertainty.offline.replay import run_pipeline
from rls_uncertainty.settings.parameters import pipeline_config
from rls_uncertainty.settings.yaml_files import load

ROOT = Path(__file__).resolve().parents[1]
BAG = ROOT / "bags" / "t2_maneuver"
CONFIG = ROOT / "config" / "t2.yaml"
T0 = 1767225600000000000  # the bundled bag's first log time
S = 1_000_000_000
# Two test points of the bundled 12 s maneuver, and garbage between them.
EVENTS = [
    (int(0.5 * S), "pA", "start"),
    (int(1.0 * S), "pA", "start"),  # start twice
    (int(2.0 * S), "", "start"),  # empty name
    (int(2.5 * S), "p\x07", "start"),  # unprintable name
    (int(3.0 * S), "pA", "pause"),  # unknown value
    (int(4.0 * S), "pB", "stop"),  # another test point's stop
    (int(5.5 * S), "pA", "stop"),
    (int(5.7 * S), "pA", "stop"),  # stop without start
    (int(6.0 * S), "pB", " START "),  # blanks and case are ignored
    (int(11.5 * S), "pB", "stop"),
]
REJECTED = {"start_twice": 1, "event_key": 2, "event_value": 1, "stop_other_name": 1, "stop_without_start": 1}


def events_bag(tmp_path, events=EVENTS, topic="/test_point", name="flight"):
    """The bundled bag with test-point events (diagnostic_msgs/msg/KeyValue) at offsets from its start."""
    from rosbags.highlevel import AnyReader
    from rosbags.rosbag2 import StoragePlugin, Writer

    store = typestore()
    kv = store.types["diagnostic_msgs/msg/KeyValue"]
    path = tmp_path / name
    with AnyReader([BAG], default_typestore=store) as reader, \
            Writer(path, version=9, storage_plugin=StoragePlugin.MCAP) as w:
        conns = {c.topic: w.add_connection(c.topic, c.msgtype, typestore=store) for c in reader.connections}
        ev = w.add_connection(topic, "diagnostic_msgs/msg/KeyValue", typestore=store)
        pending = sorted(events)
        for conn, t, raw in reader.messages():
            while pending and T0 + pending[0][0] <= t:
                off, key, value = pending.pop(0)
                w.write(ev, T0 + off, store.serialize_cdr(kv(key=key, value=value), "diagnostic_msgs/msg/KeyValue"))
            w.write(conns[conn.topic], t, raw)
    return path


def params(**extra):
    p = dict(load(CONFIG, "config")["/**"]["ros__parameters"])
    flat = {}

    def walk(prefix, d):
        for k, v in d.items():
            if isinstance(v, dict):
                walk(f"{prefix}{k}.", v)
            else:
                flat[f"{prefix}{k}"] = v
    walk("", p)
    flat.update(extra)
    return flat


def rows_of(path):
    with open(path) as f:
        return list(csv.DictReader(f))


def live_history(bag, config):
    """The node's way: one pipeline without regression rows, each input message through feed,
    each event to the tracker when it arrives, each output to the tracker."""
    messages, _t0 = read_inputs(bag, events=config.maneuvers.topic)
    pipe = Pipeline(config)
    tracker = ManeuverTracker(pipe, config.maneuvers)
    last = 0
    for kind, stamp, msg in messages:
        if kind == "event":
            tracker.event(stamp, msg.key, msg.value)
            continue
        last = max(last, stamp)
        for out in feed(pipe, kind, msg):
            tracker.sample(out)
    pipe.finish()
    tracker.finish(last)
    return tracker


def reset_by_hand(bag, config, start, stop, wanted):
    """A pipeline fed ``bag``'s messages up to ``stop`` (ns from the bag's start), reset by hand
    (inputs kept) at the first message at or after ``start``: the pipeline, its newest sample's
    stamp just before the reset, and the last output for which ``wanted(out)`` holds."""
    messages, _ = read_inputs(bag)
    pipe = Pipeline(config)
    last, reset, newest = None, False, None
    for kind, stamp, msg in messages:
        if stamp >= T0 + start and not reset:
            newest = pipe.last_stamp_ns
            pipe.reset("by_hand", clear_inputs=False)
            reset = True
        if stamp > T0 + stop:
            break
        for out in feed(pipe, kind, msg):
            if wanted(out):
                last = out
    assert last is not None
    return pipe, newest, last


# ---------------------------------------------------------------------------- the events' rules
@pytest.mark.parametrize(("key", "value", "reason"), [
    ("p", "begin", "event_value"), ("p", "", "event_value"), ("", "start", "event_key"),
    ("   ", "stop", "event_key"), ("x" * 65, "start", "event_key"), (None, "start", "event_type"),
    ("p", 3, "event_type"), (b"p", "start", "event_type"),
])
def test_a_bad_event_is_rejected_with_its_reason_and_changes_nothing(key, value, reason):
    config = pipeline_config(params(**{"maneuvers.source": "events"}))
    tracker = ManeuverTracker(Pipeline(config), config.maneuvers)
    assert tracker.event(0, key, value) == reason
    assert tracker.rejected == {reason: 1} and tracker.active is None and not tracker.history


def test_garbage_events_are_counted_by_reason_and_never_start_or_end_a_maneuver(tmp_path):
    config = pipeline_config(params(**{"maneuvers.source": "events"}))
    tracker = live_history(events_bag(tmp_path), config)
    assert tracker.rejected == REJECTED
    assert [r.name for r in tracker.history] == ["pA", "pB"]
    a, b = tracker.history
    # Placed in data time: the newest sample used when the event came, within the delay line
    # (differentiator lag and the interpolation's wait: a few samples) before it.
    for rec, (start, end) in ((a, (0.5, 5.5)), (b, (6.0, 11.5))):
        assert start - 0.2 < (rec.start_ns - T0) * 1e-9 <= start and end - 0.2 < (rec.end_ns - T0) * 1e-9 <= end
        assert rec.start_ns % (S // 50) == 0 and rec.end_ns % (S // 50) == 0  # samples of the 50 Hz grid
    summary = tracker.summary()
    assert summary["maneuvers.events_rejected"] == 6 and summary["maneuvers.recorded"] == 2
    assert summary["maneuvers.events_rejected.start_twice"] == 1 and summary["maneuvers.last"] == "pB"


def test_the_history_is_a_ring_of_maneuvers_history_entries():
    config = pipeline_config(params(**{"maneuvers.source": "events", "maneuvers.history": 2}))
    tracker = ManeuverTracker(Pipeline(config), config.maneuvers)
    for k in range(5):
        assert tracker.event(10 * k * S, f"p{k}", "start") is None
        assert tracker.event((10 * k + 5) * S, f"p{k}", "stop") is None
    assert [r.name for r in tracker.history] == ["p3", "p4"] and tracker.recorded == 5
    # No data: every row says so, with the maneuver's 5 s.
    assert all(r.status.startswith("no estimate") for r in tracker.history[-1].rows)
    assert tracker.history[-1].duration == 5.0


def test_maneuvers_are_off_by_default_and_detect_feeds_the_detector_of_the_settings():
    pipe = Pipeline(pipeline_config(params()))
    assert pipe.config.maneuvers == ManeuverSettings() and tracker_for(pipe) is None
    detect = Pipeline(pipeline_config(params(**{"maneuvers.source": "detect", "maneuvers.threshold": 20.0})))
    tracker = tracker_for(detect)
    assert isinstance(tracker.detector, ManeuverDetector) and tracker.detector.options.threshold == 20.0


# ---------------------------------------------------------------------------- a maneuver's numbers
def test_each_maneuver_is_a_fresh_estimator_over_its_own_samples(tmp_path):
    """A maneuver's final estimates are those of a pipeline restarted (inputs kept) where its
    start arrives and read at the last output before its end arrives: checked against a second
    pipeline reset by hand at the same place in the stream (event times off the messages' grid)."""
    config = pipeline_config(params(**{"maneuvers.source": "events"}))
    start, stop = 6 * S + 1_300_000, int(11.5 * S) + 1_300_000
    bag = events_bag(tmp_path, [(start, "pB", "start"), (stop, "pB", "stop")])
    tracker = live_history(bag, config)
    (rec,) = tracker.history
    pipe, newest, last = reset_by_hand(bag, config, start, stop, lambda out: out.ready.all())
    theta = [r.estimate for r in rec.rows]
    expected = [last.theta[j, i] for j, n in enumerate(pipe.sizes) for i in range(n)]
    np.testing.assert_array_equal(theta, expected)
    se = [r.se_corrected for r in rec.rows]
    np.testing.assert_array_equal(se, [last.se[j, i] for j, n in enumerate(pipe.sizes) for i in range(n)])
    assert all(r.status == "ok" for r in rec.rows)
    # The samples since the start: about the 5.5 s between the events at 50 Hz.
    assert all(abs(r.samples - 5.5 * config.rate) <= 10 for r in rec.rows)
    # Start and end are the newest samples when the events came: the end the final estimates'.
    assert (rec.start_ns, rec.end_ns) == (newest, last.stamp_ns)


def test_with_both_methods_each_maneuver_has_its_frequency_domain_rows(tmp_path):
    """estimator.method both: after each time-domain row the parameter's frequency-domain row (the
    bias has none), its values those of the newest sample before the end whose frequency-domain
    results were ready, checked against a pipeline reset by hand at the start's place in the
    stream; and the replay's, the campaign's and the node's way agree on them."""
    extra = {"maneuvers.source": "events", "estimator.method": "both"}
    config = pipeline_config(params(**extra))
    start, stop = 6 * S + 1_300_000, int(11.5 * S) + 1_300_000
    bag = events_bag(tmp_path, [(start, "pB", "start"), (stop, "pB", "stop")])
    tracker = live_history(bag, config)
    (rec,) = tracker.history
    pipe, _newest, last = reset_by_hand(bag, config, start, stop,
                                        lambda out: out.frequency is not None and out.frequency.ready.all())
    methods = [(r.parameter, r.method) for r in rec.rows]
    want = [(p, m) for j, names in enumerate(pipe.parameter_names) for p in names
            for m in ("time", "frequency") if m == "time" or p in pipe.models[j].frequency_parameter_names]
    assert methods == want and sum(m == "frequency" for _p, m in methods) == 5
    f = last.frequency
    expected = {p: (f.theta[j, k], f.se[j, k], f.se_conventional[j, k])
                for j, m in enumerate(pipe.models) for k, p in enumerate(m.frequency_parameter_names)}
    for r in rec.rows:
        if r.method == "frequency":
            assert r.status == "ok" and (r.estimate, r.se_corrected, r.se_conventional) == expected[r.parameter]
            assert math.isnan(r.se_corrected_all) and math.isnan(r.r_squared)
    cfg = tmp_path / "both.yaml"
    events_on = "    maneuvers:\n      source: events\n    aircraft: t2"
    cfg.write_text(CONFIG.read_text().replace("    aircraft: t2", events_on, 1))
    assert cli.main(["replay", str(bag), "--config", str(cfg), "--method", "both", "--out", str(tmp_path / "r"),
                     "--quiet", "--no-figures"]) == 0
    assert cli.main(["campaign", str(bag), "--config", str(cfg), "--method", "both", "--out", str(tmp_path / "c"),
                     "--quiet", "--no-figures"]) == 0
    replayed = rows_of(tmp_path / "r" / "maneuvers.csv")
    assert replayed == rows_of(tmp_path / "c" / "maneuvers.csv")
    freq = [r for r in replayed if r["method"] == "frequency"]
    assert [float(r["estimate"]) for r in freq] == [r.estimate for r in rec.rows if r.method == "frequency"]


# ---------------------------------------------------------------------------- the three paths agree
def test_replay_campaign_and_live_history_give_the_same_rows(tmp_path):
    bag = events_bag(tmp_path)
    cfg = tmp_path / "events.yaml"
    events_on = "    maneuvers:\n      source: events\n    aircraft: t2"
    cfg.write_text(CONFIG.read_text().replace("    aircraft: t2", events_on, 1))
    assert cli.main(["replay", str(bag), "--config", str(cfg), "--out", str(tmp_path / "r"), "--quiet",
                     "--no-figures"]) == 0
    assert cli.main(["campaign", str(bag), "--config", str(cfg), "--out", str(tmp_path / "c"), "--quiet",
                     "--no-figures"]) == 0
    replayed = (tmp_path / "r" / "maneuvers.csv").read_text()
    campaigned = (tmp_path / "c" / "maneuvers.csv").read_text()
    assert replayed == campaigned
    rows = list(csv.DictReader(io.StringIO(replayed)))
    assert tuple(rows[0]) == (*MANEUVER_COLUMNS, "start", "end")
    spans = [(r["maneuver"], float(r["start"]), float(r["end"])) for r in rows[::7]]
    assert [name for name, _s, _e in spans] == ["pA", "pB"]
    for (_name, s0, s1), (start, end) in zip(spans, ((0.5, 5.5), (6.0, 11.5)), strict=True):
        assert start - 0.2 < s0 <= start and end - 0.2 < s1 <= end
    assert all(r["status"] == "ok" and float(r["se_corrected_all"]) > 0 for r in rows)
    # The node's way of feeding (no regression rows: no all-lags SE) gives the same numbers.
    live = live_history(bag, pipeline_config(params(**{"maneuvers.source": "events"})))
    flat = [r for rec in live.history for r in rec.rows]
    assert len(flat) == len(rows)
    for got, want in zip(flat, rows, strict=True):
        for c in MANEUVER_COLUMNS:
            if c in ("se_corrected_all", "se_percent"):
                continue
            value = getattr(got, c)
            cell = "" if isinstance(value, float) and math.isnan(value) else (
                repr(value) if isinstance(value, float) else str(value))
            assert cell == want[c], (c, got.parameter)
        assert math.isnan(got.se_corrected_all)
    table = rows_of(tmp_path / "c" / "table4.csv")
    assert {r["parameter"]: int(r["maneuvers"]) for r in table} == {r.parameter: 2 for r in flat}


def test_replay_without_maneuvers_writes_no_maneuvers_csv_and_the_same_numbers(tmp_path):
    """The default (maneuvers.source off): the event topic is not read, nothing is cut."""
    bag = events_bag(tmp_path)
    plain = run_pipeline(read_inputs(BAG)[0], pipeline_config(params()), record=False)
    assert plain.maneuvers is None
    assert cli.main(["replay", str(bag), "--config", str(CONFIG), "--out", str(tmp_path / "r"), "--quiet",
                     "--no-figures"]) == 0
    assert not (tmp_path / "r" / "maneuvers.csv").exists()


@pytest.mark.parametrize("targets", ["Cm_q=1000,CZ_alpha=1000", "Cm_q=0.01"])
def test_a_maneuvers_rows_carry_its_verdict_at_its_end(tmp_path, targets):
    """With targets.percent, maneuvers.csv (and the history) gives each maneuver's verdict on
    its rows: one test point over the whole bag ends with the verdict of a run without
    maneuvers over the same samples; without targets the column is empty."""
    bag = events_bag(tmp_path, events=[(0, "pA", "start")])
    cfg = tmp_path / "targets.yaml"
    cfg.write_text(CONFIG.read_text().replace(
        "    aircraft: t2", f"    maneuvers:\n      source: events\n    targets:\n      percent: {targets}\n"
        "    aircraft: t2", 1))
    assert cli.main(["replay", str(bag), "--config", str(cfg), "--out", str(tmp_path / "r"), "--quiet",
                     "--no-figures"]) == 0
    rows = rows_of(tmp_path / "r" / "maneuvers.csv")
    plain = run_pipeline(read_inputs(BAG)[0], pipeline_config(params(**{"targets.percent": targets})), record=False)
    want = plain.pipeline.targets.verdict().text
    assert want.startswith("done" if "1000" in targets else ("needs more", "not identifiable"))
    assert {r["maneuver"] for r in rows} == {"pA"} and {r["verdict"] for r in rows} == {want}
    live = live_history(bag, pipeline_config(params(**{"maneuvers.source": "events", "targets.percent": targets})))
    assert [d["rows"][0]["verdict"] for d in (rec.as_dict() for rec in live.history)] == [want]
    untargeted = live_history(bag, pipeline_config(params(**{"maneuvers.source": "events"})))
    assert {r.verdict for rec in untargeted.history for r in rec.rows} == {""}


def test_replays_estimates_mcap_holds_the_nodes_history_as_it_changed(tmp_path):
    """The replay writes ~/maneuvers into estimates.mcap as the node publishes it: at the start
    (nothing recorded), at each boundary and rejected event; the last message's maneuvers are
    the rows of maneuvers.csv, start and end in s of the inputs' stamps."""
    import json

    from rosbags.highlevel import AnyReader

    bag = events_bag(tmp_path)
    cfg = tmp_path / "events.yaml"
    cfg.write_text(CONFIG.read_text().replace("    aircraft: t2", "    maneuvers:\n      source: events\n"
                                              "    aircraft: t2", 1))
    assert cli.main(["replay", str(bag), "--config", str(cfg), "--out", str(tmp_path / "r"), "--quiet",
                     "--no-figures"]) == 0
    with AnyReader([tmp_path / "r" / "estimates.mcap"], default_typestore=typestore()) as reader:
        conns = [c for c in reader.connections if c.topic == "/rls_estimator/maneuvers"]
        assert [c.msgtype for c in conns] == ["std_msgs/msg/String"]
        history = [json.loads(reader.deserialize(raw, c.msgtype).data) for c, _t, raw in reader.messages(conns)]
    assert history[0]["recorded"] == 0 and history[0]["active"] is None
    assert [h["recorded"] for h in history] == sorted(h["recorded"] for h in history)
    assert sum(history[-1]["rejected"].values()) == sum(REJECTED.values()) and history[-1]["recorded"] == 2
    rows = rows_of(tmp_path / "r" / "maneuvers.csv")
    flat = [(m["name"], m["start"], m["end"], r) for m in history[-1]["maneuvers"] for r in m["rows"]]
    assert len(flat) == len(rows)
    for (name, start, end, got), want in zip(flat, rows, strict=True):
        assert name == want["maneuver"]
        assert math.isclose(start - T0 * 1e-9, float(want["start"]), abs_tol=1e-6)
        assert math.isclose(end - T0 * 1e-9, float(want["end"]), abs_tol=1e-6)
        for c in MANEUVER_COLUMNS[1:]:
            value = got[c]
            cell = "" if value is None else repr(value) if isinstance(value, float) else str(value)
            assert cell == want[c], (c, name)


def test_campaign_of_a_recording_counts_the_refused_events_and_refuses_one_without_maneuvers(tmp_path, capsys):
    cfg = tmp_path / "events.yaml"
    events_on = "    maneuvers:\n      source: events\n    aircraft: t2"
    cfg.write_text(CONFIG.read_text().replace("    aircraft: t2", events_on, 1))
    bag = events_bag(tmp_path)
    assert cli.main(["campaign", str(bag), "--config", str(cfg), "--out", str(tmp_path / "c"), "--quiet",
                     "--no-figures"]) == 0
    last = (tmp_path / "c" / "summary.txt").read_text().splitlines()[-1]
    assert last.startswith(f"{sum(REJECTED.values())} events on /test_point refused (")
    for reason, n in REJECTED.items():
        assert f"{reason} {n}" in last
    capsys.readouterr()
    # The event topic is in the recording but holds no message: no maneuver, nothing written.
    empty = events_bag(tmp_path, events=[], name="no_events")
    assert cli.main(["campaign", str(empty), "--config", str(cfg), "--out", str(tmp_path / "e"), "--quiet",
                     "--no-figures"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "no maneuver found by maneuvers.source events" in err, err
    assert "no start and stop event on maneuvers.topic /test_point" in err
    assert not (tmp_path / "e").exists()
    # Only refused events: the reasons are the error's.
    refused = events_bag(tmp_path, events=[(S, "pA", "pause"), (2 * S, "pA", "stop")], name="refused")
    assert cli.main(["campaign", str(refused), "--config", str(cfg), "--out", str(tmp_path / "r"), "--quiet",
                     "--no-figures"]) == 2
    err = capsys.readouterr().err
    assert "2 events on /test_point refused (event_value 1, stop_without_start 1" in err, err
    assert not (tmp_path / "r").exists()


def test_campaign_refuses_a_maneuvers_file_beside_maneuvers_source(tmp_path, capsys):
    # Two ways of cutting the one recording: the file used to win silently.
    cfg = tmp_path / "events.yaml"
    events_on = "    maneuvers:\n      source: events\n    aircraft: t2"
    cfg.write_text(CONFIG.read_text().replace("    aircraft: t2", events_on, 1))
    spans = tmp_path / "m.yaml"
    spans.write_text("maneuvers:\n  - {name: a, start: 0.0, end: 5.0}\n")
    assert cli.main(["campaign", str(BAG), "--maneuvers", str(spans), "--config", str(cfg),
                     "--out", str(tmp_path / "c"), "--quiet", "--no-figures"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1, err
    assert "--maneuvers FILE and maneuvers.source events both cut the recording" in err
    assert "maneuvers.source off to cut it by FILE" in err and not (tmp_path / "c").exists()


def test_campaign_refuses_maneuvers_source_with_several_recordings(tmp_path, capsys):
    # Each bag would be one maneuver and maneuvers.source silently unused.
    cfg = tmp_path / "detect.yaml"
    detect_on = "    maneuvers:\n      source: detect\n    aircraft: t2"
    cfg.write_text(CONFIG.read_text().replace("    aircraft: t2", detect_on, 1))
    assert cli.main(["campaign", str(BAG), str(BAG), "--config", str(cfg), "--out", str(tmp_path / "c"), "--quiet",
                     "--no-figures"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "maneuvers.source detect cuts one recording into maneuvers; got 2 INPUTs" in err
    assert not (tmp_path / "c").exists()


def test_each_maneuver_has_its_models_in_models_json_and_predict_takes_them(tmp_path, capsys):
    """A replay with maneuvers and the campaign of the same recording write models.json with one
    entry per maneuver, in order: its final estimates are the rows' in maneuvers.csv, the
    square roots of its corrected covariance's diagonal the rows' corrected standard errors;
    `predict --maneuver` applies one of them to the bag."""
    from rls_uncertainty.offline.model_file import read_models

    cfg = tmp_path / "events.yaml"
    cfg.write_text(CONFIG.read_text().replace("    aircraft: t2", "    maneuvers:\n      source: events\n"
                                              "    aircraft: t2", 1))
    bag = events_bag(tmp_path)
    for command in ("replay", "campaign"):
        assert cli.main([command, str(bag), "--config", str(cfg), "--out", str(tmp_path / command), "--quiet",
                         "--no-figures"]) == 0
    models = read_models(tmp_path / "replay")
    assert [name for name, _ in models] == ["pA", "pB"]
    assert [(n, [m.as_json() for m in ms]) for n, ms in read_models(tmp_path / "campaign")] == \
        [(n, [m.as_json() for m in ms]) for n, ms in models]
    rows = rows_of(tmp_path / "replay" / "maneuvers.csv")
    for name, fitted in models:
        assert [m.model for m in fitted] == ["CZ", "Cm"]
        for m in fitted:
            mine = {r["parameter"]: r for r in rows if r["maneuver"] == name and r["model"] == m.model}
            assert list(mine) == list(m.parameters)
            np.testing.assert_array_equal(m.estimate, [float(mine[p]["estimate"]) for p in m.parameters])
            np.testing.assert_allclose(np.sqrt(np.diag(m.covariance)),
                                       [float(mine[p]["se_corrected"]) for p in m.parameters], rtol=1e-9)
            np.testing.assert_allclose(np.sqrt(np.diag(m.covariance_conventional)),
                                       [float(mine[p]["se_conventional"]) for p in m.parameters], rtol=1e-9)
    capsys.readouterr()
    assert cli.main(["predict", str(tmp_path / "campaign"), str(BAG), "--config", str(CONFIG), "--out",
                     str(tmp_path / "p"), "--maneuver", "pB"]) == 0
    assert "pB" in capsys.readouterr().out and (tmp_path / "p" / "prediction.csv").exists()
