"""The dashboard in a real browser: headless Chromium (Debian's package, driven by Playwright,
no browser download) loads the page of `rls-uncertainty dashboard`:

* live: the bundled bag is played to the estimator node (in its own process, under a
  namespace) while the page is open; the page shows every parameter name the node's arrays
  carry, its latest values equal the node's last published values to display precision, its
  convergence badges equal the node's flags, each model's residual autocorrelation and R^2
  those of the node's last ``~/M/fit`` and each parameter's identifiability the node's last
  ``~/M/identifiability``;
* late joiner: the dashboard is started after the bag was played; the page shows the node's
  last published values and fit at once (the outputs keep their last samples for late joiners);
* replay: the Twin Otter recording (converted, then replayed with all six models) shows the
  values of the replay's estimates.csv, and the model the node holds back (C_m explains too
  little of its output on this lateral maneuver) says why on every parameter;
* both methods: a replay of ``--method both`` shows, beside each time-domain value, the
  frequency-domain one of estimates_frequency.csv (matched by name; the bias is not estimated
  in the frequency domain), in the same plots, with a legend; so does a live node started with
  ``estimator.method both`` (its last published frequency-domain values);
* no node: the page says so, naming the domain and discovery range.

Every test waits for the state it then asserts: the samples the page itself counts and has
drawn (``rlsState.drawn``) equal to the replay's, or its newest sample at the node's last
stamp, never a first sign such as the banner (set before the readouts, which change at the
page's next draw).

Without Chromium (or Playwright) these tests skip with the reason; under RLS_REQUIRE_BROWSER=1
they fail instead. Screenshots go to the test's directory, and to $RLS_DASHBOARD_SCREENSHOTS
when set (docs/images/ was made so)."""

from __future__ import annotations

import csv
import math
import os
import shutil
import subprocess
import sys
import threading
import time
from datetime import UTC, datetime
from pathlib import Path

import pytest
import rclpy
from rclpy.qos import QoSHistoryPolicy, QoSProfile, QoSReliabilityPolicy
from std_msgs.msg import Float64MultiArray, Header

from rls_uncertainty.datapath.inputs import STREAMS
from rls_uncertainty.datapath.outputs import parse_stamp_label
from rls_uncertainty.ros.player import stop_process
from rls_uncertainty.simulation.t2 import T2_TRUE

from conftest import FLIGHT_DATA
from ros_harness import REPLAY_NODE, ROOT, T2, NodeProcess, spin_until

CHROMIUM = os.environ.get("RLS_CHROMIUM", "/usr/bin/chromium")
REQUIRE = os.environ.get("RLS_REQUIRE_BROWSER", "") not in ("", "0")
FLAGS = ["--no-sandbox", "--disable-gpu", "--disable-background-networking", "--disable-component-update",
         "--disable-sync", "--no-first-run"]
NS = "/fleet"
RELIABLE = QoSProfile(depth=5000, reliability=QoSReliabilityPolicy.RELIABLE, history=QoSHistoryPolicy.KEEP_LAST)


def _no_browser(reason: str) -> None:
    if REQUIRE:
        pytest.fail(f"{reason}; RLS_REQUIRE_BROWSER is set, so a missing browser fails", pytrace=False)
    pytest.skip(reason)


@pytest.fixture
def browser(tmp_path):
    """A fresh headless Chromium page (its own profile directory), closed afterwards."""
    if not Path(CHROMIUM).is_file():
        _no_browser(f"no Chromium at {CHROMIUM} (bash scripts/setup_browser.sh installs Debian's chromium)")
    try:
        from playwright.sync_api import sync_playwright
    except ImportError:
        _no_browser("Playwright is not installed (requirements-dev.txt)")
    with sync_playwright() as p:
        context = p.chromium.launch_persistent_context(str(tmp_path / "profile"), executable_path=CHROMIUM,
                                                       headless=True, args=FLAGS,
                                                       viewport={"width": 1600, "height": 1000})
        try:
            yield context.pages[0] if context.pages else context.new_page()
        finally:
            context.close()


class Dashboard:
    """``rls-uncertainty dashboard --port 0 ...`` in its own process; ``url`` from its first line."""

    def __init__(self, *args: str, cwd: Path = ROOT) -> None:
        """``cwd``: where it runs (a replay named relative to it shows no test path on the page)."""
        self.proc = subprocess.Popen([sys.executable, "-m", "rls_uncertainty.cli", "dashboard", "--port", "0", *args],
                                     stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=cwd)
        lines: list[str] = []
        reader = threading.Thread(target=lambda: lines.append(self.proc.stdout.readline()), daemon=True)
        reader.start()
        reader.join(60)
        if not lines or not lines[0].startswith("serving http://127.0.0.1:"):
            self.stop()
            raise AssertionError(f"dashboard did not start: {lines} {self.proc.stderr.read()}")
        self.url = lines[0].split()[1]

    def stop(self) -> str:
        stop_process(self.proc, 30)
        return self.proc.stderr.read()


