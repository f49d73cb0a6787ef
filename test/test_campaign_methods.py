"""The campaign with both methods (``estimator.method`` / ``--method``, issue 23): on a small
simulated severe-turbulence campaign, the frequency-domain rows of maneuvers.csv are, to the
bit, the last rows of ``estimates_frequency.csv`` from ``rls-uncertainty replay`` of the same
bag (an independent path: the replay's sink and its CSV writer), Table 4's frequency-domain
rows are numpy's mean and sample standard deviation over them, Fig. 12 gets them beside the
time-domain values, and with ``--method time`` the outputs are those of the time-domain rows
of a run with both, without a method column in the text tables. No ROS."""

from __future__ import annotations

import csv
import math
from pathlib import Path

import numpy as np
import pytest

from rls_uncertainty import cli
from rls_uncertainty.campaign import CampaignSettings, Maneuver, campaign_to, from_bags
from rls_uncertainty.campaign.figure import campaign_figures
from rls_uncertainty.campaign.run import run_maneuver
from rls_uncertainty.executors import LocalProcesses
from rls_uncertainty.settings import node_config, pipeline_config
from rls_uncertainty.testing import parameters

ROOT = Path(__file__).resolve().parents[1]
BUNDLED = ROOT / "bags" / "t2_maneuver"
CONFIG = str(ROOT / "config" / "t2.yaml")


def _rows(path: Path) -> list[dict[str, str]]:
    with open(path, newline="") as fh:
        return list(csv.DictReader(fh))


@pytest.fixture(scope="module")
def bags(tmp_path_factory):
    """Three simulated T-2 maneuvers in severe turbulence (make-bag --campaign)."""
    out = tmp_path_factory.mktemp("campaign") / "c"
    assert cli.main(["make-bag", "--campaign", "3", "--gust-intensity", "severe", "--seed", "2010", "--out",
                     str(out)]) == 0
    return sorted(out.glob("m*"))


@pytest.fixture(scope="module")
def both(bags, tmp_path_factory):
    """The campaign over ``bags`` with --method both (no plots)."""
    out = tmp_path_factory.mktemp("both") / "out"
    assert cli.main(["campaign", *map(str, bags), "--config", CONFIG, "--method", "both", "--out", str(out),
                     "--workers", "1", "--quiet", "--no-figures"]) == 0
    return out


@pytest.fixture(scope="module")
def replays(bags, tmp_path_factory):
    """Each bag through ``rls-uncertainty replay --method both``: its output directory."""
    dirs = []
    for bag in bags:
        out = tmp_path_factory.mktemp("replay") / bag.name
        assert cli.main(["replay", str(bag), "--config", CONFIG, "--method", "both", "--out", str(out), "--quiet",
                         "--no-figures"]) == 0
        dirs.append(out)
    return dirs


def _last(path: Path) -> dict[tuple[str, str], dict[str, str]]:
    """The last row of each (model, parameter) of a replay's estimates CSV."""
    return {(r["model"], r["parameter"]): r for r in _rows(path)}


def test_frequency_rows_are_the_replays_last_frequency_estimates_to_the_bit(bags, both, replays):
    rows = _rows(both / "maneuvers.csv")
    assert {r["method"] for r in rows} == {"time", "frequency"}
    for bag, replay in zip(bags, replays, strict=True):
        freq = _last(replay / "estimates_frequency.csv")
        time = _last(replay / "estimates.csv")
        mine = [r for r in rows if r["maneuver"] == bag.name]
        got = {(r["model"], r["parameter"]): r for r in mine if r["method"] == "frequency"}
        assert set(got) == set(freq) and "CZ_0" not in {p for _m, p in got}  # no bias in the frequency domain
        for key, r in got.items():
            want = freq[key]
            assert (r["estimate"], r["se_conventional"], r["se_corrected"]) == (
                want["estimate"], want["std_error_conventional"], want["std_error"])
            assert r["status"] == "ok" and r["se_corrected_all"] == "" and r["r_squared"] == ""
            # The frequency-domain record holds the rows the time-domain estimator used (every: 1).
            t = next(x for x in mine if x["method"] == "time" and x["model"] == key[0])
            assert r["samples"] == t["samples"] and int(r["samples"]) > 0
        for r in (r for r in mine if r["method"] == "time"):
            want = time[(r["model"], r["parameter"])]
            assert (r["estimate"], r["se_conventional"], r["se_corrected"]) == (
                want["estimate"], want["std_error_conventional"], want["std_error"])
        # Per parameter the time-domain row, then the frequency-domain one.
        order = [(r["parameter"], r["method"]) for r in mine]
        assert order.index(("Cm_q", "time")) + 1 == order.index(("Cm_q", "frequency"))


