"""The dashboard without ROS and without a browser: arrays paired by the stamp they carry (never
by arrival), bounded histories, the node's /diagnostics read back (against the node's own
diagnostics policy on the bundled bag), the page's states, and a finished replay read back
equal to its estimates.csv."""

from __future__ import annotations

import csv
import random
from pathlib import Path
from types import SimpleNamespace

import pytest

from rls_uncertainty.config import NODE_NAME
from rls_uncertainty.dashboard.health import HealthTracker, parse_statuses
from rls_uncertainty.dashboard.hub import Hub, Source
from rls_uncertainty.dashboard.model import (
    MAX_PENDING,
    PAIRED,
    ArrayUpdate,
    ModelHistory,
    Pairing,
    Sample,
    array_update,
)
from rls_uncertainty.dashboard.settings import full_node_name, load_reference
from rls_uncertainty.errors import ConfigError
from rls_uncertainty.inputs import STREAMS
from rls_uncertainty.outputs import stamp_label

ROOT = Path(__file__).resolve().parents[1]
NAMES = ("CZ_0", "CZ_alpha", "CZ_delta_e")


def _values(stamp: int, suffix: str) -> tuple[float, ...]:
    """A distinct, checkable value for each stamp, array and parameter."""
    return tuple(stamp * 1e-9 + PAIRED.index(suffix) * 100 + i for i in range(len(NAMES)))


def _update(stamp: int, suffix: str, model: str = "CZ") -> ArrayUpdate:
    return ArrayUpdate(model, suffix, NAMES, _values(stamp, suffix), stamp)


def _msg(names: str, data, *labels: str):
    """A Float64MultiArray as rclpy and rosbags present it (read by field name)."""
    dims = [SimpleNamespace(label=label, size=1, stride=1) for label in (names, *labels)]
    return SimpleNamespace(layout=SimpleNamespace(dim=dims, data_offset=0), data=list(data))


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
    u = array_update("Cm", "estimates", _msg("Cm_0,Cm_q", [1.5, -40.0], stamp_label(stamp)), 7)
    assert (u.names, u.data, u.stamp_ns, u.published_ns) == (("Cm_0", "Cm_q"), (1.5, -40.0), stamp, 7)
    for msg in (_msg("Cm_0", [1.0]), _msg("Cm_0", [1.0], "time:1.0")):
        msg.layout.dim = msg.layout.dim[:1] if len(msg.layout.dim) == 1 else msg.layout.dim
        with pytest.raises(ValueError):
            array_update("Cm", "estimates", msg)


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
    from rls_uncertainty.bags import read_inputs
    from rls_uncertainty.config import load_parameters_file, node_config, pipeline_config
    from rls_uncertainty.replay import run_pipeline

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
    from rls_uncertainty.config import load_parameters_file, pipeline_config
    from rls_uncertainty.diagnostics import Snapshot
    from rls_uncertainty.pipeline import Pipeline

    pipe = Pipeline(pipeline_config(load_parameters_file("t2")))
    return Snapshot(counters=pipe.counters(), models=[(m.output, pipe.model_report(j)) for j, m in
                                                      enumerate(pipe.config.models)],
                    required=tuple(pipe.required), max_gap=0.1, now_ns=0, elapsed_s=1.0,
                    publishers=dict.fromkeys(STREAMS, 1), topics={k: f"/{k}" for k in STREAMS}, reliable=True,
                    enabled=enabled, state_file="no state file")


def test_statuses_of_namespaced_nodes_are_told_apart():
    """Three nodes named rls_estimator (root, /a, /b) report on one /diagnostics: each
    consumer reads its own node's statuses, named by the node's policy."""
    from rls_uncertainty.diagnostics import DiagnosticsPolicy

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


def test_the_page_says_when_the_node_it_showed_is_gone():
    hub = _live_hub()
    hub.set_graph(True)
    hub.add_arrays([("CZ", suffix, _msg(",".join(NAMES), _values(10, suffix), stamp_label(10)), None)
                    for suffix in PAIRED])
    assert hub.state()["state"] == "running"
    msg = hub.set_graph(False)
    assert msg["state"] == "node_lost" and "ROS_DOMAIN_ID=25" in msg["text"] and "last ones" in msg["text"]
    assert hub.snapshot()["models"]["CZ"]["t"] == [1e-8]  # its last values stay on the page


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
    arrays = [("CZ", suffix, _msg(",".join(NAMES), _values(s, suffix), stamp_label(s)), 99)
              for s in (10, 20) for suffix in PAIRED]
    msg = hub.add_arrays(arrays)
    assert msg["type"] == "samples" and msg["published_ns"] == 99
    cols = msg["models"]["CZ"]
    assert cols["names"] == list(NAMES) and cols["t"] == [1e-8, 2e-8]
    assert cols["se"][1] == [_values(10, "standard_errors")[1], _values(20, "standard_errors")[1]]
    hub.add_arrays([("CZ", suffix, _msg(",".join(NAMES), _values(5, suffix), stamp_label(5)), None)
                    for suffix in PAIRED])
    assert hub.history_resets == 1 and hub.histories["CZ"].size == 1
    assert hub.snapshot()["models"]["CZ"]["t"] == [5e-9]


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
def test_a_finished_replay_is_shown_with_the_values_of_its_estimates_csv(tmp_path):
    from rls_uncertainty.config import load_parameters_file
    from rls_uncertainty.dashboard.replay_source import read_replay
    from rls_uncertainty.replay import replay

    out = tmp_path / "est"
    replay(ROOT / "bags" / "t2_maneuver", load_parameters_file("t2"), out, progress=False, plots=False)
    node, items = read_replay(out)
    assert node == f"/{NODE_NAME}"
    hub = Hub(Source("replay", node, replay_dir=str(out)))
    hub.add_arrays([i[1:] for i in items if i[0] == "array"])
    for i in items:
        if i[0] == "diagnostics":
            hub.add_diagnostics(i[1])
    with open(out / "estimates.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))
    for model, h in hub.histories.items():
        cols = h.columns()
        mine = [r for r in rows if r["model"] == model]
        assert len(cols["t"]) * len(cols["names"]) == len(mine)  # every sample, none thinned
        last = mine[-len(cols["names"]):]
        for i, r in enumerate(last):
            assert r["parameter"] == cols["names"][i]
            assert float(r["estimate"]) == pytest.approx(cols["estimate"][i][-1], rel=1e-12, abs=1e-15)
            assert float(r["std_error"]) == pytest.approx(cols["se"][i][-1], rel=1e-12, abs=1e-15)
            assert float(r["std_error_conventional"]) == pytest.approx(cols["se_conventional"][i][-1], rel=1e-12)
            assert float(r["converged"]) == cols["converged"][i][-1]
    assert hub.state()["state"] == "replay" and hub.health.latest is not None


def test_a_directory_without_estimates_mcap_is_refused_with_the_reason(tmp_path):
    from rls_uncertainty.dashboard.replay_source import read_replay
    from rls_uncertainty.errors import BagError

    with pytest.raises(BagError, match=r"no estimates\.mcap"):
        read_replay(tmp_path)