def _shot(page, tmp_path: Path, name: str) -> Path:
    path = tmp_path / name
    page.screenshot(path=str(path), full_page=True)
    if os.environ.get("RLS_DASHBOARD_SCREENSHOTS"):
        shutil.copy(path, Path(os.environ["RLS_DASHBOARD_SCREENSHOTS"]) / name)
    assert path.stat().st_size > 10_000
    return path


def _shot_of(page, selector: str, tmp_path: Path, name: str) -> None:
    """A screenshot of one element of the page (as _shot)."""
    path = tmp_path / name
    page.locator(selector).screenshot(path=str(path))
    if os.environ.get("RLS_DASHBOARD_SCREENSHOTS"):
        shutil.copy(path, Path(os.environ["RLS_DASHBOARD_SCREENSHOTS"]) / name)
    assert path.stat().st_size > 10_000


def _shown(page) -> dict[str, tuple[str, str]]:
    """Per parameter panel: (latest value as displayed, convergence badge)."""
    return page.evaluate("""() => Object.fromEntries([...document.querySelectorAll('.panel')].map(p =>
        [p.querySelector('.title').textContent,
         [p.querySelector('.value').textContent, p.querySelector('.badge').dataset.converged]]))""")


def _wait(page, js: str, timeout_s: float) -> None:
    """Poll ``js`` (an expression or a function) in the page until true. Polled from here:
    Playwright's wait_for_function evaluates strings inside the page, which the page's
    Content-Security-Policy (no eval) forbids, and the test keeps that policy on."""
    expression = js if js.lstrip().startswith("()") else f"() => ({js})"
    deadline = time.monotonic() + timeout_s
    while not page.evaluate(expression):
        assert time.monotonic() < deadline, f"page never satisfied {js!r}; banner: {page.text_content('#banner')!r}"
        time.sleep(0.2)


def _decimals(se: float) -> int:
    """The decimals that show ``se`` to two significant digits (at most 12)."""
    return max(0, min(12, 1 - math.floor(math.log10(se))))


def _expect_digits(text: str, value: float, se: float) -> None:
    """``text`` is ``value`` as Python formats it to the decimals of two significant digits of
    ``se`` (a tie, where JavaScript rounds half up and Python to even, either way)."""
    d = _decimals(se)
    tie = abs(abs(value * 10**d) % 1 - 0.5) < 1e-6
    assert text == f"{value:.{d}f}" or (tie and abs(float(text) - value) <= 0.5 * 10**-d + 1e-12), (text, value, se)


def _expect_shown(shown: dict, last: dict[str, tuple[float, float, float]]) -> None:
    """Every parameter shown, its value to the decimals of two significant digits of its
    corrected standard error, its badge."""
    assert set(shown) == set(last)
    for name, (value, flag, se) in last.items():
        text, badge = shown[name]
        _expect_digits(text, value, se)
        assert badge == ("1" if flag == 1.0 else "0"), (name, badge, flag)


# ------------------------------------------------------------------ live
class _Recorder:
    """The node's estimates and convergence flags, as it publishes them (to know its last values)."""

    def __init__(self, node_name: str, models=("CZ", "Cm")) -> None:
        self.node = rclpy.create_node("browser_test_recorder")
        self.got: dict[tuple[str, str], list] = {}
        self.stamps: list = []
        self.node.create_subscription(Header, f"{node_name}/sample_stamp", self.stamps.append, RELIABLE)
        for m in models:
            for suffix in ("estimates", "standard_errors", "converged", "fit", "identifiability"):
                store = self.got.setdefault((m, suffix), [])
                self.node.create_subscription(Float64MultiArray, f"{node_name}/{m}/{suffix}", store.append, RELIABLE)

    def spin_until(self, condition, timeout: float) -> bool:
        return spin_until(self.node, condition, timeout)

    def last(self) -> tuple[int, dict[str, tuple[float, float, float]]]:
        out, stamps = {}, set()
        for m in ("CZ", "Cm"):
            est, conv, se = (self.got[(m, s)][-1] for s in ("estimates", "converged", "standard_errors"))
            stamps.add(parse_stamp_label(est.layout.dim[-1].label))
            assert parse_stamp_label(conv.layout.dim[-1].label) in stamps
            assert parse_stamp_label(se.layout.dim[-1].label) in stamps
            for name, value, flag, e in zip(est.layout.dim[0].label.split(","), est.data, conv.data, se.data,
                                            strict=True):
                out[name] = (float(value), float(flag), float(e))
        return max(stamps), out

    def wait_quiet(self, count: int, timeout: float = 120.0) -> None:
        """Until at least ``count`` samples came and the node's outputs have stopped for 2 s."""
        assert self.spin_until(lambda: len(self.stamps) >= count, timeout), {k: len(v) for k, v in self.got.items()}
        deadline = time.monotonic() + timeout
        n = -1
        fits = [(m, s) for m in ("CZ", "Cm") for s in ("fit", "identifiability")]
        while n != len(self.stamps) or not all(self.got[k] for k in fits):
            assert time.monotonic() < deadline, {k: len(v) for k, v in self.got.items()}
            n = len(self.stamps)
            self.spin_until(lambda: False, 2.0)

    def last_fits(self) -> dict[str, tuple[list[float], list[bool]]]:
        """Per model: the last ~/M/fit's data and the last ~/M/identifiability's flags."""
        out = {}
        for m in ("CZ", "Cm"):
            fit, table = self.got[(m, "fit")][-1], self.got[(m, "identifiability")][-1]
            n = len(table.layout.dim[0].label.split(","))
            out[m] = (list(fit.data), [table.data[i * (n + 3) + n + 2] == 1.0 for i in range(n)])
        return out


