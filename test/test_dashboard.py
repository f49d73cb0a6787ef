"""The dashboard without ROS and without a browser: arrays paired by the stamp they carry (never
by arrival), bounded histories, the node's /diagnostics read back (against the node's own
diagnostics policy on the bundled bag), the page's states, and a finished replay read back
equal to its estimates.csv."""

from __future__ import annotations

import csv
import random
import re
from pathlib import Path
from types import SimpleNamespace

import pytest

from rls_uncertainty.dashboard.hub import Hub, Source
from rls_uncertainty.dashboard.model import MAX_PENDING, ArrayUpdate, ModelHistory, Pairing, Sample, array_update
from rls_uncertainty.dashboard.settings import full_node_name, load_reference
from rls_uncertainty.datapath.inputs import STREAMS
from rls_uncertainty.datapath.outputs import (
    FREQUENCY_DOMAIN,
    PAIRED,
    TIME_DOMAIN,
    ArrayKey,
    array_key,
    split_topic,
    stamp_label,
)
from rls_uncertainty.errors import ConfigError
from rls_uncertainty.ros.health import HealthTracker, parse_statuses
from rls_uncertainty.settings import NODE_NAME

ROOT = Path(__file__).resolve().parents[1]
NAMES = ("CZ_0", "CZ_alpha", "CZ_delta_e")
QUANTITIES = ("estimate", "se", "se_conventional", "converged")


def _values(stamp: int, suffix: str) -> tuple[float, ...]:
    """A distinct, checkable value for each stamp, array and parameter."""
    return tuple(stamp * 1e-9 + PAIRED.index(suffix) * 100 + i for i in range(len(NAMES)))


def _update(stamp: int, suffix: str, model: str = "CZ") -> ArrayUpdate:
    return ArrayUpdate(model, suffix, NAMES, _values(stamp, suffix), stamp)


def _msg(names: str, data, *labels: str):
    """A Float64MultiArray as rclpy and rosbags present it (read by field name)."""
    dims = [SimpleNamespace(label=label, size=1, stride=1) for label in (names, *labels)]
    return SimpleNamespace(layout=SimpleNamespace(dim=dims, data_offset=0), data=list(data))


def _key(suffix: str, model: str = "CZ") -> ArrayKey:
    return ArrayKey(TIME_DOMAIN, model, suffix)


def _page_of(messages) -> dict:
    """What a page holds after ``messages`` (a snapshot, then samples), rebuilt here as the
    page's script does: per method and model the columns, appended in order; the counts."""
    page: dict = {"methods": {}, "counts": {}, "quality": []}
    for m in messages:
        if m["type"] == "snapshot":
            page = {"methods": {}, "counts": {}, "quality": m["quality"]}
        elif m["type"] == "samples":
            for model, cols in m["models"].items():
                held = page["methods"].setdefault(m["method"], {}).get(model)
                if held is None or held["names"] != cols["names"] or cols["t"][0] <= held["t"][-1]:
                    held = page["methods"][m["method"]][model] = {
                        "names": cols["names"], "t": [], **{q: [[] for _ in cols["names"]] for q in QUANTITIES}}
                held["t"] += cols["t"]
                for q in QUANTITIES:
                    for column, values in zip(held[q], cols[q], strict=True):
                        column.extend(values)
                if "count" in cols:
                    page["counts"][(m["method"], model)] = cols["count"]
    return page


def _arrays(stamps, published=None, model: str = "CZ"):
    """The four paired arrays of each stamp, as the hub takes them."""
    return [(_key(suffix, model), _msg(",".join(NAMES), _values(s, suffix), stamp_label(s)), published)
            for s in stamps for suffix in PAIRED]


# ------------------------------------------------------------------ pairing
def test_arrays_are_paired_by_their_stamps_whatever_the_arrival_order():
    stamps = [1_000_000_000 + 20_000_000 * k for k in range(30)]
    arrivals = [_update(s, suffix) for s in stamps for suffix in PAIRED]
    random.Random(7).shuffle(arrivals)
    pairing = Pairing(max_pending=len(stamps))
    done = [s for s in map(pairing.add, arrivals) if s is not None]
    assert sorted(s.stamp_ns for s in done) == stamps
    for s in done:  # every field from the arrays of its own stamp
        assert s.estimate == _values(s.stamp_ns, "estimates")
        assert s.se == _values(s.stamp_ns, "standard_errors")
        assert s.se_conventional == _values(s.stamp_ns, "standard_errors_conventional")
        assert s.converged == _values(s.stamp_ns, "converged")
    assert pairing.dropped == {}


def test_an_array_whose_partners_never_come_is_dropped_and_counted_not_paired_with_another_stamp():
    pairing = Pairing()
    assert pairing.add(_update(5, "estimates")) is None  # its standard errors are lost
    done = []
    for k in range(MAX_PENDING + 1):
        for suffix in PAIRED:
            s = pairing.add(_update(10 + k, suffix))
            if s is not None:
                done.append(s)
    assert [s.stamp_ns for s in done] == list(range(10, 11 + MAX_PENDING))
    assert pairing.dropped == {"unpaired": 1}


def test_a_late_joiners_burst_of_kept_samples_one_array_after_the_other_pairs_up():
    """A transient-local late joiner receives every kept sample of one array, then of the next:
    each array's messages in order, far more than MAX_PENDING stamps apart from their partners.
    Every sample completes, in stamp order, nothing is dropped; waiting stamps are bounded."""
    stamps = [1_000_000_000 + 20_000_000 * k for k in range(5 * MAX_PENDING)]
    pairing = Pairing()
    done = [s for suffix in PAIRED for stamp in stamps if (s := pairing.add(_update(stamp, suffix))) is not None]
    assert [s.stamp_ns for s in done] == stamps and pairing.dropped == {}
    bounded = Pairing(max_stamps=10)
    for stamp in stamps[:25]:
        bounded.add(_update(stamp, "estimates"))  # partners that never come
    assert bounded.dropped == {"unpaired": 15} and len(bounded._pending[(TIME_DOMAIN, "CZ")]) == 10


def test_refused_arrays_are_counted_by_reason():
    pairing = Pairing()
    bad = ArrayUpdate("CZ", "estimates", NAMES, (1.0, float("nan"), 2.0), 1)
    short = ArrayUpdate("CZ", "estimates", NAMES, (1.0,), 2)
    assert pairing.add(bad) is None and pairing.add(short) is None
    for suffix in PAIRED[:-1]:
        pairing.add(_update(3, suffix))
    other = ArrayUpdate("CZ", "converged", ("CZ_0", "CZ_beta", "CZ_delta_e"), (1.0, 1.0, 1.0), 3)
    assert pairing.add(other) is None
    assert pairing.add(_update(4, "estimates")) is None and pairing.add(_update(4, "estimates")) is None
    assert pairing.dropped == {"non_finite": 1, "bad_layout": 1, "mismatched_names": 4, "duplicate": 1}