def test_table4_frequency_rows_are_numpys_mean_and_scatter_of_the_frequency_rows(both):
    rows = _rows(both / "maneuvers.csv")
    table = {(r["parameter"], r["method"]): r for r in _rows(both / "table4.csv")}
    freq_params = {r["parameter"] for r in rows if r["method"] == "frequency"}
    assert {p for p, m in table if m == "frequency"} == freq_params and len(freq_params) == 5
    for p in freq_params:
        mine = [r for r in rows if r["parameter"] == p and r["method"] == "frequency"]
        est = np.array([float(r["estimate"]) for r in mine])
        se = np.array([float(r["se_corrected"]) for r in mine])
        conv = np.array([float(r["se_conventional"]) for r in mine])
        t = table[(p, "frequency")]
        assert int(t["maneuvers"]) == 3
        assert float(t["mean"]) == pytest.approx(np.mean(est), rel=1e-14)
        assert float(t["scatter"]) == pytest.approx(np.std(est, ddof=1), rel=1e-12)
        assert float(t["se_corrected"]) == pytest.approx(np.mean(se), rel=1e-14)
        assert float(t["se_conventional"]) == pytest.approx(np.mean(conv), rel=1e-14)
        assert float(t["corrected_over_scatter"]) == pytest.approx(np.mean(se) / np.std(est, ddof=1), rel=1e-12)
        assert t["se_corrected_all"] == "" and t["corrected_all_over_scatter"] == ""
        # beside the time-domain row of the same parameter
        keys = list(table)
        assert keys.index((p, "time")) + 1 == keys.index((p, "frequency"))
    summary = (both / "summary.txt").read_text()
    assert summary.splitlines()[0].split()[:3] == ["parameter", "method", "n"]
    assert any(line.split()[:2] == ["Cm_q", "frequency"] for line in summary.splitlines())
    assert "| Cm | Cm_q | frequency | 3 |" in (both / "table4.md").read_text()


def test_method_time_gives_the_time_rows_of_both_without_a_method_column_in_the_text(bags, both, tmp_path):
    out = tmp_path / "time"
    assert cli.main(["campaign", *map(str, bags), "--config", CONFIG, "--out", str(out), "--workers", "1",
                     "--quiet", "--no-figures"]) == 0
    lines = (out / "maneuvers.csv").read_text().splitlines()
    both_lines = (both / "maneuvers.csv").read_text().splitlines()
    assert lines[0] == both_lines[0]
    assert lines[1:] == [line for line in both_lines[1:] if line.split(",")[3] == "time"]
    t4 = (out / "table4.csv").read_text().splitlines()
    assert t4[1:] == [line for line in (both / "table4.csv").read_text().splitlines()[1:]
                      if line.split(",")[2] == "time"]
    md = (out / "table4.md").read_text()
    assert "| model | parameter | maneuvers | converged at end | mean |" in md and "method" not in md
    md_both = (both / "table4.md").read_text()
    for line in (x for x in md.splitlines() if x.startswith("| C")):  # the same cells, less the method one
        model, parameter, rest = line.split(" | ", 2)
        assert f"{model} | {parameter} | time | {rest}" in md_both
    head = (out / "summary.txt").read_text().splitlines()[0].split()
    assert head[:2] == ["parameter", "n"]


def test_fig12_gets_the_frequency_domain_values_beside_the_time_domain_ones(bags, tmp_path, monkeypatch):
    from rls_uncertainty.offline import figures
    p = parameters("t2", {"estimator.method": "both"})
    settings = CampaignSettings(pipeline_config(p), node_config(p).topics)
    c = campaign_to(tmp_path / "o", from_bags(bags), settings, LocalProcesses(1), figures=None)
    calls = []
    monkeypatch.setattr(figures, "figure12", lambda *a, **k: calls.append((a, k)) or [])
    campaign_figures(tmp_path, c.table, c.results)
    assert [a[0] for a, _k in calls] == ["CZ", "Cm"]
    for (model, _maneuvers, names, est, _conv, _corr, _out), kw in calls:
        assert names == [r.parameter for r in c.table if r.model == model and r.method == "time"]
        f_est, f_se = kw["frequency"]
        means = {r.parameter: r.mean for r in c.table if r.method == "frequency"}
        for k, n in enumerate(names):
            if n not in means:  # the bias: no frequency-domain estimate
                assert np.isnan(f_est[:, k]).all() and math.isnan(kw["frequency_mean"][k])
                continue
            assert kw["frequency_mean"][k] == means[n]
            for i, res in enumerate(c.results):
                (row,) = [r for r in res.rows if r.parameter == n and r.method == "frequency"]
                (time_row,) = [r for r in res.rows if r.parameter == n and r.method == "time"]
                assert (f_est[i, k], f_se[i, k]) == (row.estimate, row.se_corrected)
                assert est[i, k] == time_row.estimate