def _expect_fits(page, fits: dict[str, tuple[list[float], list[bool]]]) -> None:
    """The page's autocorrelation, R^2 and identifiability are the node's last ones."""
    for model, (fit, identifiable) in fits.items():
        # A model's fit comes in its own message, after or before its samples: wait for it (and
        # its drawing) until it is the node's last, then compare.
        js = (f"() => {{ const q = window.rlsState.models.get('{model}').quality; const f = q && q.time && q.time.fit;"
              f" return !!f && f.r_squared === {fit[0]!r} && f.samples === {fit[1]!r} && !window.rlsState.dirty; }}")
        _wait(page, js, 60)
        shown = page.evaluate(f"window.rlsState.models.get('{model}').quality.time.fit")
        assert [shown["r_squared"], shown["samples"], shown["bound_2sigma"], *shown["rho"]] == fit
        text = page.text_content(f"section.model[data-model='{model}'] .fit")
        assert text.startswith(f"R² {fit[0]:.3f}  ·  {len(fit) - 3} lags"), text
        flags = page.evaluate(f"[...document.querySelectorAll(\"section.model[data-model='{model}'] .ident\")]"
                              ".map(e => e.dataset.identifiable)")
        assert flags == ["1" if ok else "0" for ok in identifiable]
        assert page.evaluate(f"!!document.querySelector(\"section.model[data-model='{model}'] .acf-chart canvas\")")


def test_live_page_shows_the_nodes_last_published_values_and_flags_under_a_namespace(tmp_path, browser):
    node_name = f"{NS}/rls_estimator"
    remaps = [a for kind in STREAMS for a in ("-r", f"{kind}:=/{kind}")]  # the bag's topics are /imu, ...
    node = NodeProcess(tmp_path, "--params-file", T2, *REPLAY_NODE, "-r", f"__ns:={NS}", *remaps)
    dashboard = None
    reference = tmp_path / "reference.yaml"  # the simulation's true values (make-bag's maneuver)
    reference.write_text("".join(f"{name}: {value!r}\n" for name, value in T2_TRUE.items()))
    rclpy.init()
    recorder = _Recorder(node_name)
    try:
        dashboard = Dashboard("--node", node_name, "--reference", str(reference))
        browser.goto(dashboard.url)
        _wait(browser, "document.getElementById('banner').dataset.state === 'no_samples'", 90)
        assert node_name in browser.text_content("#node")
        play = subprocess.run([sys.executable, "-m", "rls_uncertainty.cli", "play", str(ROOT / "bags" / "t2_maneuver"),
                               "--rate", "1", "--subscribers", "1", "--wait", "60"],
                              capture_output=True, text=True, cwd=ROOT, timeout=300)
        assert play.returncode == 0, play.stderr
        # The node's last samples: its outputs have stopped coming for 2 s (at real time it may
        # form a few samples fewer than the offline replay's 591; the page must show its last).
        recorder.wait_quiet(500)
        stamp, last = recorder.last()
        _wait_for_stamp(browser, stamp)
        _expect_shown(_shown(browser), last)
        _expect_fits(browser, recorder.last_fits())
        assert browser.get_attribute("#banner", "data-state") == "running"
        # The reference's verdict: |estimate - reference| / SE of the node's last sample.
        refs = browser.evaluate("Object.fromEntries([...document.querySelectorAll('.panel')].map(p => "
                                "[p.dataset.param, [p.querySelector('.ref').textContent, "
                                "p.querySelector('.ref').dataset.verdict || '']]))")
        for name, (value, _, se) in last.items():
            if name not in T2_TRUE:
                assert refs[name] == ["", ""], name
                continue
            sigmas = abs(value - T2_TRUE[name]) / se
            text, verdict = refs[name]
            assert text.startswith("reference ") and text.count("  ·  ") == 1, (name, text)
            _expect_digits(text.removeprefix("reference ").split("  ·  ")[0], T2_TRUE[name], se)
            assert abs(float(text.rsplit("  ·  ", 1)[1].removesuffix("σ off")) - sigmas) <= 0.05 + 1e-9, (name, text)
            assert verdict == ("within" if sigmas <= 2 else "outside"), (name, text, sigmas)
        assert {r.get_attribute("data-stream") for r in browser.query_selector_all("#streams tbody tr")} == set(STREAMS)
        assert browser.evaluate("window.rlsLatency.length") > 100
        _shot(browser, tmp_path, "dashboard_live.png")
        # The node's reset (its /diagnostics count it): the panels empty, no badge says
        # converged, each parameter's state line says the node's model is initializing again.
        reset = subprocess.run([sys.executable, "-m", "rls_uncertainty.cli", "reset", "--node", node_name],
                               capture_output=True, text=True, cwd=ROOT, timeout=120)
        assert reset.returncode == 0, reset.stderr
        _wait(browser, "() => [...document.querySelectorAll('.panel')].every(p => "
                       "p.querySelector('.value').textContent === '–' && "
                       "p.querySelector('.badge').dataset.converged === '0' && "
                       "p.querySelector('.pstate').textContent.startsWith('initializing'))", 60)
        assert browser.evaluate("document.querySelectorAll('.panel').length") == len(last)
    finally:
        err = _stop(recorder, dashboard, node)
    assert "dashboard stopped" in err and "arrays dropped: none" in err, err