def test_array_update_reads_names_and_stamp_from_the_layout_the_node_writes():
    stamp = 1_767_225_600_140_000_000
    u = array_update(_key("estimates", "Cm"), _msg("Cm_0,Cm_q", [1.5, -40.0], stamp_label(stamp)), 7)
    assert (u.names, u.data, u.stamp_ns, u.published_ns) == (("Cm_0", "Cm_q"), (1.5, -40.0), stamp, 7)
    for msg in (_msg("Cm_0", [1.0]), _msg("Cm_0", [1.0], "time:1.0")):
        msg.layout.dim = msg.layout.dim[:1] if len(msg.layout.dim) == 1 else msg.layout.dim
        with pytest.raises(ValueError):
            array_update(_key("estimates", "Cm"), msg)


def test_topics_under_the_node_map_to_the_method_model_and_array_shown():
    assert array_key("CZ/estimates") == ArrayKey(TIME_DOMAIN, "CZ", "estimates")
    assert array_key("Cm/identifiability") == ArrayKey(TIME_DOMAIN, "Cm", "identifiability")
    for suffix in PAIRED:  # the frequency-domain estimator's arrays (docs/frequency.md)
        assert array_key(f"CZ/frequency/{suffix}") == ArrayKey(FREQUENCY_DOMAIN, "CZ", suffix)
    for other in ("CZ/covariance", "sample_stamp", "CZ", "/estimates", "CZ/estimates/x", "CZ/frequency/fit",
                  "CZ/frequency/identifiability", "CZ/frequency/covariance", "/frequency/estimates",
                  "CZ/frequency/estimates/x", "CZ/frequenc/estimates"):
        assert array_key(other) is None, other
    # A bag's absolute topics, whose node is not known beforehand.
    assert split_topic("/ns/rls_estimator/CZ/frequency/converged") == (
        "/ns/rls_estimator", ArrayKey(FREQUENCY_DOMAIN, "CZ", "converged"))
    assert split_topic("/rls_estimator/Cm/estimates") == ("/rls_estimator", ArrayKey(TIME_DOMAIN, "Cm", "estimates"))
    for other in ("/rls_estimator/CZ/covariance", "/rls_estimator/sample_stamp", "/CZ/estimates", "CZ/estimates"):
        assert split_topic(other) is None, other


def test_the_hub_keeps_the_two_methods_of_a_model_apart():
    """The same model's time- and frequency-domain arrays of the same stamps (the frequency
    domain's over the parameters without the bias) complete separate samples and histories,
    each holding its own arrays' values, and the page's messages name the method."""
    hub = Hub(Source("live", "/rls_estimator"))
    stamps = [1_000_000_000 + 20_000_000 * k for k in range(5)]
    f_names = NAMES[1:]

    def f_values(stamp, suffix):
        return tuple(1000 + v for v in _values(stamp, suffix)[1:])  # its own values (positive, as SEs are)

    arrays = []
    for s in stamps:  # interleaved as the node publishes them: time domain, then frequency domain
        arrays += _arrays([s])
        arrays += [(ArrayKey(FREQUENCY_DOMAIN, "CZ", suffix), _msg(",".join(f_names), f_values(s, suffix),
                                                                   stamp_label(s)), None) for suffix in PAIRED]
    messages = hub.add_arrays(arrays)
    assert hub.pairing.dropped == {}
    assert set(hub.histories) == {(TIME_DOMAIN, "CZ"), (FREQUENCY_DOMAIN, "CZ")}
    for method, names, values in ((TIME_DOMAIN, NAMES, _values), (FREQUENCY_DOMAIN, f_names, f_values)):
        cols = hub.histories[(method, "CZ")].columns()
        assert cols["names"] == list(names) and cols["t"] == [s * 1e-9 for s in stamps]
        for quantity, suffix in zip(("estimate", "se", "se_conventional", "converged"), PAIRED, strict=True):
            assert [list(c) for c in zip(*cols[quantity], strict=True)] == [list(values(s, suffix)) for s in stamps]
    assert {m["method"] for m in messages if m["type"] == "samples"} == {TIME_DOMAIN, FREQUENCY_DOMAIN}
    snapshot = _page_of(hub.snapshot_messages())["methods"]
    assert snapshot[FREQUENCY_DOMAIN]["CZ"]["names"] == list(f_names)
    assert snapshot[TIME_DOMAIN]["CZ"]["names"] == list(NAMES)
    assert hub.history_resets == 0 and hub.samples_total == 2 * len(stamps)


