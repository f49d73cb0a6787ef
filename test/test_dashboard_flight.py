"""The flight so far on the dashboard page, in a real browser (the fixtures of
test_dashboard_browser.py): a simulated flight (``make-bag --flight``) replayed with its
test-point events and targets up to the middle of its fifth test point, then shown by
``rls-uncertainty dashboard --replay``: four maneuvers ended and the fifth running. The page's
Table 4 equals an independent computation from the replay's maneuvers.csv (per parameter the
mean and sample standard deviation of the estimates of status ok, the mean standard errors and
their ratios), its Fig. 12 draws every maneuver of each parameter, its maneuver list gives each
maneuver's verdict as maneuvers.csv records it, and its test-point card gives the node's last
targets and verdict from /diagnostics.

Screenshots go to the test's directory, and to $RLS_DASHBOARD_SCREENSHOTS when set
(docs/images/ was made so)."""

from __future__ import annotations

import csv
import math
from pathlib import Path

import numpy as np
import pytest
from test_dashboard_browser import Dashboard, _shot_of, _wait, browser  # noqa: F401 - browser: a fixture

TARGETS = "CZ_alpha=5,Cm_alpha=8,Cm_q=12"
SEED = 3


@pytest.fixture(scope="module")
def flight_replay(tmp_path_factory):
    """The simulated flight replayed with events and targets up to the middle of its fifth
    test point (its truth.csv's start and end)."""
    from rls_uncertainty import cli
    from rls_uncertainty.offline.replay import replay
    from rls_uncertainty.settings import load_parameters_file

    base = tmp_path_factory.mktemp("flight")
    assert cli.main(["make-bag", "--flight", "--out", str(base / "bag"), "--seed", str(SEED)]) == 0
    with open(base / "bag" / "truth.csv", newline="") as fh:
        truth = list(csv.DictReader(fh))
    params = {**load_parameters_file("t2"), "maneuvers.source": "events", "targets.percent": TARGETS}
    middle = (float(truth[4]["start"]) + float(truth[4]["end"])) / 2
    replay(base / "bag", params, base / "mid", end=middle, progress=False, plots=False)
    return base, truth


def _maneuvers_csv(path: Path) -> list[dict[str, str]]:
    with open(path / "maneuvers.csv", newline="") as fh:
        return list(csv.DictReader(fh))


def _table4_of(rows: list[dict[str, str]]) -> dict[str, dict[str, float]]:
    """Table 4 from maneuvers.csv by hand: per time-domain parameter over the rows of status ok."""
    out = {}
    for p in dict.fromkeys(r["parameter"] for r in rows):
        ok = [r for r in rows if r["parameter"] == p and r["method"] == "time" and r["status"] == "ok"]
        est = np.array([float(r["estimate"]) for r in ok])
        conv = np.array([float(r["se_conventional"]) for r in ok])
        corr = np.array([float(r["se_corrected"]) for r in ok])
        scatter = float(np.sqrt(np.sum((est - est.sum() / len(est)) ** 2) / (len(est) - 1)))
        out[p] = {"maneuvers": len(ok), "mean": float(np.sum(est) / len(est)), "scatter": scatter,
                  "se_conventional": float(np.sum(conv) / len(conv)), "se_corrected": float(np.sum(corr) / len(corr)),
                  "conventional_over_scatter": float(np.mean(conv)) / scatter,
                  "corrected_over_scatter": float(np.mean(corr)) / scatter}
    return out


def _page_table4(page) -> dict[str, dict[str, str]]:
    return page.evaluate("""() => Object.fromEntries([...document.querySelectorAll('#table4 tbody tr')]
        .map(tr => [tr.dataset.parameter, Object.fromEntries([...tr.querySelectorAll('td[data-col]')]
            .map(td => [td.dataset.col, td.dataset.value]))]))""")


def _last_targets(directory: Path) -> tuple[dict[str, str], str]:
    """The node's last target.<p> texts and verdict in the replay's /diagnostics."""
    from rosbags.highlevel import AnyReader

    from rls_uncertainty.offline.bags import typestore

    targets, verdict = {}, ""
    with AnyReader([directory / "estimates.mcap"], default_typestore=typestore()) as reader:
        conns = [c for c in reader.connections if c.topic == "/diagnostics"]
        for conn, _t, raw in reader.messages(connections=conns):
            for s in reader.deserialize(raw, conn.msgtype).status:
                for kv in s.values:
                    if kv.key.startswith("target."):
                        targets[kv.key[7:]] = kv.value
                    elif kv.key == "verdict":
                        verdict = kv.value
    return targets, verdict