def _stop(recorder: _Recorder, dashboard: Dashboard | None, node: NodeProcess) -> str:
    """Stop what a live test started; the dashboard's stderr."""
    recorder.node.destroy_node()
    rclpy.try_shutdown()
    err = dashboard.stop() if dashboard is not None else ""
    assert node.stop() == 0, node.text()
    return err


def _wait_drawn(page, expected: dict[tuple[str, str], tuple[int | None, float]], timeout_s: float = 180) -> None:
    """Until the page has *drawn*, per ``(method, model)``, its own count of samples equal to
    the expected one (None: any) and its newest sample at the expected time (s): the state the
    test then reads, never a first sign. The page publishes what its last draw showed
    (``rlsState.drawn``, set at the end of each draw, after the readouts); the banner and the
    data arrive before the draw that shows them (a 200 ms timer, late on a loaded machine)."""
    deadline = time.monotonic() + timeout_s
    while True:
        drawn = page.evaluate("window.rlsState.drawn")
        shown = {(method, model): (drawn.get(method, {}).get(model) or {}) for method, model in expected}
        if all(d and (n is None or d["count"] == n) and abs(d["t"] - t) < 1e-6
               for (n, t), d in zip(expected.values(), shown.values(), strict=True)):
            return
        assert time.monotonic() < deadline, (f"page never drew {expected}: it drew {shown}; banner: "
                                             f"{page.text_content('#banner')!r}")
        time.sleep(0.2)


def _wait_for_stamp(page, stamp: int) -> None:
    """:func:`_wait_drawn`: both models' time-domain samples drawn up to ``stamp`` (ns)."""
    _wait_drawn(page, {("time", "CZ"): (None, stamp * 1e-9), ("time", "Cm"): (None, stamp * 1e-9)})


def _replay_counts(path: Path, method: str = "time") -> dict[tuple[str, str], tuple[int, float]]:
    """Per model of a replay CSV: the samples the page shows (the distinct times of its rows;
    a sample with a standard error of 0 or less is refused) and the time of its last one."""
    samples: dict[str, dict[str, bool]] = {}
    with open(path, newline="") as fh:
        for r in csv.DictReader(fh):
            ok = float(r["std_error"]) > 0 and float(r["std_error_conventional"]) > 0
            times = samples.setdefault(r["model"], {})
            times[r["time"]] = times.get(r["time"], True) and ok
    return {(method, model): (sum(times.values()), float(max(t for t, ok in times.items() if ok)))
            for model, times in samples.items()}


def test_a_dashboard_started_after_the_node_shows_its_latest_values_at_once(tmp_path, browser):
    """The bag is played to the node first; the dashboard starts afterwards and gets the node's
    last samples and fits from the outputs kept for late joiners (transient local): the page
    shows the node's last published values, flags, autocorrelation and identifiability."""
    node = NodeProcess(tmp_path, "--params-file", T2, *REPLAY_NODE)
    dashboard = None
    rclpy.init()
    recorder = _Recorder("/rls_estimator")
    try:
        play = subprocess.run([sys.executable, "-m", "rls_uncertainty.cli", "play", str(ROOT / "bags" / "t2_maneuver"),
                               "--rate", "1", "--subscribers", "1", "--wait", "60"],
                              capture_output=True, text=True, cwd=ROOT, timeout=300)
        assert play.returncode == 0, play.stderr
        recorder.wait_quiet(300)  # on a busy machine the node forms fewer than the replay's 591
        stamp, last = recorder.last()
        dashboard = Dashboard()
        browser.goto(dashboard.url)
        _wait_for_stamp(browser, stamp)
        _expect_shown(_shown(browser), last)
        _expect_fits(browser, recorder.last_fits())
        assert browser.get_attribute("#banner", "data-state") == "running"
    finally:
        err = _stop(recorder, dashboard, node)
    assert "dashboard stopped" in err and "arrays dropped: none" in err, err


