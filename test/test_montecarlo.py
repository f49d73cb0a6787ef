"""The Table 3 Monte Carlo's convergence flags with the node's identifiability tests
(rls_uncertainty.simulation.montecarlo): the flags it reports are those of an independent convergence
monitor less what an independent identifiability monitor takes out, and the held-back
statistics count exactly the runs whose first flag the tests delayed. No ROS.

montecarlo.py's noise variant and executors: the band-limited noise on all four measured
signals or on the responses only (the default, docs/validation.md), the same random draws in
both; the levels run on any executor with the same numbers. No ROS.

The methods and the batches: the frequency-domain results against a bank of its own, the
batches of runs on two workers bit for bit as on one, the method column of the outputs."""

from __future__ import annotations

import numpy as np
import pytest
from bag_samples import fails

from rls_uncertainty import cli
from rls_uncertainty.datapath.convergence import ConvergenceMonitor
from rls_uncertainty.datapath.identifiability import IdentifiabilityConfig, IdentifiabilityMonitor
from rls_uncertainty.estimator import EstimatorBank
from rls_uncertainty.executors import LocalProcesses
from rls_uncertainty.frequency import FrequencyBank
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
    t2_frequency_options,
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


# --------------------------------------------------------------- methods and batches
def _same(a, b):
    """Every field of two LevelResults equal, bit for bit (NaN where NaN)."""
    for name, x in vars(a).items():
        y = getattr(b, name)
        if isinstance(x, np.ndarray):
            assert x.dtype == y.dtype and np.array_equal(x, y, equal_nan=x.dtype.kind == "f"), name
        elif isinstance(x, dict):
            assert x.keys() == y.keys(), name
            for key in x:
                assert np.array_equal(np.asarray(x[key]), np.asarray(y[key]), equal_nan=True), (name, key)
        else:
            assert x == y, name


def test_batches_on_two_workers_are_the_serial_run_bit_for_bit():
    """Both methods, the runs of two levels cut into batches of 2 (the last one short): two local
    worker processes give every array of every result as one process does."""
    kw = dict(levels=(0.05, 0.2), method="both", batch_runs=2, progress=lambda _s: None)
    serial = run_table3(5, executor=LocalProcesses(1), **kw)
    pooled = run_table3(5, executor=LocalProcesses(2), **kw)
    assert [(r.level, r.method) for r in serial] == [(0.05, "time"), (0.05, "frequency"), (0.2, "time"),
                                                     (0.2, "frequency")]
    assert [(r.level, r.method) for r in pooled] == [(r.level, r.method) for r in serial]
    for a, b in zip(serial, pooled, strict=True):
        _same(a, b)
        assert a.runs == 5 and a.estimates.shape == (5, len(PARAMETERS))


def test_time_domain_batches_are_one_bank_of_every_run():
    """The time-domain bank's models are independent: cut into batches the runs give the numbers
    of one bank of all of them, bit for bit."""
    _same(run_level(0.2, 5, batch_runs=2), run_level(0.2, 5, batch_runs=5))