# Writing and replaying the flight takes minutes on a busy 2-core machine (the setup counts).
@pytest.mark.timeout(1800)
def test_mid_flight_the_pages_table_4_is_the_one_of_the_replays_maneuvers_csv(tmp_path, browser, flight_replay):  # noqa: F811
    base, truth = flight_replay
    rows = _maneuvers_csv(base / "mid")
    names = list(dict.fromkeys(r["maneuver"] for r in rows))
    # Cut in the fifth test point: maneuvers.csv records it at the end of the data; the node's
    # history (estimates.mcap) has the four ended and the fifth running, as live at that instant.
    assert names == [t["maneuver"] for t in truth[:5]]
    ended = [r for r in rows if r["maneuver"] in names[:4]]
    targets, verdict = _last_targets(base / "mid")
    assert set(targets) == {t.split("=")[0] for t in TARGETS.split(",")} and verdict
    dashboard = Dashboard("--replay", "mid", cwd=base)
    try:
        browser.goto(dashboard.url)
        _wait(browser, "document.getElementById('banner').dataset.state === 'replay'", 300)
        _wait(browser, "document.getElementById('flight').dataset.maneuvers === '4'", 60)
        assert browser.text_content("#active") == f"running: {names[4]}"
        shown = _page_table4(browser)
        want = _table4_of(ended)
        assert set(shown) == set(want)
        for p, values in want.items():
            assert int(shown[p]["maneuvers"]) == values["maneuvers"] == 4, p
            for col, x in values.items():
                assert math.isclose(float(shown[p][col]), x, rel_tol=1e-12), (p, col, shown[p][col], x)
        # Fig. 12: one plot per parameter, one estimate per maneuver of status ok.
        drawn = browser.evaluate("""() => Object.fromEntries([...document.querySelectorAll('.fig12')]
            .map(f => [f.dataset.parameter, f.querySelectorAll('circle.estimate').length]))""")
        assert drawn == {p: v["maneuvers"] for p, v in want.items()}
        # Each maneuver's verdict as maneuvers.csv records it (targets set: never empty).
        verdicts = browser.evaluate("""() => Object.fromEntries([...document.querySelectorAll('#maneuver-list tr')]
            .filter(tr => tr.dataset.maneuver).map(tr => [tr.dataset.maneuver,
                tr.querySelector('td[data-col=verdict]').dataset.value]))""")
        recorded = {r["maneuver"]: r["verdict"] for r in ended}
        assert verdicts == recorded and all(v.split(" (")[0] in ("done", "needs more", "not identifiable")
                                            for v in recorded.values())
        # The test point running: the node's last targets and verdict.
        page_targets = browser.evaluate("""() => Object.fromEntries([...document.querySelectorAll('#targets tbody tr')]
            .map(tr => [tr.dataset.parameter, tr.querySelector('td[data-col=target]').dataset.value]))""")
        assert page_targets == targets
        assert browser.text_content("#verdict") == verdict
        _shot_of(browser, "#flight", tmp_path, "dashboard_flight_table4.png")
        _shot_of(browser, "#testpoint", tmp_path, "dashboard_flight_testpoint.png")
        # Between test points (the same history with none running) the estimator runs over trim:
        # the card gives the last test point's verdict at its end instead of targets; before the
        # first test point it waits.
        browser.evaluate("() => drawFlight({...window.rlsFlight.message, active: null})")
        assert browser.text_content("#verdict") == \
            f"between test points: the last, {names[3]}, ended {recorded[names[3]]}"
        assert browser.evaluate("() => document.querySelectorAll('#targets tbody tr').length") == 0
        browser.evaluate("() => drawFlight({...window.rlsFlight.message, active: null, maneuvers: [], table4: []})")
        assert browser.text_content("#verdict") == "waiting for the first test point"
    finally:
        dashboard.stop()