def test_a_live_node_publishing_both_methods_shows_its_last_frequency_domain_values(tmp_path, browser):
    """A node with ``estimator.method both``: after the bag was played, the dashboard (a late
    joiner, from the outputs kept for it) shows beside the time domain's values the node's last
    published frequency-domain estimates and flags, matched by name."""
    node = NodeProcess(tmp_path, "--params-file", T2, *REPLAY_NODE, "-p", "estimator.method:=both")
    dashboard = None
    rclpy.init()
    recorder = _Recorder("/rls_estimator")
    frequency: dict[tuple[str, str], list] = {}
    for m in ("CZ", "Cm"):
        for suffix in ("estimates", "converged", "standard_errors"):
            store = frequency.setdefault((m, suffix), [])
            recorder.node.create_subscription(Float64MultiArray, f"/rls_estimator/{m}/frequency/{suffix}",
                                              store.append, RELIABLE)
    try:
        play = subprocess.run([sys.executable, "-m", "rls_uncertainty.cli", "play", str(ROOT / "bags" / "t2_maneuver"),
                               "--rate", "1", "--subscribers", "1", "--wait", "60"],
                              capture_output=True, text=True, cwd=ROOT, timeout=300)
        assert play.returncode == 0, play.stderr
        recorder.wait_quiet(300)
        assert all(frequency.values()), {k: len(v) for k, v in frequency.items()}
        stamp, last = recorder.last()
        last_frequency, frequency_stamps = {}, {}
        for m in ("CZ", "Cm"):
            est, conv, se = (frequency[(m, s)][-1] for s in ("estimates", "converged", "standard_errors"))
            assert est.layout.dim[-1].label == conv.layout.dim[-1].label == se.layout.dim[-1].label
            frequency_stamps[m] = parse_stamp_label(est.layout.dim[-1].label) * 1e-9
            for name, value, flag, e in zip(est.layout.dim[0].label.split(","), est.data, conv.data, se.data,
                                            strict=True):
                last_frequency[name] = (float(value), float(flag), float(e))
        assert set(last_frequency) == set(last) - {"CZ_0", "Cm_0"}  # no bias in the frequency domain
        dashboard = Dashboard()
        browser.goto(dashboard.url)
        _wait_drawn(browser, {**{("time", m): (None, stamp * 1e-9) for m in ("CZ", "Cm")},
                              **{("frequency", m): (None, t) for m, t in frequency_stamps.items()}})
        _expect_shown(_shown(browser), last)
        shown = browser.evaluate("""() => Object.fromEntries([...document.querySelectorAll('.panel')].map(p => {
            const r = p.querySelector('.readout.alt[data-method="frequency"]');
            return [p.dataset.param, [r.querySelector('.alt-value').textContent,
                                      r.querySelector('.alt-badge').dataset.converged]];
        }))""")
        _expect_shown({n: v for n, v in shown.items() if n in last_frequency}, last_frequency)
        assert shown["CZ_0"][0] == shown["Cm_0"][0] == "–"
    finally:
        err = _stop(recorder, dashboard, node)
    assert "dashboard stopped" in err and "arrays dropped: none" in err, err


# ------------------------------------------------------------------ replay
@pytest.fixture(scope="module")
def twin_otter_replay(tmp_path_factory):
    from rls_uncertainty.offline.bags import convert
    from rls_uncertainty.offline.replay import replay
    from rls_uncertainty.settings import load_parameters_file

    base = tmp_path_factory.mktemp("twin_otter")
    convert(FLIGHT_DATA / "totter_f1_017", ROOT / "msg_schemas" / "fti_msgs" / "mapping.yaml", base / "bag")
    params = {**load_parameters_file("twin_otter_lateral"), "models.enabled": ["CX", "CY", "CZ", "Cl", "Cm", "Cn"]}
    replay(base / "bag", params, base / "totter_f1_017", progress=False, plots=False)
    return base / "totter_f1_017"


