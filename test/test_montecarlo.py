"""The Table 3 Monte Carlo's convergence flags with the node's identifiability tests
(rls_uncertainty.simulation.montecarlo): the flags it reports are those of an independent convergence
monitor less what an independent identifiability monitor takes out, and the held-back
statistics count exactly the runs whose first flag the tests delayed. No ROS.

montecarlo.py's noise variant and executors: the band-limited noise on all four measured
signals or on the responses only (the default, docs/validation.md), the same random draws in
both; the levels run on any executor with the same numbers. No ROS."""

from __future__ import annotations

import numpy as np
import pytest

from rls_uncertainty import cli
from rls_uncertainty.datapath.convergence import ConvergenceMonitor
from rls_uncertainty.datapath.identifiability import IdentifiabilityConfig, IdentifiabilityMonitor
from rls_uncertainty.estimator import EstimatorBank
from rls_uncertainty.executors import LocalProcesses
from rls_uncertainty.settings import REGRESSOR_UNITS
from rls_uncertainty.simulation.montecarlo import (
    MONTE_CARLO_CONVERGENCE,
    PARAMETERS,
    TABLE3_OPTIONS,
    convergence_summary,
    level_inputs,
    parameter_cells,
    run_level,
    run_table3,
)
from rls_uncertainty.simulation.t2 import BAND_LIMITED_ON, RESPONSES, SIGNALS, T2_MODELS

RUNS = 6


def first_flags(level, config):
    """First flag sample of every run's Table 3 parameters, without and with the tests,
    recomputed here from the bank, the convergence monitor and the identifiability monitor."""
    t, _red, sizes, X, Z = level_inputs(level, RUNS)
    bank = EstimatorBank(sizes, TABLE3_OPTIONS)
    monitor = ConvergenceMonitor(sizes, MONTE_CARLO_CONVERGENCE)
    rows = [m.regressors for m in T2_MODELS] * RUNS
    tests = IdentifiabilityMonitor(rows, [[REGRESSOR_UNITS[r] for r in row] for row in rows], config)
    r, c = parameter_cells(RUNS)
    untested = np.full((RUNS, len(PARAMETERS)), np.inf)
    tested = np.full((RUNS, len(PARAMETERS)), np.inf)
    for k in range(t.size):
        bank.update(X[k], Z[k])
        tests.add(X[k], Z[k])
        flags, _ = monitor.update(int(round(t[k] * 1e9)), bank.theta_all(), bank.standard_errors_all(), bank.ready)
        untested = np.where(np.isinf(untested) & flags[r, c], t[k], untested)
        ok = tests.judge(bank, bank.ready)
        tested = np.where(np.isinf(tested) & (flags & ok)[r, c], t[k], tested)
    return untested, tested


@pytest.mark.parametrize("config", [IdentifiabilityConfig(), IdentifiabilityConfig(min_r_squared=0.97)])
def test_flag_times_are_the_monitors_less_what_the_tests_take_out(config):
    """The default tests hold nothing back on the maneuver at 20 %; a fit criterion of R^2 0.97
    (above what the noisy C_m model reaches) delays or withholds flags, and the summary counts
    exactly those runs."""
    res = run_level(0.2, RUNS, identifiability=config)
    untested, tested = first_flags(0.2, config)
    np.testing.assert_array_equal(res.untested_flag_time, untested)
    np.testing.assert_array_equal(res.flag_time, tested)
    rows = {row["parameter"]: row for row in convergence_summary(res)}
    for i, name in enumerate(PARAMETERS):
        assert rows[name]["held_back"] == pytest.approx(np.mean(tested[:, i] > untested[:, i]))
        assert rows[name]["untested_flag_time_median"] == pytest.approx(np.median(untested[:, i]))
    held = [rows[name]["held_back"] for name in PARAMETERS]
    if config == IdentifiabilityConfig():
        assert held == [0.0] * len(PARAMETERS) and np.array_equal(tested, untested)
    else:
        assert max(held) > 0.0 and np.all(tested >= untested)


def test_the_variants_differ_in_the_measured_elevator_only():
    """C_Z's regressors are (1, alpha, delta_e), C_m's (1, alpha, q_hat, delta_e); the outputs
    come from a_z and the differentiated q. Only the elevator columns may differ."""
    _t, _r, _s, X_all, Z_all = level_inputs(0.2, 3, band_limited_on=SIGNALS)
    _t, _r, _s, X_resp, Z_resp = level_inputs(0.2, 3, band_limited_on=RESPONSES)
    np.testing.assert_array_equal(Z_all, Z_resp)
    elevator = np.zeros(X_all.shape[1:], dtype=bool)
    elevator[0::2, 2] = elevator[1::2, 3] = True  # C_Z's column 2, C_m's column 3
    np.testing.assert_array_equal(X_all[:, ~elevator], X_resp[:, ~elevator])
    assert np.all(np.any(X_all[:, elevator] != X_resp[:, elevator], axis=0))
    _t, _r, _s, X0_all, _z = level_inputs(0.0, 2, band_limited_on=SIGNALS)
    _t, _r, _s, X0_resp, _z = level_inputs(0.0, 2, band_limited_on=RESPONSES)
    np.testing.assert_array_equal(X0_all, X0_resp)  # no band-limited noise: the same runs


def test_the_default_is_the_responses_and_the_result_says_which():
    assert BAND_LIMITED_ON == RESPONSES
    _t, _r, _s, X_default, _z = level_inputs(0.1, 2)
    _t, _r, _s, X_resp, _z = level_inputs(0.1, 2, band_limited_on=RESPONSES)
    np.testing.assert_array_equal(X_default, X_resp)
    assert run_level(0.1, 2, band_limited_on=SIGNALS).band_limited_on == SIGNALS


def test_levels_on_an_executor_are_the_levels_run_here(tmp_path, capsys):
    direct = [run_level(lv, 3, band_limited_on=SIGNALS) for lv in (0.05, 0.2)]
    pooled = run_table3(3, (0.05, 0.2), executor=LocalProcesses(2), band_limited_on=SIGNALS, progress=lambda _s: None)
    for a, b in zip(direct, pooled, strict=True):
        assert a.level == b.level and a.summary() == b.summary()
    assert cli.main(["montecarlo", "--runs", "3", "--levels", "20", "--noise-on", "all", "--workers", "1",
                     "--no-figures", "--out", str(tmp_path / "mc")]) == 0
    assert "Band-limited noise on delta_e, alpha, q, az" in (tmp_path / "mc" / "table3.md").read_text()
    assert "band-limited noise on all" in capsys.readouterr().out