def _history(estimates: list[list[float]], status: str = "ok") -> str:
    """A ~/maneuvers message of maneuvers m1.. with one row per parameter p0.. (SEs from the estimate)."""
    import json

    return json.dumps({"source": "events", "recorded": len(estimates), "rejected": {}, "active": "next",
                       "maneuvers": [{"name": f"m{i + 1}", "start": 10.0 * i, "end": 10.0 * i + 8, "duration": 8.0,
                                      "rows": [{"model": "Cm", "parameter": f"p{j}", "method": "time", "estimate": e,
                                                "se_conventional": abs(e) / 40, "se_corrected": abs(e) / 10,
                                                "se_corrected_all": None, "samples": 400, "r_squared": 0.9,
                                                "status": status if i else "too_short: 2.00 s", "se_percent": 10.0,
                                                "state": "converged", "reason": "", "verdict": "done"}
                                               for j, e in enumerate(row)]}
                                     for i, row in enumerate(estimates)]})


def test_the_flight_message_is_table_4_of_the_history_and_garbage_is_refused():
    from rls_uncertainty.dashboard.flight import FlightHistory

    rng = np.random.default_rng(7)
    estimates = rng.normal(-1.0, 0.1, size=(6, 3)).tolist()
    flight = FlightHistory()
    msg = flight.update(_history(estimates))
    assert msg is not None and msg["type"] == "flight" and msg["active"] == "next"
    assert [m["name"] for m in msg["maneuvers"]] == [f"m{i}" for i in range(1, 7)]
    used = np.array(estimates[1:])  # the first maneuver is too short: out of Table 4
    for j, row in enumerate(msg["table4"]):
        assert row["parameter"] == f"p{j}" and row["maneuvers"] == 5
        assert math.isclose(row["mean"], float(np.mean(used[:, j])), rel_tol=1e-12)
        assert math.isclose(row["scatter"], float(np.std(used[:, j], ddof=1)), rel_tol=1e-12)
        assert math.isclose(row["se_corrected"], float(np.mean(np.abs(used[:, j]) / 10)), rel_tol=1e-12)
        assert math.isclose(row["corrected_over_scatter"], row["se_corrected"] / row["scatter"], rel_tol=1e-12)
    assert flight.update(_history(estimates)) is None  # the same history: nothing new for the page
    one = flight.update(_history(estimates[:2]))
    assert one is not None and all(r["scatter"] is None for r in one["table4"])  # one maneuver: no scatter
    for bad in ("", "[]", '{"maneuvers": 3}', '{"maneuvers": [{"rows": [{"estimate": "x"}]}]}', "{" * 100_000):
        assert flight.update(bad) is None
    assert flight.refused == 5 and flight.message == one


def test_the_live_source_hands_on_the_nodes_latched_history():
    """A dashboard started after the node published its history gets it at once (latched)."""
    import json
    import threading
    import time

    import rclpy
    from rclpy.qos import QoSDurabilityPolicy, QoSHistoryPolicy, QoSProfile, QoSReliabilityPolicy
    from std_msgs.msg import String

    from rls_uncertainty.dashboard.ros_source import RosSource

    node_name = f"/flight_test_{id(object())}"
    context = rclpy.Context()
    rclpy.init(context=context)
    publisher_node = rclpy.create_node(node_name[1:], context=context)
    latched = QoSProfile(depth=1, reliability=QoSReliabilityPolicy.RELIABLE, history=QoSHistoryPolicy.KEEP_LAST,
                         durability=QoSDurabilityPolicy.TRANSIENT_LOCAL)
    text = _history([[1.0, 2.0], [1.1, 2.2]])
    publisher_node.create_publisher(String, f"{node_name}/maneuvers", latched).publish(String(data=text))
    got: list[tuple] = []
    arrived = threading.Event()

    def put(item: tuple) -> None:
        if item[0] == "maneuvers":
            got.append(item)
            arrived.set()

    source = RosSource(node_name, put)
    try:
        source.start()
        deadline = time.monotonic() + 60
        while not arrived.is_set():
            assert time.monotonic() < deadline, "the latched history never arrived"
            arrived.wait(0.2)
        assert json.loads(got[0][1]) == json.loads(text)
    finally:
        source.stop()
        publisher_node.destroy_node()
        context.try_shutdown()