# ------------------------------------------------------------------ history
def test_history_is_bounded_and_keeps_the_newest_half_at_full_rate():
    h = ModelHistory(NAMES, capacity=100)
    for k in range(1000):
        h.append(Sample("CZ", k, NAMES, (k, 0, 0), (1, 1, 1), (2, 2, 2), (0, 0, 1), None))
    cols = h.columns()
    t = [round(x * 1e9) for x in cols["t"]]
    assert h.size <= 100 and t[0] == 0 and t[-1] == 999
    assert t == sorted(t) and cols["estimate"][0] == t  # the values travel with their stamps
    newest = t[-h.size // 2:]
    assert newest == list(range(999 - len(newest) + 1, 1000))  # no gap in the newest half
    assert h.thinned == 1000 - h.size


# ------------------------------------------------------------------ diagnostics read back
@pytest.fixture(scope="module")
def bundled_replay():
    from rls_uncertainty.offline.bags import read_inputs
    from rls_uncertainty.offline.replay import run_pipeline
    from rls_uncertainty.settings import load_parameters_file, node_config, pipeline_config

    params = load_parameters_file("t2")
    messages = read_inputs(ROOT / "bags" / "t2_maneuver")[0]
    return run_pipeline(messages, pipeline_config(params), diagnostics=node_config(params))


def test_health_reads_back_what_the_node_diagnostics_policy_writes(bundled_replay):
    _stamp, statuses = bundled_replay.diagnostics[-1]
    tuples = [(s.name, s.level, s.message, dict(s.values)) for s in statuses]
    h = parse_statuses(tuples, NODE_NAME)
    by_name = {s.name: s for s in statuses}
    inputs = by_name[f"{NODE_NAME}: inputs"]
    assert h.inputs_level == inputs.level and h.inputs_message == inputs.message
    assert [s.name for s in h.streams] == list(STREAMS)
    values = dict(inputs.values)
    for s in h.streams:
        for key in ("rate_hz", "age_s", "received", "accepted", "recent.rejected"):
            assert s.get(key) == values[f"{s.name}.{key}"]
    assert h.samples_message == by_name[f"{NODE_NAME}: samples"].message
    assert set(h.models) == {"CZ", "Cm"}
    assert h.models["CZ"]["r_squared"] == dict(by_name[f"{NODE_NAME}: model CZ"].values)["r_squared"]
    assert parse_statuses(tuples, "other_node") is None


def _inputs(rejected: dict[str, int], recent: int, window: float = 10.0, prefix: str = NODE_NAME):
    values = {"recent_window_s": f"{window:g}", "imu.received": "100", "imu.recent.rejected": str(recent)}
    values.update({f"imu.rejected.{r}": str(n) for r, n in rejected.items()})
    return [(f"{prefix}: inputs", 1 if recent else 0, "", values)]


def _snapshot(enabled: bool):
    """What a fresh node with the t2 configuration hands its diagnostics policy."""
    from rls_uncertainty.datapath.diagnostics import Snapshot
    from rls_uncertainty.datapath.pipeline import Pipeline
    from rls_uncertainty.settings import load_parameters_file, pipeline_config

    pipe = Pipeline(pipeline_config(load_parameters_file("t2")))
    return Snapshot(counters=pipe.counters(), models=[(m.output, pipe.model_report(j)) for j, m in
                                                      enumerate(pipe.config.models)],
                    required=tuple(pipe.required), max_gap=0.1, now_ns=0, elapsed_s=1.0,
                    publishers=dict.fromkeys(STREAMS, 1), topics={k: f"/{k}" for k in STREAMS}, reliable=True,
                    enabled=enabled, state_file="no state file")


def test_statuses_of_namespaced_nodes_are_told_apart():
    """Three nodes named rls_estimator (root, /a, /b) report on one /diagnostics: each
    consumer reads its own node's statuses, named by the node's policy."""
    from rls_uncertainty.datapath.diagnostics import DiagnosticsPolicy

    arrays = []
    for node, enabled in (("/rls_estimator", True), ("/a/rls_estimator", False), ("/b/rls_estimator", True)):
        statuses = DiagnosticsPolicy(node).update(_snapshot(enabled))
        assert {s.hardware_id for s in statuses} == {node.lstrip("/") if node.count("/") == 1 else node}
        arrays += [(s.name, s.level, s.message, dict(s.values)) for s in statuses]
    names = [name for name, *_ in arrays]
    assert len(set(names)) == len(names)  # no two statuses share a name
    assert {n.partition(":")[0] for n in names} == {"rls_estimator", "/a/rls_estimator", "/b/rls_estimator"}
    for node, enabled in (("/rls_estimator", True), ("rls_estimator", True), ("/a/rls_estimator", False),
                          ("/b/rls_estimator", True)):
        health = parse_statuses(arrays, node)
        assert health.samples["enabled"] == str(enabled), node
    assert parse_statuses(arrays, "/c/rls_estimator") is None


def test_recent_rejections_by_reason_are_the_increase_over_the_nodes_window():
    now = [0.0]
    tracker = HealthTracker(clock=lambda: now[0])
    seen = []
    reports = ((0, {"non_finite": 3}, 3), (5, {"non_finite": 3, "stamp_jump": 1}, 4),
               (12, {"non_finite": 3, "stamp_jump": 2}, 1), (30, {"non_finite": 3, "stamp_jump": 2}, 0))
    for t, rejected, recent in reports:
        now[0] = t
        health = tracker.update(parse_statuses(_inputs(rejected, recent), NODE_NAME))
        seen.append(dict(health.streams[0].recent_reasons))
    # the first report: the node says all 3 are recent; at 12 s the baseline is the report of
    # 0 s (the newest at least 10 s old); at 30 s nothing is recent.
    assert seen == [{"non_finite": 3}, {"non_finite": 3, "stamp_jump": 1}, {"stamp_jump": 2}, {}]


# ------------------------------------------------------------------ fit and identifiability
def _hostile_streams(case: str):
    """The seeded T-2 maneuver made hostile (as test_pipeline's cases): ``collinear`` rudder =
    elevator + 1e-6 rad; ``flat`` rudder at 0.01 rad +- 5e-5 (under the 1e-4 rad resolution, off
    zero); ``noise`` trim plus sensor noise (the regressors move a little, the outputs follow
    nothing)."""
    import dataclasses

    import numpy as np

    from rls_uncertainty.simulation.t2 import simulate_sensor_streams

    st = simulate_sensor_streams(0.2, 250)
    rng = np.random.default_rng(19)
    srf = st.control_surfaces[1].copy()
    if case == "collinear":
        srf[:, 4] = srf[:, 0] + rng.normal(0.0, 1e-6, srf.shape[0])
    elif case == "flat":
        srf[:, 4] = 0.01 + rng.normal(0.0, 5e-5, srf.shape[0])
    else:
        imu = st.imu[1].copy()
        imu[:, 1] = 0.002 * rng.standard_normal(imu.shape[0])
        imu[:, 5] = np.median(imu[:, 5]) + 0.02 * rng.standard_normal(imu.shape[0])
        srf[:, 0] = srf[:, 1] = 0.0005 * rng.standard_normal(srf.shape[0])
        vel = st.airspeed[1].copy()
        a = np.median(np.arctan2(-vel[:, 2], vel[:, 0])) + 0.001 * rng.standard_normal(vel.shape[0])
        speed = np.hypot(vel[:, 0], vel[:, 2])
        vel[:, 0], vel[:, 2] = speed * np.cos(a), -speed * np.sin(a)
        st = dataclasses.replace(st, imu=(st.imu[0], imu), airspeed=(st.airspeed[0], vel))
    return dataclasses.replace(st, control_surfaces=(st.control_surfaces[0], srf))


@pytest.mark.parametrize("case", ["collinear", "flat", "noise"])
def test_why_a_parameter_is_not_identifiable_is_read_from_the_published_figures_as_the_node_judged_it(case, tmp_path):
    """The node's own arrays (its encoder after a run of the node's pipeline on a hostile
    bag) and /diagnostics into the hub: each parameter's reason names what the node's
    identifiability monitor found (its problems, not the arrays), and the figures it shows."""
    from rls_uncertainty.datapath.cdr import FLOAT64_MULTIARRAY, decode
    from rls_uncertainty.datapath.outputs import FIT_OUTPUTS, OutputLayout
    from rls_uncertainty.offline.bags import read_inputs, write_sensor_streams
    from rls_uncertainty.offline.replay import run_pipeline
    from rls_uncertainty.settings import load_parameters_file, node_config, pipeline_config

    params = load_parameters_file("t2")
    if case != "noise":  # the rudder in C_Z (the T-2 maneuver does not move it otherwise)
        params["models.CZ"] = ["1", "alpha", "delta_e", "delta_r"]
    bag = write_sensor_streams(tmp_path / "bag", _hostile_streams(case))
    result = run_pipeline(read_inputs(bag)[0], pipeline_config(params), record=False,
                          diagnostics=node_config(params))
    pipe = result.pipeline
    layout = OutputLayout.of(pipe)
    hub = Hub(Source("live", f"/{NODE_NAME}"))  # the replay's statuses are the root node's
    hub.add_diagnostics([(st.name, st.level, st.message, dict(st.values)) for st in result.diagnostics[-1][1]])
    arrays = [(ArrayKey(TIME_DOMAIN, *layout.fit_topics[i][0].split("/")), decode(FLOAT64_MULTIARRAY, raw), None)
              for i, raw in layout.encode_fit(pipe)]
    assert {a[0].suffix for a in arrays} == set(FIT_OUTPUTS)
    quality = {q["model"]: q for q in hub.add_arrays(arrays)}
    assert set(quality) == {"CZ", "Cm"}  # both models ready
    monitor = pipe.identifiability
    for j, (model, names) in enumerate(layout.models):
        params_shown = quality[model]["parameters"]
        assert list(params_shown) == list(names)
        assert [p["identifiable"] for p in params_shown.values()] == monitor.identifiable[j, :len(names)].tolist()
        problems = monitor.problems(j)
        kinds = {p.kind for p in problems}
        reasons = {name: p["reason"] for name, p in params_shown.items() if not p["identifiable"]}
        if not problems:
            assert reasons == {}
            continue
        if "no_fit" in kinds:
            r2 = problems[0].figures[0]
            assert set(reasons) == set(names)
            flat = {f"{model}_{r}" for p in problems if p.kind == "not_excited" for r in p.regressors}
            for name, text in reasons.items():
                assert text == (f"model explains nothing (R^2 {r2:.3f})" if name not in flat else text), name
            assert quality[model]["fit"]["r_squared"] == pytest.approx(r2, rel=1e-12)
        for p in problems:
            if p.kind == "not_excited":
                for r, std, res in zip(p.regressors, p.figures, p.limits, strict=True):
                    assert reasons[f"{model}_{r}"] == f"not excited (std {std:.2g}, resolution {res:.2g})"
                if "no_fit" not in kinds and not monitor.identifiable[j, 0]:  # the bias, its mean off zero
                    flat = ", ".join(f"{model}_{r}" for r in p.regressors)
                    assert reasons[f"{model}_0"] == f"confounded with {flat} (not excited, off zero)"
            elif p.kind == "collinear":
                a, b = (f"{model}_{r}" for r in p.regressors)
                assert reasons[a] == f"correlated {p.figures[0]:.4f} with {b}"
                assert reasons[b] == f"correlated {p.figures[0]:.4f} with {a}"
        assert quality[model]["node_text"] == pipe.model_report(j)["identifiability"]
    # Sensor noise only: nothing fits, and the regressors move no more than their sensors' noise.
    expected = {"collinear": {"collinear"}, "flat": {"not_excited"}, "noise": {"no_fit", "noise"}}[case]
    assert {p.kind for j in range(len(layout.models)) for p in monitor.problems(j)} == expected


# ------------------------------------------------------------------ the page's states
def _live_hub():
    return Hub(Source("live", "/ns/rls_estimator", domain="25", discovery_range="LOCALHOST"))


def test_the_page_says_which_domain_was_searched_when_no_node_is_seen():
    hub = _live_hub()
    msg = hub.set_graph(False)
    assert msg["state"] == "no_node"
    assert "/ns/rls_estimator" in msg["text"] and "ROS_DOMAIN_ID=25" in msg["text"] and "LOCALHOST" in msg["text"]
    assert hub.set_graph(False) is None  # unchanged: nothing to push


def test_the_page_says_why_a_seen_node_has_no_samples_from_its_diagnostics():
    hub = _live_hub()
    assert hub.set_graph(True)["state"] == "waiting_diagnostics"
    ns = "/ns/rls_estimator"  # a namespaced node names its statuses with its full name
    statuses = [*_inputs({"missing_joint": 40}, 40, prefix=ns),
                (f"{ns}: samples", 0, "0 of 0 samples used", {"samples_formed": "0"}),
                (f"{ns}: model CZ", 0, "initializing: regressors not yet informative", {"ready": "False"})]
    statuses[0] = (statuses[0][0], 1, "control_surfaces rejected 40 in the last 10 s", statuses[0][3])
    msg = hub.add_diagnostics(statuses)
    assert msg["state"] == "no_samples"
    assert "control_surfaces rejected 40" in msg["text"] and "CZ: initializing" in msg["text"]
    # A node that used samples before the dashboard joined, with outputs not kept for it.
    statuses[1] = (statuses[1][0], 0, "591 of 599 samples used", {"samples_used": "591"})
    msg = hub.add_diagnostics(statuses)
    assert msg["state"] == "no_samples" and "has used 591 samples, none received here yet" in msg["text"]


def test_the_page_says_when_the_node_it_showed_is_gone():
    hub = _live_hub()
    hub.set_graph(True)
    hub.add_arrays(_arrays([10]))
    assert hub.state()["state"] == "running"
    msg = hub.set_graph(False)
    assert msg["state"] == "node_lost" and "ROS_DOMAIN_ID=25" in msg["text"] and "last ones" in msg["text"]
    assert _page_of(hub.snapshot_messages())["methods"][TIME_DOMAIN]["CZ"]["t"] == [1e-8]  # its last values stay


def test_the_samples_counted_are_the_nodes_not_its_models_arrays():
    hub = _live_hub()
    hub.set_graph(True)
    hub.add_arrays(_arrays(range(1, 11)) + _arrays(range(3, 11), model="Cm"))  # Cm ready two samples later
    assert hub.samples_total == 18
    assert hub.state()["text"].endswith(": 10 samples received")


def test_the_first_samples_turn_the_banner_to_running_at_once():
    """A late joiner hears the node's diagnostics ("none received here yet") before its kept
    samples: the samples themselves change the banner, not the next diagnostics a second later."""
    from rls_uncertainty.dashboard.app import _Dispatch
    from rls_uncertainty.dashboard.feed import Feed

    hub = _live_hub()
    sent: list[dict] = []
    feed = Feed(hub)
    feed.send = sent.append  # type: ignore[method-assign]
    dispatch = _Dispatch(hub, feed)
    dispatch([("graph", True)])
    ns = "/ns/rls_estimator"
    dispatch([("diagnostics", [*_inputs({}, 40, prefix=ns),
                               (f"{ns}: samples", 0, "591 of 599 samples used", {"samples_used": "591"})])])
    assert sent[-1]["state"] == "no_samples"
    sent.clear()
    dispatch([("array", *a) for a in _arrays([10])])
    assert [m["type"] for m in sent] == ["samples", "health"] and sent[-1]["state"] == "running"
    sent.clear()
    dispatch([("array", *a) for a in _arrays([11])])  # no change of state: no health message
    assert [m["type"] for m in sent] == ["samples"]


def test_samples_that_arrive_before_discovery_names_the_node_are_running_not_lost():
    hub = _live_hub()
    hub.set_graph(False)  # its name not discovered yet (a busy machine), its samples already here
    hub.add_arrays(_arrays([10]))
    assert hub.state()["state"] == "running"
    hub.set_graph(True)
    assert hub.set_graph(False)["state"] == "node_lost"


def test_the_inbox_hands_items_from_another_thread_to_the_loop_in_order_and_batches():
    import asyncio
    import threading

    from rls_uncertainty.dashboard.server import Inbox

    async def main():
        got: list[list[int]] = []
        done = asyncio.Event()
        loop = asyncio.get_running_loop()

        def handler(items):
            got.append(items)
            if items[-1] == 9999:
                done.set()

        inbox = Inbox(loop, handler)
        producer = threading.Thread(target=lambda: [inbox.put(k) for k in range(10_000)])
        producer.start()
        await asyncio.wait_for(done.wait(), 30)
        producer.join()
        return got

    got = asyncio.run(main())
    assert [k for batch in got for k in batch] == list(range(10_000))
    assert len(got) < 10_000  # batched: one wake-up per batch, not per item


def test_a_hub_sends_samples_as_columns_and_restarts_a_model_whose_time_goes_back():
    hub = _live_hub()
    (msg,) = hub.add_arrays(_arrays([10, 20], published=99))
    assert msg["type"] == "samples" and msg["method"] == TIME_DOMAIN and msg["published_ns"] == 99
    cols = msg["models"]["CZ"]
    assert cols["names"] == list(NAMES) and cols["t"] == [1e-8, 2e-8]
    assert cols["se"][1] == [_values(10, "standard_errors")[1], _values(20, "standard_errors")[1]]
    hub.add_arrays(_arrays([5]))
    assert hub.history_resets == 1 and hub.histories[(TIME_DOMAIN, "CZ")].size == 1
    assert _page_of(hub.snapshot_messages())["methods"][TIME_DOMAIN]["CZ"]["t"] == [5e-9]
    assert hub.add_arrays([(_key("estimates"), None, None)]) == [] and hub.pairing.dropped == {"undecodable": 1}


def test_a_sample_completed_after_a_newer_one_is_dropped_and_counted_not_taken_for_a_restart():
    """A late joiner's burst of kept samples may complete a sample after a newer one (a late
    partner array): it is dropped and counted, the history stays; a sample older than the
    pairing window is a restart (a looped replay), as before."""
    hub = _live_hub()
    stamps = [1000 + 10 * k for k in range(MAX_PENDING + 5)]
    hub.add_arrays(_arrays(stamps[:-2]))
    (msg,) = hub.add_arrays(_arrays([stamps[-1], stamps[-2]]))  # the newer completes first
    assert msg["models"]["CZ"]["t"] == [stamps[-1] * 1e-9]
    assert hub.pairing.dropped == {"out_of_order": 1} and hub.history_resets == 0
    assert hub.histories[(TIME_DOMAIN, "CZ")].last_stamp == stamps[-1]
    hub.add_arrays(_arrays([stamps[-1]]))  # a duplicate of the newest
    assert hub.pairing.dropped == {"out_of_order": 2} and hub.history_resets == 0
    hub.add_arrays(_arrays([stamps[-MAX_PENDING - 3]]))  # behind the window: time went back
    assert hub.history_resets == 1 and hub.histories[(TIME_DOMAIN, "CZ")].size == 1


# ------------------------------------------------------------------ options
def test_node_names_are_checked_and_made_absolute():
    assert full_node_name("rls_estimator") == "/rls_estimator"
    assert full_node_name("/ns/rls_estimator") == "/ns/rls_estimator"
    for bad in ("", "/", "/ns//x", "/1node", "/ns/rls estimator", "/ns/"):
        with pytest.raises(ConfigError, match="--node"):
            full_node_name(bad)


def test_reference_values_are_a_mapping_of_names_to_finite_numbers(tmp_path):
    good = tmp_path / "ref.yaml"
    good.write_text("CZ_alpha: -3.911\nCm_q: -53.25\n")
    assert load_reference(good) == {"CZ_alpha": -3.911, "Cm_q": -53.25}
    for text in ("[1, 2]\n", "CZ_alpha: .nan\n", "CZ_alpha: fast\n", "CZ_alpha: true\n", ""):
        bad = tmp_path / "bad.yaml"
        bad.write_text(text)
        with pytest.raises(ConfigError, match="--reference"):
            load_reference(bad)


# ------------------------------------------------------------------ replay
@pytest.fixture(scope="module")
def t2_replay(tmp_path_factory):
    from rls_uncertainty.offline.replay import replay
    from rls_uncertainty.settings import load_parameters_file

    out = tmp_path_factory.mktemp("t2") / "est"
    replay(ROOT / "bags" / "t2_maneuver", load_parameters_file("t2"), out, progress=False, plots=False)
    return out


def _read(directory, hub_capacity=None, deliver=None):
    """Read a replay directory through the dashboard's own path (source thread -> event loop
    -> dispatch -> hub), to its end; the hub and the batches as delivered."""
    import asyncio

    from rls_uncertainty.dashboard.app import _Dispatch
    from rls_uncertainty.dashboard.feed import Feed
    from rls_uncertainty.dashboard.replay_source import open_replay

    source = open_replay(directory)
    hub = Hub(Source("replay", source.node, replay_dir=str(directory), replay_file=source.file),
              capacity=hub_capacity)
    dispatch = _Dispatch(hub, Feed(hub))
    batches: list[int] = []

    async def main():
        done = asyncio.Event()

        def handle(items):
            batches.append(len(items))
            if deliver is not None:
                deliver(items)
            dispatch(items)
            if items[-1][0] == "replay_done":
                done.set()

        source.start(asyncio.get_running_loop().call_soon_threadsafe, handle)
        try:
            await asyncio.wait_for(done.wait(), 120)
        finally:
            source.stop()

    asyncio.run(main())
    return hub, batches


def _csv_rows(path):
    with open(path, newline="") as fh:
        return list(csv.DictReader(fh))


def _shown_rows(rows):
    """The rows of the samples the page shows: a sample (the rows of one time and model) with a
    standard error of 0 or less is refused; and how many were."""
    bad = {(r["time"], r["model"]) for r in rows
           if float(r["std_error"]) <= 0 or float(r["std_error_conventional"]) <= 0}
    return [r for r in rows if (r["time"], r["model"]) not in bad], len(bad)


def _expect_csv(hub, rows, method=TIME_DOMAIN):
    """Every sample of every model of ``method`` equals the CSV's rows (the same doubles: CSV
    writes repr), but those refused for a standard error of 0 or less."""
    rows, _refused = _shown_rows(rows)
    assert {m for which, m in hub.histories if which == method} == {r["model"] for r in rows}
    for (which, model), h in hub.histories.items():
        if which != method:
            continue
        cols = h.columns()
        mine = [r for r in rows if r["model"] == model]
        assert len(cols["t"]) * len(cols["names"]) == len(mine)  # every sample, none thinned
        n = len(cols["names"])
        for k, r in enumerate(mine):
            i, sample = k % n, k // n
            assert r["parameter"] == cols["names"][i]
            assert float(r["time"]) == pytest.approx(cols["t"][sample], abs=5e-7)  # s since 1970: ulp 2.4e-7
            assert float(r["estimate"]) == cols["estimate"][i][sample]
            assert float(r["std_error"]) == cols["se"][i][sample]
            assert float(r["std_error_conventional"]) == cols["se_conventional"][i][sample]
            assert float(r["converged"]) == cols["converged"][i][sample]


def _last_fits(path):
    """The last ~/M/fit and ~/M/identifiability of an estimates.mcap, read with rosbags."""
    from rosbags.highlevel import AnyReader

    from rls_uncertainty.offline.bags import typestore

    last = {}
    with AnyReader([path], default_typestore=typestore()) as reader:
        conns = [c for c in reader.connections if c.topic.endswith(("/fit", "/identifiability"))]
        for conn, _t, raw in reader.messages(connections=conns):
            last[tuple(conn.topic.rsplit("/", 2)[1:])] = reader.deserialize(raw, conn.msgtype)
    return last


def test_a_finished_replay_is_read_as_a_stream_with_every_sample_of_its_estimates_csv_and_its_fits(t2_replay):
    hub, _batches = _read(t2_replay)
    assert hub.source.node == f"/{NODE_NAME}" and hub.source.replay_file == "estimates.mcap"
    _expect_csv(hub, _csv_rows(t2_replay / "estimates.csv"))
    assert hub.state()["state"] == "replay" and hub.health.latest is not None and hub.pairing.dropped == {}
    last = _last_fits(t2_replay / "estimates.mcap")
    assert {m for m, _suffix in last} == {"CZ", "Cm"}
    for (model, suffix), msg in last.items():
        if suffix == "fit":
            fit = hub.fits[(TIME_DOMAIN, model)]
            assert [fit.r_squared, fit.samples, fit.bound_2sigma, *fit.rho] == msg.data.tolist()
        else:
            table = hub.tables[(TIME_DOMAIN, model)]
            n = len(table.names)
            rows = msg.data.reshape(n, n + 3)
            assert table.names == tuple(msg.layout.dim[0].label.split(","))
            assert [list(r) for r in table.correlation] == rows[:, :n].tolist()
            assert list(table.excitation) == rows[:, n].tolist() and list(table.identifiable) == [True] * n
    quality = {q["model"]: q for q in _page_of(hub.snapshot_messages())["quality"]}
    for model in ("CZ", "Cm"):  # the seeded T-2 maneuver identifies every parameter
        assert all(p["identifiable"] and p["reason"] == "" for p in quality[model]["parameters"].values())
        assert quality[model]["fit"]["r_squared"] == hub.fits[(TIME_DOMAIN, model)].r_squared


def test_the_replay_reader_stays_a_bounded_number_of_batches_ahead_of_the_page(t2_replay, monkeypatch):
    """Memory does not grow with the recording: the reading thread waits while IN_FLIGHT
    batches are not handled yet (a slow event loop), instead of queueing the file."""
    import time as _time

    from rls_uncertainty.dashboard import replay_source

    monkeypatch.setattr(replay_source, "BATCH", 100)
    produced = [0]
    ahead = []
    original = replay_source.ReplaySource.__init__

    def counting_init(self, directory, file, node, items):
        def counted():
            for item in items():
                produced[0] += 1
                yield item
        original(self, directory, file, node, counted)

    monkeypatch.setattr(replay_source.ReplaySource, "__init__", counting_init)
    consumed = [0]

    def slow(items):
        consumed[0] += len(items)
        ahead.append(produced[0] - consumed[0])
        _time.sleep(0.01)  # slower than the reader: without the wait it would run through the file

    hub, batches = _read(t2_replay, deliver=slow)
    # The file is many times what may be in flight (so reading it through would show), and the
    # reader never got further ahead than that.
    assert len(batches) > 10 * (replay_source.IN_FLIGHT + 1) and max(ahead) <= (replay_source.IN_FLIGHT + 1) * 100
    _expect_csv(hub, _csv_rows(t2_replay / "estimates.csv"))


def test_a_replay_directory_with_only_estimates_csv_is_shown_and_says_what_is_missing(t2_replay, tmp_path):
    only = tmp_path / "csv_only"
    only.mkdir()
    (only / "estimates.csv").write_bytes((t2_replay / "estimates.csv").read_bytes())
    hub, _ = _read(only)
    rows = _csv_rows(only / "estimates.csv")
    _expect_csv(hub, rows)
    state = hub.state()
    assert state["state"] == "replay" and "from estimates.csv (no estimates.mcap" in state["text"]
    assert not hub.fits and hub.health.latest is None
    # A damaged row ends the reading there, named; the samples before it stay shown.
    lines = (only / "estimates.csv").read_text().splitlines(keepends=True)
    lines[100] = lines[100].replace(lines[100].split(",")[3], "nan", 1)
    (only / "estimates.csv").write_text("".join(lines))
    hub, _ = _read(only)
    state = hub.state()
    assert state["state"] == "replay_error" and "estimates.csv: line 101: not a row of estimates.csv" in state["text"]
    assert 0 < hub.samples_total < len({(r["time"], r["model"]) for r in rows})


def test_a_directory_without_replay_outputs_is_refused_with_the_reason(tmp_path):
    from rls_uncertainty.dashboard.replay_source import open_replay
    from rls_uncertainty.errors import BagError

    with pytest.raises(BagError, match=r"no estimates\.mcap, estimates\.csv or estimates_frequency\.csv"):
        open_replay(tmp_path)
    (tmp_path / "estimates.csv").write_text("a,b\n1,2\n")
    with pytest.raises(BagError, match=r"not the estimates\.csv of rls-uncertainty replay"):
        open_replay(tmp_path)


# ------------------------------------------------------------------ hostile replays
def _hostile(directory: Path, header: str, lines) -> Path:
    directory.mkdir()
    with open(directory / "estimates.csv", "w") as fh:
        fh.write(header)
        fh.writelines(lines)
    return directory


def _first_samples(t2_replay, samples: int) -> tuple[str, list[str]]:
    """The header and the rows of the first ``samples`` sample times of a replay's estimates.csv."""
    header, *rows = (t2_replay / "estimates.csv").read_text().splitlines(keepends=True)
    times = list(dict.fromkeys(r.split(",", 1)[0] for r in rows))[:samples]
    return header, [r for r in rows if r.split(",", 1)[0] in set(times)]


@pytest.mark.parametrize("case", ["models", "parameters", "time", "short", "repeated", "nan", "inf", "cut"])
def test_a_hostile_replay_csv_ends_the_reading_at_the_line_named_never_a_traceback(t2_replay, tmp_path, case,
                                                                                   capsys):
    """What rls-uncertainty replay never writes: more models than Eq. 2 has (here the 100,000
    names of an attack, cut short at the seventh), one sample with 50,000 parameters, a time of
    1e30 s, a last sample missing a row or repeating one, a value NaN or inf, a row cut short.
    The reading ends at the line named, on the page's banner and in one line on stderr; the
    samples before it are shown; memory stays that of the rows read."""
    from rls_uncertainty.dashboard.model import MAX_MODELS, MAX_PARAMETERS

    header, rows = _first_samples(t2_replay, 100)
    t0 = 1767225600
    if case == "models":
        lines = [f"{t0 + i // 50}.{(i % 50) * 20_000_000:09d},M{i},M{i}_0,0.5,0.01,0.005,0,2\n" for i in range(100_000)]
        bad, why = MAX_MODELS + 2, rf"a model more \('M{MAX_MODELS}'\) than the {MAX_MODELS} of Eq. 2"
    elif case == "parameters":
        lines = [f"{t0}.000000000,CZ,P{i},0.5,0.01,0.005,0,2\n" for i in range(50_000)]
        bad, why = MAX_PARAMETERS + 2, rf"CZ at {t0}.000000000 s has more than {MAX_PARAMETERS} parameters"
    elif case == "time":
        last = [r for r in rows if r.split(",", 1)[0] == rows[-1].split(",", 1)[0]]
        lines = rows + ["1" + "0" * 30 + ".000000000," + r.split(",", 1)[1] for r in last]
        bad, why = len(rows) + 2, r"time '1000000000000000000000000000000.000000000' s is after the year 2262"
    elif case in ("short", "repeated"):
        lines = rows[:-1] if case == "short" else [*rows, rows[-1]]
        model = rows[-1].split(",")[1]
        start = next(i for i, r in enumerate(lines) if r.split(",")[:2] == rows[-1].split(",")[:2])
        bad, why = start + 2, rf"{model} at .* has the parameters .*, its first sample \(line \d+\)"
    else:
        lines = list(rows)
        k = len(rows) // 2
        if case == "cut":
            lines[k] = ",".join(lines[k].split(",")[:4]) + "\n"
        else:
            parts = lines[k].split(",")
            parts[3] = case
            lines[k] = ",".join(parts)
        bad, why = k + 2, r"not a row of estimates.csv \((values|time)"
    directory = _hostile(tmp_path / case, header, lines)
    hub, _ = _read(directory)
    state = hub.state()
    assert state["state"] == "replay_error"
    assert re.search(rf"estimates.csv: line {bad}: .*{why}", state["text"]), state["text"]
    err = capsys.readouterr().err
    assert len(err.splitlines()) == 1 and f"line {bad}:" in err and "Traceback" not in err
    held = sum(h.size for h in hub.histories.values())
    assert 0 < held <= 100 * MAX_MODELS or (case == "parameters" and held == 0)


def test_samples_with_a_standard_error_of_zero_or_less_are_refused_counted_and_said(t2_replay, tmp_path, capsys):
    """Rows with a standard error of -5 or 0: their samples are not drawn (no band to draw);
    the page's banner and one line on stderr say how many were refused and why."""
    header, rows = _first_samples(t2_replay, 100)
    lines = []
    for k, r in enumerate(rows):
        parts = r.split(",")
        if k % 7 in (0, 1):
            parts[4 if k % 2 else 5] = "-5" if k % 7 == 0 else "0"
        lines.append(",".join(parts))
    directory = _hostile(tmp_path / "se", header, lines)
    hub, _ = _read(directory)
    shown, refused = _shown_rows(_csv_rows(directory / "estimates.csv"))
    assert refused > 10
    _expect_csv(hub, shown)
    held = [h.columns()[q] for h in hub.histories.values() for q in ("se", "se_conventional")]
    assert min(min(column) for columns in held for column in columns) > 0
    text = f"{refused} samples refused, not drawn (a standard error of 0 or less: {refused})"
    assert hub.refused == {"se_not_positive": refused} and hub.state()["state"] == "replay"
    assert text in hub.state()["text"]
    assert capsys.readouterr().err == f"rls-uncertainty dashboard: {directory}: {text}\n"


def test_whatever_a_file_provokes_while_shown_ends_the_reading_on_the_page(t2_replay, tmp_path, monkeypatch):
    """A failure met while the read samples are shown (here provoked) ends the reading with the
    file and the error on the banner: never a page left at "reading"."""
    only = tmp_path / "csv_only"
    only.mkdir()
    (only / "estimates.csv").write_bytes((t2_replay / "estimates.csv").read_bytes())

    def broken(self, samples):
        raise RuntimeError("provoked")

    monkeypatch.setattr(Hub, "add_samples", broken)
    hub, _ = _read(only)
    assert hub.state()["state"] == "replay_error"
    assert hub.state()["text"].endswith("then estimates.csv: cannot be shown (RuntimeError: provoked)")


def test_a_live_node_beyond_eq_2_is_bounded_and_counted():
    """Arrays of a seventh model of a method, or of more parameters than Eq. 2 has regressors,
    are dropped before pairing; samples with a standard error of 0 or less, or a time beyond
    int64 nanoseconds, are refused: counted, never stored."""
    from rls_uncertainty.dashboard.model import MAX_MODELS, MAX_PARAMETERS

    hub = _live_hub()
    for k in range(MAX_MODELS + 3):
        hub.add_arrays(_arrays([10], model=f"M{k}"))
    assert len(hub.histories) == MAX_MODELS and hub.pairing.dropped == {"too_many_models": 3 * len(PAIRED)}
    wide = ",".join(f"CZ_{i}" for i in range(MAX_PARAMETERS + 1))
    hub.add_arrays([(_key(suffix, "M0"), _msg(wide, [1.0] * (MAX_PARAMETERS + 1), stamp_label(20)), None)
                    for suffix in PAIRED])
    assert hub.pairing.dropped["too_many_parameters"] == len(PAIRED)
    zero = [(_key(s, "M1"), _msg(",".join(NAMES), [0.0 if s == "standard_errors" else 1.0] * 3, stamp_label(30)),
             None) for s in PAIRED]
    late = [(_key(s, "M2"), _msg(",".join(NAMES), [1.0] * 3, "stamp:99999999999.000000000"), None) for s in PAIRED]
    assert hub.add_arrays(zero + late) == []
    assert hub.refused == {"se_not_positive": 1, "time_out_of_range": 1}
    assert all(h.size == 1 for h in hub.histories.values())


def test_large_batches_are_sent_in_bounded_pieces_counted_and_restarts_send_only_the_new_history():
    """A replay's batch of thousands of samples is sent as several messages of at most
    FRAME_VALUES numbers, each model's ``count`` the samples shown up to its last one; a batch
    in which a model's time goes back sends only what follows the restart: the page rebuilt
    from the messages holds the hub's history."""
    from rls_uncertainty.dashboard.messages import FRAME_VALUES

    hub = _live_hub()
    samples = [Sample("CZ", 1000 + 10 * k, NAMES, (k, 0, 0), (1, 1, 1), (1, 1, 1), (0, 0, 0), None)
               for k in range(3000)]
    messages = hub.add_samples(samples)
    assert len(messages) > 3
    assert all(sum(len(c["t"]) * (1 + 4 * len(c["names"])) for c in m["models"].values()) <= FRAME_VALUES
               for m in messages)
    counts = [m["models"]["CZ"]["count"] for m in messages]
    assert counts == sorted(counts) and counts[-1] == 3000
    page = _page_of(messages)
    assert page["methods"][TIME_DOMAIN]["CZ"]["estimate"][0] == list(range(3000))
    again = [Sample("CZ", 5 + k, NAMES, (-k, 0, 0), (1, 1, 1), (1, 1, 1), (0, 0, 0), None) for k in range(3)]
    more = hub.add_samples([*samples[-1:], *again])  # a duplicate, then time back: a restart
    assert [len(m["models"]["CZ"]["t"]) for m in more] == [3] and hub.history_resets == 1
    page = _page_of(messages + more)
    assert page["methods"][TIME_DOMAIN]["CZ"]["estimate"][0] == [0, -1, -2]
    assert page["counts"][(TIME_DOMAIN, "CZ")] == 3003 == hub.counts()[TIME_DOMAIN]["CZ"]


# ------------------------------------------------------------------ both methods
@pytest.fixture(scope="module")
def t2_both(tmp_path_factory):
    """The bundled bag replayed with both estimators (estimator.method both)."""
    from rls_uncertainty.offline.replay import replay
    from rls_uncertainty.settings import load_parameters_file

    out = tmp_path_factory.mktemp("t2_both") / "est"
    replay(ROOT / "bags" / "t2_maneuver", {**load_parameters_file("t2"), "estimator.method": "both"}, out,
           progress=False, plots=False)
    return out


def _expect_frequency_csv(hub, directory):
    """The frequency-domain histories equal estimates_frequency.csv, read here with the csv
    module: per model the parameters without the bias, every sample of the file but those with
    a standard error of 0 (the first of each model here: its corrected SE is 0 at the first
    lags), which are refused and counted."""
    rows = _csv_rows(directory / "estimates_frequency.csv")
    assert rows and not any(r["parameter"].endswith("_0") for r in rows)  # no bias in the frequency domain
    _expect_csv(hub, rows, FREQUENCY_DOMAIN)
    time_rows = _csv_rows(directory / "estimates.csv") if (directory / "estimates.csv").is_file() else []
    refused = _shown_rows(rows)[1] + _shown_rows(time_rows)[1]
    assert hub.refused == ({"se_not_positive": refused} if refused else {})
    for model in {r["model"] for r in rows}:  # and the last values, as the page shows them
        last_time = max(r["time"] for r in rows if r["model"] == model)
        last = {r["parameter"]: r for r in rows if r["model"] == model and r["time"] == last_time}
        cols = hub.histories[(FREQUENCY_DOMAIN, model)].columns()
        assert cols["names"] == list(last)
        for i, name in enumerate(cols["names"]):
            assert cols["estimate"][i][-1] == float(last[name]["estimate"])
            assert cols["se"][i][-1] == float(last[name]["std_error"])


def test_a_replay_of_both_methods_shows_each_methods_estimates_as_its_csv_has_them(t2_both, tmp_path):
    hub, _ = _read(t2_both)  # estimates.mcap: ~/M/... and ~/M/frequency/...
    assert hub.source.replay_file == "estimates.mcap" and hub.pairing.dropped == {}
    assert {method for method, _ in hub.histories} == {TIME_DOMAIN, FREQUENCY_DOMAIN}
    _expect_csv(hub, _csv_rows(t2_both / "estimates.csv"))
    _expect_frequency_csv(hub, t2_both)
    assert not any(method == FREQUENCY_DOMAIN for method, _ in hub.fits)  # fits are the time domain's
    # The CSV files alone: both read, merged in time order.
    only = tmp_path / "csv_only"
    only.mkdir()
    for name in ("estimates.csv", "estimates_frequency.csv"):
        (only / name).write_bytes((t2_both / name).read_bytes())
    hub, _ = _read(only)
    assert hub.source.replay_file == "estimates.csv and estimates_frequency.csv"
    _expect_csv(hub, _csv_rows(only / "estimates.csv"))
    _expect_frequency_csv(hub, only)
    assert "from estimates.csv and estimates_frequency.csv (no estimates.mcap" in hub.state()["text"]
    # A frequency-only replay (estimator.method frequency writes no estimates.csv).
    (only / "estimates.csv").unlink()
    hub, _ = _read(only)
    assert {method for method, _ in hub.histories} == {FREQUENCY_DOMAIN}
    _expect_frequency_csv(hub, only)
    # A damaged row of the frequency file is named, with its file.
    lines = (only / "estimates_frequency.csv").read_text().splitlines(keepends=True)
    lines[50] = lines[50].replace(lines[50].split(",")[3], "inf", 1)
    (only / "estimates_frequency.csv").write_text("".join(lines))
    hub, _ = _read(only)
    assert "estimates_frequency.csv: line 51: not a row of estimates_frequency.csv" in hub.state()["text"]


def test_a_reset_of_the_node_clears_what_the_page_shows_and_the_snapshot():
    """The node's reset shows in its /diagnostics (the samples status's ``resets.<reason>``
    counters grow): the hub forgets the histories and fits it showed, the page is told once
    (``take_reset``), and a page that connects afterwards gets an empty snapshot; a dashboard
    that joins a node that reset before it does not clear anything."""
    ns = "/ns/rls_estimator"

    def diagnostics(resets: dict[str, int]):
        values = {"samples_used": "30", **{f"resets.{k}": str(n) for k, n in resets.items()}}
        return [*_inputs({}, 0, prefix=ns), (f"{ns}: samples", 0, "30 of 30 samples used", values)]

    hub = _live_hub()
    hub.set_graph(True)
    hub.add_diagnostics(diagnostics({"service": 2}))  # resets before this dashboard joined
    assert not hub.take_reset()
    hub.add_arrays(_arrays(range(1, 11)))
    assert _page_of(hub.snapshot_messages())["methods"][TIME_DOMAIN]["CZ"]["t"] != []
    hub.add_diagnostics(diagnostics({"service": 2}))
    assert not hub.take_reset() and hub.histories
    hub.add_diagnostics(diagnostics({"service": 2, "time_jumped_backwards": 1}))
    assert hub.take_reset() and not hub.take_reset()  # told once
    assert _page_of(hub.snapshot_messages())["methods"] == {}
    hub.add_arrays(_arrays(range(20, 25)))  # the restarted estimator's samples
    assert _page_of(hub.snapshot_messages())["methods"][TIME_DOMAIN]["CZ"]["t"] == pytest.approx(
        [k * 1e-9 for k in range(20, 25)])