def test_frequency_domain_against_an_independent_recomputation():
    """The frequency-domain results of one batch: a FrequencyBank on the same rows without the
    bias column (every T-2 model has it first), the Table 3 parameters picked from it, the
    convergence monitor's first flags (the node's identifiability tests hold nothing back on
    this maneuver, as in the time domain) and the statistics over runs."""
    runs, options = RUNS, t2_frequency_options()
    res = run_level(0.2, runs, method="frequency", batch_runs=runs)
    assert res.method == "frequency" and res.frequency == options and res.lags == options.n_lags
    t, _red, sizes, X, Z = level_inputs(0.2, runs)
    bank = FrequencyBank([s - 1 for s in sizes], options)
    monitor = ConvergenceMonitor([s - 1 for s in sizes], MONTE_CARLO_CONVERGENCE)
    cols = [c - 1 for c in parameter_cells(runs)[1][0]]
    rows = parameter_cells(runs)[0]
    first = np.full((runs, len(PARAMETERS)), np.inf)
    theta = np.empty((t.size, runs, len(PARAMETERS)))
    for k in range(t.size):
        bank.update(X[k][:, 1:], Z[k])
        theta[k] = bank.theta_all()[rows, cols]
        flags, _ = monitor.update(int(round(t[k] * 1e9)), bank.theta_all(), bank.standard_errors_all(), bank.ready)
        first = np.where(np.isinf(first) & flags[rows, cols], t[k], first)
    np.testing.assert_array_equal(res.estimates, bank.theta_all()[rows, cols])
    np.testing.assert_array_equal(res.se_corrected, bank.standard_errors_all("corrected")[rows, cols])
    np.testing.assert_array_equal(res.se_conventional, bank.standard_errors_all("conventional")[rows, cols])
    np.testing.assert_array_equal(res.untested_flag_time, first)
    np.testing.assert_array_equal(res.flag_time, first)
    assert np.isfinite(first).mean() > 0.9  # real flags
    s = res.summary()
    for i, name in enumerate(PARAMETERS):
        assert s[name]["scatter"] == pytest.approx(np.std(res.estimates[:, i], ddof=1), rel=1e-12)
        assert s[name]["mean"] == pytest.approx(np.mean(theta[-1, :, i]), rel=1e-12)
        assert np.isnan(s[name]["se_batch"]) and np.isnan(s[name]["se_corrected_all"])
    np.testing.assert_allclose(res.ensemble_mean[-1], theta[-1].mean(axis=0), rtol=1e-12)


def test_the_outputs_name_the_method_only_beside_the_frequency_domain(tmp_path):
    """--method time writes today's columns; both adds a method column, with the time-domain rows
    those of --method time (the same runs) and the frequency-domain rows of their own; frequency
    alone names its rows too and draws no time-domain figure."""
    import csv

    base = ["montecarlo", "--runs", "3", "--levels", "20", "--workers", "1"]
    for method in ("time", "both", "frequency"):
        extra = [] if method == "time" else ["--method", method]
        assert cli.main([*base, *extra, "--no-figures", "--out", str(tmp_path / method)]) == 0
    read = {m: list(csv.DictReader((tmp_path / m / "table3.csv").read_text().splitlines()))
            for m in ("time", "both", "frequency")}
    assert "method" not in read["time"][0]
    assert [r["method"] for r in read["both"]] == ["time"] * 5 + ["frequency"] * 5
    for a, b in zip(read["time"], read["both"][:5], strict=True):
        assert a == {k: v for k, v in b.items() if k != "method"}
    assert read["frequency"] == read["both"][5:]
    assert read["both"][5]["mean"] != read["both"][0]["mean"]
    md = (tmp_path / "both" / "table3.md").read_text()
    assert "| 20% | frequency | Cm_q |" in md and "| level | method | parameter |" in md
    assert "grid 0.2-2.2 Hz every 0.04 Hz, trim 25 samples" in md
    conv = list(csv.DictReader((tmp_path / "both" / "convergence.csv").read_text().splitlines()))
    assert [r["method"] for r in conv] == ["time"] * 7 + ["frequency"] * 7
    assert "| 20% | Cm_q |" in (tmp_path / "time" / "table3.md").read_text()


def test_one_method_per_level_and_known_methods_only(capsys, tmp_path):
    from rls_uncertainty.errors import ConfigError

    with pytest.raises(ConfigError, match="one method"):
        run_level(0.2, 2, method="both")
    with pytest.raises(ConfigError, match="time, frequency, both"):
        run_table3(2, (0.2,), method="fft")
    fails(capsys, ["montecarlo", "--runs", "2", "--method", "fft", "--out", str(tmp_path / "mc")],
          "argument --method: invalid choice: 'fft'")
    assert not (tmp_path / "mc").exists()