def test_replay_page_shows_the_final_values_of_the_replays_estimates_csv(tmp_path, browser, twin_otter_replay):
    with open(twin_otter_replay / "estimates.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))
    last_time = {}
    for r in rows:
        last_time[r["model"]] = r["time"]
    last = {r["parameter"]: (float(r["estimate"]), float(r["converged"]), float(r["std_error"])) for r in rows
            if r["time"] == last_time[r["model"]]}
    dashboard = Dashboard("--replay", twin_otter_replay.name, cwd=twin_otter_replay.parent)
    try:
        browser.goto(dashboard.url)
        counts = _replay_counts(twin_otter_replay / "estimates.csv")
        assert {m: t for (_, m), (_, t) in counts.items()} == {m: float(t) for m, t in last_time.items()}
        _wait_drawn(browser, counts)  # every sample of the replay, drawn: the readouts are its last
        _wait(browser, "document.getElementById('banner').dataset.state === 'replay'", 60)
        assert browser.text_content("#mode") == "REPLAY"
        sections = browser.query_selector_all("section.model")
        assert [s.get_attribute("data-model") for s in sections] == ["CX", "CY", "CZ", "Cl", "Cm", "Cn"]  # Eq. 2
        _expect_shown(_shown(browser), last)
        # What the replay's last /diagnostics holds back, each parameter says why (the lateral
        # maneuver leaves C_m's R^2 under identifiability.min_r_squared).
        held = _last_held_back(twin_otter_replay / "estimates.mcap")
        assert held["Cm"] == ["Cm_0", "Cm_alpha", "Cm_q", "Cm_delta_e"]
        assert not any(held[m] for m in ("CX", "CY", "CZ", "Cl", "Cn"))
        _wait(browser, "document.querySelectorAll('.panel.held-back').length === 4", 30)
        shown = browser.evaluate("Object.fromEntries([...document.querySelectorAll('.panel')].map(p => "
                                 "[p.dataset.param, [p.querySelector('.ident').textContent, "
                                 "!p.querySelector('.held-tag').hidden]]))")
        r2 = float(held["Cm:r_squared"][0])
        for name, (text, tag) in shown.items():
            if name.startswith("Cm_"):
                assert (text, tag) == (f"not identifiable: model explains nothing (R^2 {r2:.3f})", True), name
            else:
                assert text.startswith("identifiable") and not tag, name
        # Each parameter's state line is the replay's last /diagnostics' state.<parameter>.
        states = browser.evaluate("Object.fromEntries([...document.querySelectorAll('.panel')].map(p => "
                                  "[p.dataset.param, p.querySelector('.pstate').textContent]))")
        assert states == {name: held[f"{name.split('_')[0]}:state.{name}"][0] for name in last}
        assert all(states[n].startswith("held back: not identifiable") for n in held["Cm"])
        _expect_units_and_percent(browser, last)
        _expect_time_axis(browser, twin_otter_replay / "estimates.csv")
        _shot_of(browser, "section.model[data-model='Cm']", tmp_path, "dashboard_held_back.png")
        assert browser.query_selector("nav#window button.active").get_attribute("data-window") == "0"  # all
        _shot(browser, tmp_path, "dashboard_replay.png")
        _expect_y_ranges(browser, twin_otter_replay / "estimates.csv")
    finally:
        err = dashboard.stop()
    assert "dashboard stopped" in err, err


def _csv_histories(path: Path) -> dict[str, tuple[list[float], list[float], list[float]]]:
    """Per parameter of a replay CSV, the times, estimates and corrected standard errors of the
    samples the page shows (a sample any of whose values is not finite, or whose standard
    errors are not positive, is refused for every parameter of its model)."""
    with open(path, newline="") as fh:
        rows = list(csv.DictReader(fh))
    ok: dict[tuple[str, str], bool] = {}
    for r in rows:
        values = [float(r[k]) for k in ("estimate", "std_error", "std_error_conventional")]
        good = all(math.isfinite(v) for v in values) and values[1] > 0 and values[2] > 0
        ok[(r["model"], r["time"])] = ok.get((r["model"], r["time"]), True) and good
    out: dict[str, tuple[list[float], list[float], list[float]]] = {}
    for r in rows:
        if ok[(r["model"], r["time"])]:
            t, est, se = out.setdefault(r["parameter"], ([], [], []))
            t.append(float(r["time"]))
            est.append(float(r["estimate"]))
            se.append(float(r["std_error"]))
    return out


def _expect_y_ranges(page, path: Path) -> None:
    """Each panel's y-range is band_limits (datapath/display.py, numpy) of the CSV's samples
    after the first TRANSIENT_FRACTION of them; with "y: all" it holds every sample's band."""
    import numpy as np

    from rls_uncertainty.datapath.display import TRANSIENT_FRACTION, band_limits

    def shown() -> dict[str, list[float]]:
        return page.evaluate("Object.fromEntries([...window.rlsState.models.values()].flatMap(m => m.view.plots.map("
                             "p => [p.name, [p.u.scales.y.min, p.u.scales.y.max]])))")

    histories = _csv_histories(path)
    ranges = shown()
    assert set(ranges) == set(histories)
    narrower = 0
    for name, (_, est, se) in histories.items():
        k0 = math.floor(TRANSIENT_FRACTION * len(est))
        lo, hi = band_limits(np.array(est[k0:]), np.array(se[k0:]))
        assert abs(ranges[name][0] - lo) <= 1e-9 * (hi - lo) and abs(ranges[name][1] - hi) <= 1e-9 * (hi - lo), \
            (name, ranges[name], (lo, hi))
        edges = [(e - 2 * s, e + 2 * s) for e, s in zip(est, se, strict=True)]
        narrower += max(b for _, b in edges) - min(a for a, _ in edges) > 2 * (hi - lo)
    assert narrower > 0  # the start-up transient would have set some ranges
    page.click("#y-all")
    _wait(page, "document.getElementById('y-all').classList.contains('active') && !window.rlsState.dirty", 30)
    _wait(page, "() => [...window.rlsState.models.values()].every(m => m.view.plots.every(p => p.yRange === null))", 30)
    ranges = shown()
    for name, (_, est, se) in histories.items():
        assert ranges[name][0] <= min(e - 2 * s for e, s in zip(est, se, strict=True)), name
        assert ranges[name][1] >= max(e + 2 * s for e, s in zip(est, se, strict=True)), name


def _expect_units_and_percent(page, last: dict[str, tuple[float, float, float]]) -> None:
    """Units from the parameter's name (per radian; a rate derivative per its nondimensional
    rate; the bias dimensionless) and the percent error 100 SE/|estimate| to one decimal."""
    shown = page.evaluate("Object.fromEntries([...document.querySelectorAll('.panel')].map(p => "
                          "[p.dataset.param, [p.querySelector('.unit').textContent, "
                          "p.querySelector('.readout .pct').textContent]]))")
    rates = {"p": "p b/2V", "q": "q cbar/2V", "r": "r b/2V"}
    for name, (value, _, se) in last.items():
        suffix = name.split("_", 1)[1]
        unit = "dimensionless" if suffix == "0" else "1/rad" + (f" (per {rates[suffix]})" if suffix in rates else "")
        assert shown[name] == [unit, f"{100 * se / abs(value):.1f} %"], (name, shown[name])


def _expect_time_axis(page, path: Path) -> None:
    """The time axis and the header count from the first sample; "UTC" shows the wall clock."""
    times = sorted({t for t, _, _ in _csv_histories(path).values() for t in t})
    assert page.text_content("#clock") == f"t = {times[-1] - times[0]:.2f} s since the first sample"
    first = page.evaluate("Math.min(...[...window.rlsState.models.values()].map(m => m.view.plots[0].u.data[0][0]))")
    assert abs(first) < 1e-6
    page.click("#clock-utc")
    _wait(page, "document.getElementById('clock').textContent.endsWith('UTC')", 30)
    wall = datetime.fromtimestamp(times[-1], UTC).strftime("%Y-%m-%d %H:%M:%S")
    assert page.text_content("#clock").startswith(f"t = {wall}"), page.text_content("#clock")
    page.click("#clock-utc")
    _wait(page, "document.getElementById('clock').textContent.endsWith('first sample') && "
                "[...window.rlsState.models.values()].every(m => m.view)", 30)


def _last_held_back(path: Path) -> dict[str, list[str]]:
    """Per model, the parameters held back in the last /diagnostics of an estimates.mcap (and
    ``M:r_squared``, ``M:state.P`` for each parameter P), read with rosbags."""
    from rosbags.highlevel import AnyReader

    from rls_uncertainty.offline.bags import typestore

    last = None
    with AnyReader([path], default_typestore=typestore()) as reader:
        conns = [c for c in reader.connections if c.topic == "/diagnostics"]
        for conn, _t, raw in reader.messages(connections=conns):
            last = reader.deserialize(raw, conn.msgtype)
    out: dict[str, list[str]] = {}
    for status in last.status:
        if ": model " in status.name:
            model = status.name.rsplit(" ", 1)[1]
            values = {kv.key: kv.value for kv in status.values}
            out[model] = [p for p in values.get("held_back", "").split(",") if p]
            out[f"{model}:r_squared"] = [values["r_squared"]]
            out.update({f"{model}:{k}": [v] for k, v in values.items() if k.startswith(("state.", "frequency.state."))})
    return out


# ------------------------------------------------------------------ both methods
def _last_rows(path: Path) -> dict[str, dict[str, str]]:
    """Per parameter, its row of the last time of its model in a replay CSV (csv module)."""
    with open(path, newline="") as fh:
        rows = list(csv.DictReader(fh))
    last_time = {}
    for r in rows:
        last_time[r["model"]] = r["time"]
    return {r["parameter"]: r for r in rows if r["time"] == last_time[r["model"]]}


def test_a_replay_of_both_methods_shows_the_frequency_domain_beside_the_time_domain(tmp_path, browser):
    """``rls-uncertainty replay --method both``: every panel shows the time domain's last values
    and, matched by name, the frequency domain's (estimate, corrected and conventional SE,
    flag) as in estimates_frequency.csv; the bias, which the frequency domain does not
    estimate, says so; the frequency domain's history is drawn in the same plot."""
    out = tmp_path / "t2_both"
    run = subprocess.run([sys.executable, "-m", "rls_uncertainty.cli", "replay", str(ROOT / "bags" / "t2_maneuver"),
                          "--config", T2, "--method", "both", "--out", str(out), "--no-figures", "--quiet"],
                         capture_output=True, text=True, cwd=ROOT, timeout=300)
    assert run.returncode == 0, run.stderr
    time_rows, freq_rows = _last_rows(out / "estimates.csv"), _last_rows(out / "estimates_frequency.csv")
    assert set(freq_rows) < set(time_rows) and {"CZ_0", "Cm_0"} == set(time_rows) - set(freq_rows)
    dashboard = Dashboard("--replay", out.name, cwd=out.parent)
    try:
        browser.goto(dashboard.url)
        # Every sample of both files drawn (the frequency domain's first of each model is refused:
        # its corrected standard error is 0), then the banner's end of the reading.
        _wait_drawn(browser, {**_replay_counts(out / "estimates.csv"),
                              **_replay_counts(out / "estimates_frequency.csv", "frequency")})
        _wait(browser, "document.getElementById('banner').dataset.state === 'replay'", 60)
        _expect_shown(_shown(browser), {n: (float(r["estimate"]), float(r["converged"]), float(r["std_error"]))
                                        for n, r in time_rows.items()})
        rows = browser.evaluate("""() => Object.fromEntries([...document.querySelectorAll('.panel')].map(p => {
            const r = p.querySelector('.readout.alt[data-method="frequency"]');
            return [p.dataset.param, [r.querySelector('.method').textContent, r.querySelector('.alt-value').textContent,
                    r.querySelector('.alt-se').textContent, r.querySelector('.alt-badge').dataset.converged,
                    r.querySelector('.alt-badge').hidden,
                    p.querySelector('.readout[data-method="time"] .method').textContent]];
        }))""")
        for name, (label, value, se, flag, hidden, time_label) in rows.items():
            assert (label, time_label) == ("frequency domain", "time domain (RLS)"), name
            if name not in freq_rows:  # the bias: not a frequency-domain parameter
                assert (value, se, hidden) == ("–", "not estimated", True), name
                continue
            r = freq_rows[name]
            _expect_digits(value, float(r["estimate"]), float(r["std_error"]))
            corrected, conventional = se.removeprefix("SE ").removesuffix(")").split(" (conv. ")
            _expect_digits(corrected, float(r["std_error"]), float(r["std_error"]))
            _expect_digits(conventional, float(r["std_error_conventional"]), float(r["std_error_conventional"]))
            assert (flag, hidden) == ("1" if float(r["converged"]) == 1.0 else "0", False), name
        # The page holds the CSV's very doubles (the MCAP's arrays), and draws them: per
        # panel the frequency domain's estimate and band beside the time domain's, its newest
        # point the last estimate (none for the bias).
        for model in ("CZ", "Cm"):
            held = browser.evaluate(f"(() => {{ const h = window.rlsState.models.get('{model}').methods.frequency; "
                                    "return Object.fromEntries(h.names.map((n, i) => [n, h.estimate[i].at(-1)])); "
                                    "})()")
            assert held == {n: float(r["estimate"]) for n, r in freq_rows.items() if r["model"] == model}
            drawn = browser.evaluate(f"window.rlsState.models.get('{model}').view.plots.map(p => [p.name, "
                                     "p.u.series.length, p.u.data[p.slots.frequency].filter(v => v !== null).at(-1)])")
            for name, series, last in drawn:
                assert series == 1 + 5 + 3, name  # x; time: estimate, 2 corrected, 2 conventional; frequency: 3
                assert last == (held[name] if name in freq_rows else None), name
        # Each parameter's state line: the last /diagnostics' state of each method, time domain first.
        held = _last_held_back(out / "estimates.mcap")
        states = browser.evaluate("Object.fromEntries([...document.querySelectorAll('.panel')].map(p => "
                                  "[p.dataset.param, p.querySelector('.pstate').textContent]))")
        for name, text in states.items():
            model = name.split("_")[0]
            parts = [f"time domain (RLS): {held[f'{model}:state.{name}'][0]}"]
            if name in freq_rows:
                parts.append(f"frequency domain: {held[f'{model}:frequency.state.{name}'][0]}")
            assert text == "  ·  ".join(parts), (name, text)
        legend = browser.evaluate("[...document.querySelectorAll('.model .legend-item')].map(e => e.textContent)")
        assert legend == ["time domain (RLS)", "frequency domain"] * 2
        _shot(browser, tmp_path, "dashboard_both_methods.png")
    finally:
        err = dashboard.stop()
    assert "dashboard stopped" in err and "arrays dropped: none" in err, err


# ------------------------------------------------------------------ no node
def test_without_a_node_the_page_says_which_domain_and_discovery_range_it_searched(tmp_path, browser):
    dashboard = Dashboard("--node", "/nobody_here/rls_estimator")
    try:
        browser.goto(dashboard.url)
        _wait(browser, "document.getElementById('banner').dataset.state === 'no_node'", 60)
        text = browser.text_content("#banner")
        domain = os.environ.get("ROS_DOMAIN_ID") or "0"
        assert "/nobody_here/rls_estimator" in text and f"ROS_DOMAIN_ID={domain}" in text
        assert f"ROS_AUTOMATIC_DISCOVERY_RANGE={os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE']}" in text
        assert browser.query_selector_all(".panel") == []
        _shot(browser, tmp_path, "dashboard_no_node.png")
    finally:
        dashboard.stop()