def test_with_the_frequency_domain_alone_fig12_and_the_rows_are_its_own(bags, tmp_path, monkeypatch):
    from rls_uncertainty.offline import figures
    p = parameters("t2", {"estimator.method": "frequency"})
    settings = CampaignSettings(pipeline_config(p), node_config(p).topics)
    c = campaign_to(tmp_path / "o", from_bags(bags[:2]), settings, LocalProcesses(1), figures=None)
    assert {r.method for res in c.results for r in res.rows} == {"frequency"}
    assert [r.method for r in c.table] == ["frequency"] * 5
    calls = []
    monkeypatch.setattr(figures, "figure12", lambda *a, **k: calls.append((a, k)) or [])
    campaign_figures(tmp_path, c.table, c.results, frequency_lags="50 lags")
    for (model, _m, names, est, conv, corr, _out), kw in calls:
        rows = [r for r in c.table if r.model == model]
        assert names == [r.parameter for r in rows] and kw["mean"] == [r.mean for r in rows]
        assert kw["se_corrected_all"] is None and "frequency" not in kw and kw["title"] == "frequency domain"
        for i, res in enumerate(c.results):
            got = {r.parameter: r for r in res.rows}
            np.testing.assert_array_equal(est[i], [got[n].estimate for n in names])
            np.testing.assert_array_equal(conv[i], [got[n].se_conventional for n in names])
            np.testing.assert_array_equal(corr[i], [got[n].se_corrected for n in names])


def test_a_failed_or_short_maneuver_has_rows_for_both_methods():
    p = parameters("t2", {"estimator.method": "both"})
    settings = CampaignSettings(pipeline_config(p), node_config(p).topics)
    lost = run_maneuver((Maneuver("lost", str(BUNDLED.parent / "nowhere")), settings))
    assert [r.method for r in lost.rows].count("time") == 7 and [r.method for r in lost.rows].count("frequency") == 5
    assert all(r.status.startswith("failed: ") for r in lost.rows)
    short = run_maneuver((Maneuver("short", str(BUNDLED), 0.0, 0.2), settings))
    assert len(short.rows) == 12 and all(r.status.startswith("too_short: ") for r in short.rows)
    assert [r.method for r in short.rows] == [r.method for r in lost.rows]


def test_a_bad_method_is_one_line_naming_the_option(tmp_path, capsys):
    with pytest.raises(SystemExit) as exc:
        cli.main(["campaign", str(BUNDLED), "--method", "fourier", "--out", str(tmp_path / "o")])
    assert exc.value.code == 2 and "--method" in capsys.readouterr().err and not (tmp_path / "o").exists()


def test_a_frequency_domain_that_never_published_says_why():
    """frequency.every longer than the maneuver: the frequency domain never evaluates. The replay
    and the campaign's rows say so, not that the regressors were not excited (the time
    domain's reason) nor nothing (with both methods)."""
    from rls_uncertainty.testing import replay_bag

    why = ("no estimate: the frequency-domain estimator is evaluated every frequency.every = 100000 samples and "
           "took 591 (lower frequency.every)")
    for method, label in (("frequency", "CZ"), ("both", "CZ (frequency domain)")):
        result = replay_bag(BUNDLED, "t2", estimator__method=method, frequency__every=100000)
        assert result.explanations == [f"{label}: {why}", f"{label.replace('CZ', 'Cm')}: {why}"]
        p = parameters("t2", {"estimator.method": method, "frequency.every": 100000})
        rows = run_maneuver((Maneuver("m", str(BUNDLED)), CampaignSettings(pipeline_config(p),
                                                                           node_config(p).topics))).rows
        assert [r.status for r in rows if r.method == "frequency"] == [why] * 5
        assert all(r.status == "ok" for r in rows if r.method == "time")
