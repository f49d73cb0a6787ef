"""campaign/run.py: one maneuver through the replay's pipeline with the configured lags and,
on the same regression rows, with all lags. The configured-lags values are the replay's
(testing.replay_bag) bit for bit, and the all-lags standard errors those of a replay
configured with all lags (estimator.lag_span -1): two independent paths through the same
estimator on one machine. No ROS."""

from __future__ import annotations

import math
from dataclasses import fields, replace
from pathlib import Path

import pytest

from rls_uncertainty.campaign import MANEUVER_COLUMNS, CampaignSettings, Maneuver, ParameterResult
from rls_uncertainty.campaign.run import run_maneuver
from rls_uncertainty.settings import node_config, pipeline_config
from rls_uncertainty.testing import parameters, replay_bag

ROOT = Path(__file__).resolve().parents[1]
BUNDLED = ROOT / "bags" / "t2_maneuver"


@pytest.fixture(scope="module")
def settings():
    p = parameters("t2")
    return CampaignSettings(pipeline_config(p), node_config(p).topics)


def test_columns_are_the_documented_ones():
    assert MANEUVER_COLUMNS == ("maneuver", "model", "parameter", "method", "estimate", "se_conventional",
                                "se_corrected", "se_corrected_all", "samples", "r_squared", "status", "se_percent",
                                "state", "reason", "verdict")
    # every field is written, and the percent error beside them
    assert set(MANEUVER_COLUMNS) == {f.name for f in fields(ParameterResult)} | {"se_percent"}


@pytest.mark.parametrize("span", [(None, None), (1.0, 11.5)])
def test_a_maneuver_gives_the_replays_estimates_and_the_all_lags_replays_errors(settings, span):
    start, end = span
    res = run_maneuver((Maneuver("m", str(BUNDLED), start, end), settings))
    replay = replay_bag(BUNDLED, "t2", start=start, end=end)
    every_lag = replay_bag(BUNDLED, "t2", start=start, end=end, estimator__lag_span=-1)
    assert [r.parameter for r in res.rows] == list(replay.parameters)
    fit = {m: replay.pipeline.model_fit(j) for j, m in enumerate(replay.models)}
    for row in res.rows:
        f, a = replay.final(row.parameter), every_lag.final(row.parameter)
        assert row.status == "ok" and row.maneuver == "m" and row.verdict == ""  # (no targets)
        assert row.se_percent == pytest.approx(100 * f.std_error / abs(f.estimate), rel=1e-12)
        assert (row.estimate, row.se_conventional, row.se_corrected) == (f.estimate, f.std_error_conventional,
                                                                         f.std_error)
        assert a.estimate == f.estimate  # the lags change the standard errors only
        assert row.se_corrected_all == a.std_error
        assert row.samples == fit[row.model]["samples"] and row.r_squared == fit[row.model]["r_squared"]
    assert set(res.seconds) == {"read", "pipeline", "all_lags"} and all(s >= 0 for s in res.seconds.values())
    assert res.problem is None


def test_a_bag_that_cannot_be_read_fails_its_maneuver_only(settings, tmp_path):
    res = run_maneuver((Maneuver("lost", str(tmp_path / "nowhere")), settings))
    assert len(res.rows) == 7 and all(r.status.startswith("failed: ") and "no such bag" in r.status
                                      for r in res.rows)
    assert all(math.isnan(r.estimate) and r.samples == 0 for r in res.rows)
    assert res.problem == res.rows[0].status
    outside = run_maneuver((Maneuver("late", str(BUNDLED), 30.0, 40.0), settings))
    assert outside.problem is not None and "after the bag's last message" in outside.problem


def test_a_maneuver_too_short_to_identify_a_model_says_why(settings):
    """0.2 s: ten samples, fewer than the differentiator and exact initialization need. Below
    --min-span every row is too_short with the span and the minimum; without a minimum the rows
    say the model published no estimate."""
    res = run_maneuver((Maneuver("short", str(BUNDLED), 0.0, 0.2), settings))
    want = f"too_short: {res.data_seconds:.2f} s of data, fewer than --min-span {settings.min_span:g} s"
    assert 0 < res.data_seconds < settings.min_span
    assert {r.status for r in res.rows} == {want}
    assert all(math.isnan(r.se_corrected_all) for r in res.rows)
    res = run_maneuver((Maneuver("short", str(BUNDLED), 0.0, 0.2), replace(settings, min_span=0.0)))
    assert all(r.status.startswith("no estimate") for r in res.rows), {r.status for r in res.rows}
    assert all(math.isnan(r.se_corrected_all) for r in res.rows)


@pytest.mark.parametrize("targets", ["Cm_q=1000,CZ_alpha=1000", "Cm_q=0.01"])
def test_a_maneuvers_rows_carry_the_replays_verdict_against_its_targets(targets):
    """With targets.percent, every row of the maneuver carries the verdict the replay of the same
    bag ends with (:mod:`..datapath.targets`); without targets it is empty (above)."""
    p = {**parameters("t2"), "targets.percent": targets}
    res = run_maneuver((Maneuver("m", str(BUNDLED)), CampaignSettings(pipeline_config(p), node_config(p).topics)))
    replay = replay_bag(BUNDLED, "t2", targets__percent=targets)
    want = replay.pipeline.targets.verdict().text
    assert want.startswith("done" if "1000" in targets else ("needs more", "not identifiable"))
    assert {r.verdict for r in res.rows} == {want}
