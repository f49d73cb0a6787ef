"""Identifiability (rls_uncertainty.datapath.identifiability): the running regressor statistics against
numpy's batch formulas, R^2 against a batch least-squares fit, the parameter correlations
against the bank's own covariance, and each test of a parameter (fit, excitation,
collinearity) on data built to pass or fail it, with what is said of a model not ready.
No ROS; numpy only."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

from rls_uncertainty.datapath.identifiability import (
    ANGLE,
    BIAS,
    NONDIMENSIONAL,
    IdentifiabilityConfig,
    IdentifiabilityMonitor,
    RegressorStatistics,
    r_squared,
)
from rls_uncertainty.errors import ConfigError
from rls_uncertainty.estimator import EstimatorBank, EstimatorOptions

N = 600


def maneuver(seed=0, n=N):
    """Three smooth, independent regressors (rad), a bias, and a noisy output of known slopes."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) / 50.0
    x = np.column_stack([np.ones(n), 0.05 + 0.02 * np.sin(1.3 * t), 0.03 * np.sin(2.9 * t + 1.0),
                         0.01 * np.sin(0.7 * t + 2.0) + 0.002 * rng.standard_normal(n)])
    z = x @ np.array([0.1, -4.0, 0.3, 1.5]) + 0.01 * rng.standard_normal(n)
    return x, z


DEFAULTS = IdentifiabilityConfig()


def run(x, z, units=(BIAS, ANGLE, ANGLE, ANGLE), config=DEFAULTS, forgetting=1.0, names=None):
    """One model through a bank and a monitor, judged at every sample; the last judgement."""
    names = names or tuple(f"r{i}" if u is not BIAS else "1" for i, u in enumerate(units))
    bank = EstimatorBank([x.shape[1]], EstimatorOptions(lags=10, forgetting=forgetting))
    monitor = IdentifiabilityMonitor([names], [list(units)], config, forgetting)
    for k in range(x.shape[0]):
        bank.update(x[k][None, :], z[k : k + 1])
        monitor.add(x[k][None, :], z[k : k + 1])
        monitor.restrict(np.ones((1, x.shape[1]), dtype=bool), np.ones(1, dtype=bool), bank, bank.ready)
    return bank, monitor


@pytest.mark.parametrize("forgetting", [1.0, 0.98])
def test_regressor_statistics_equal_the_weighted_batch_mean_and_covariance(forgetting):
    x, _ = maneuver()
    x = x + 1e3  # an offset far above the variation: the running form must not cancel
    stats = RegressorStatistics((1, 4), forgetting)
    for row in x:
        stats.add(row[None, :])
    w = forgetting ** np.arange(N - 1, -1, -1.0)
    mean = w @ x / w.sum()
    cov = (x - mean).T @ ((x - mean) * w[:, None]) / w.sum()
    np.testing.assert_allclose(stats.mean[0], mean, rtol=1e-13)
    np.testing.assert_allclose(stats.std[0, 1:], np.sqrt(np.diag(cov))[1:], rtol=1e-8)
    assert stats.std[0, 0] == 0.0  # the bias column does not vary
    corr = cov[1:, 1:] / np.sqrt(np.outer(np.diag(cov)[1:], np.diag(cov)[1:]))
    np.testing.assert_allclose(stats.correlation()[0, 1:, 1:], corr, rtol=1e-7, atol=1e-9)
    assert np.all(stats.correlation()[0, 0] == 0.0)  # a column that did not vary: 0, not NaN


def test_r_squared_is_the_batch_coefficient_of_determination():
    x, z = maneuver()
    bank, monitor = run(x, z)
    theta = np.linalg.lstsq(x, z, rcond=None)[0]
    sse, sst = np.sum((z - x @ theta) ** 2), np.sum((z - z.mean()) ** 2)
    assert monitor.fit(bank)[0] == pytest.approx(1.0 - sse / sst, rel=1e-10)
    # r_squared is NaN for a constant output and for a model not ready.
    assert np.isnan(r_squared(np.array([0.0]), np.array([3.0 * N]), np.array([9.0 * N]), N)).all()
    assert np.isnan(r_squared(np.array([np.nan]), np.array([1.0]), np.array([2.0]), 2.0)).all()


def test_parameter_correlations_are_the_corrected_covariances():
    x, z = maneuver()
    bank, monitor = run(x, z)
    c = bank.covariance(0, "corrected")
    np.testing.assert_allclose(monitor.correlation[0], c / np.sqrt(np.outer(np.diag(c), np.diag(c))), rtol=1e-12)
    assert monitor.identifiable[0].all() and monitor.problems(0) == []
    report = monitor.report(0, ("C_0", "C_a", "C_b", "C_c"))
    assert report["identifiable"] and report["not_identifiable"] == "" and report["held_back"] == ""
    assert report["excitation.r1"] == pytest.approx(x[:, 1].std(), rel=1e-3)


def test_two_regressors_moving_together_are_not_identifiable():
    """A surface commanded twice (x3 = x2 + 1e-4 rad of noise, enough for the exact
    initialization): the two slopes' estimates are correlated near -1 and neither is
    identifiable; the other slope and the bias are."""
    x, _ = maneuver()
    rng = np.random.default_rng(1)
    x[:, 3] = x[:, 2] + 1e-4 * rng.standard_normal(N)
    z = x[:, :3] @ np.array([0.1, -4.0, 0.3]) + 0.01 * rng.standard_normal(N)
    bank, monitor = run(x, z)
    assert bank.ready[0] and monitor.identifiable[0].tolist() == [True, True, False, False]
    assert monitor.correlation[0, 2, 3] < -0.999
    (p,) = monitor.problems(0)
    assert (p.kind, set(p.regressors)) == ("collinear", {"r2", "r3"}) and p.figures[0] < -0.999
    # A looser threshold than their correlation (within identifiability.max_correlation's range) lets them through.
    loose = IdentifiabilityConfig(max_correlation=abs(p.figures[0]) + 0.5 * (1 - abs(p.figures[0])))
    assert run(x, z, config=loose)[1].identifiable[0].all()


def test_a_regressor_that_does_not_move_is_not_excited_and_takes_the_bias_with_it():
    """A regressor varying 5e-5 rad about 0.1 rad (under the 1e-4 rad resolution) is not excited:
    its parameter, and the bias it is confounded with, are not identifiable; the same regressor
    about 0 leaves the bias identifiable; a nondimensional rate is tested against its own
    resolution."""
    x, z = maneuver()
    rng = np.random.default_rng(2)
    flat = 5e-5 * rng.standard_normal(N)
    for offset, bias_ok in ((0.1, False), (0.0, True)):
        xs = x.copy()
        xs[:, 3] = offset + flat
        bank, monitor = run(xs, z + 0.3 * xs[:, 3])
        assert bank.ready[0]
        assert monitor.identifiable[0].tolist() == [bias_ok, True, True, False], offset
        (p,) = monitor.problems(0)
        assert (p.kind, p.regressors, p.units) == ("not_excited", ("r3",), ("rad",))
        assert p.figures[0] == pytest.approx(flat.std(), rel=1e-2) and p.limits == (1e-4,)
    # As a nondimensional rate 5e-5 is well above the rates' 1e-6 floor, but it is white noise
    # only: the sensor-noise test takes it (ratio about 1); without that test it passes.
    _bank, monitor = run(xs, z, units=(BIAS, ANGLE, ANGLE, NONDIMENSIONAL))
    assert not monitor.identifiable[0, 3] and [p.kind for p in monitor.problems(0)] == ["noise"]
    no_noise_test = IdentifiabilityConfig(min_noise_ratio=0.0)
    assert run(xs, z, units=(BIAS, ANGLE, ANGLE, NONDIMENSIONAL), config=no_noise_test)[1].identifiable[0, 3]


@pytest.mark.parametrize("forgetting", [1.0, 0.995])
def test_the_sensor_noise_estimate_is_the_second_differences_mean_square_over_six(forgetting):
    """White noise of sigma 0.01 on a 2 Hz sine at 50 Hz: sigma_hat within 5 % of 0.01 over
    2000 samples (the sine leaks (2 sin(pi 2/50))^2 = 6 % of its own variance into the second
    differences, 2e-7 against sigma^2 = 1e-4); the running sums equal the batch weighted mean
    square of np.diff(x, 2) over 6; a break in the chain restarts the differences, not the sums."""
    rng = np.random.default_rng(8)
    n, sigma = 2000, 0.01
    t = np.arange(n) / 50.0
    x = 0.002 * np.sin(2 * np.pi * 2.0 * t) + sigma * rng.standard_normal(n)
    stats = RegressorStatistics((1, 1), forgetting)
    for k in range(n):
        if k == 1200:
            stats.restart_chain()
        stats.add(x[k : k + 1, None])
    d = np.concatenate([np.diff(x[:1200], 2), np.diff(x[1200:], 2)])
    k_of_d = np.concatenate([np.arange(2, 1200), np.arange(1202, n)])
    w = forgetting ** (n - 1 - k_of_d)
    np.testing.assert_allclose(stats.noise_variance[0, 0], w @ d**2 / (6 * w.sum()), rtol=1e-12)
    if forgetting == 1.0:
        assert np.sqrt(stats.noise_variance[0, 0]) == pytest.approx(sigma, rel=0.05)


def test_a_regressor_moving_no_more_than_its_sensor_noise_is_not_identifiable_with_its_reason():
    """Regressor r3 = white noise of sigma 0.002 only (ratio about 1, over the 1e-4 rad floor):
    not identifiable, the reason 'noise' with its std and its noise's; the same white noise on
    a 0.03 rad sine (ratio about 113) is identifiable; the ratio limit decides in between."""
    x, z = maneuver()
    rng = np.random.default_rng(4)
    noise = 0.002 * rng.standard_normal(N)
    x[:, 3] = noise
    _bank, monitor = run(x, z)
    assert monitor.identifiable[0].tolist() == [True, True, True, False]
    (p,) = monitor.problems(0)
    assert (p.kind, p.regressors, p.units, p.limits) == ("noise", ("r3",), ("rad",), (10.0,))
    assert p.figures[0] == pytest.approx(noise.std(), rel=1e-6)
    assert p.figures[1] == pytest.approx(np.sqrt(np.mean(np.diff(noise, 2) ** 2) / 6), rel=1e-9)
    report = monitor.report(0, ("C_0", "C_a", "C_b", "C_c"))
    assert report["noise.r3"] == pytest.approx(p.figures[1], rel=1e-3)
    x[:, 3] = 0.03 * np.sin(2 * np.pi * 0.5 * np.arange(N) / 50.0) + noise
    assert run(x, z)[1].identifiable[0].all()
    ratio = x[:, 3].var() / (np.mean(np.diff(x[:, 3], 2) ** 2) / 6)
    assert 50 < ratio < 200
    assert not run(x, z, config=IdentifiabilityConfig(min_noise_ratio=1.2 * ratio))[1].identifiable[0, 3]


def test_a_model_that_explains_nothing_has_no_identifiable_parameter():
    """Output noise only (the regressors move, the output does not follow): R^2 near 0."""
    x, _ = maneuver()
    z = 0.01 * np.random.default_rng(3).standard_normal(N)
    _bank, monitor = run(x, z)
    assert monitor.r_squared[0] < 0.05 and not monitor.identifiable[0].any()
    (p,) = monitor.problems(0)
    assert p.kind == "no_fit" and p.figures[0] == monitor.r_squared[0] and p.limits == (0.5,)
    assert run(x, z, config=IdentifiabilityConfig(min_r_squared=0.0))[1].identifiable[0].all()


def test_a_model_not_ready_names_what_keeps_it_waiting_once_it_waited_long_enough():
    x, z = maneuver()
    constant = x.copy()
    constant[:, 2] = 0.0  # never moves: exact initialization waits for ever
    bank, monitor = run(constant, z)
    assert not bank.ready[0] and not monitor.identifiable.any()
    assert monitor.problems(0, named_after=N + 1) == []  # not yet
    (p,) = monitor.problems(0, named_after=100)
    assert (p.kind, p.regressors, p.figures, p.samples) == ("constant", ("r2",), (0.0,), N)
    twins = x.copy()
    twins[:, 3] = 2.0 * twins[:, 2]  # exactly collinear
    (p,) = run(twins, z)[1].problems(0, named_after=100)
    assert (p.kind, set(p.regressors)) == ("correlated", {"r2", "r3"}) and p.figures[0] == pytest.approx(1.0)


def test_restrict_takes_the_flags_of_parameters_not_identifiable_out_and_judges_only_when_asked():
    """Two models in one bank: one with a regressor that does not move (its slope and the bias
    are not identifiable), one healthy. Flags of parameters not identifiable are taken out and
    kept in held_back; a model keeps its flag only when all its parameters do. With no flag up
    nothing is judged at the sample, and reading the figures judges the same sample."""
    x, z = maneuver()
    flat = x.copy()
    flat[:, 3] = 0.1 + 5e-5 * np.random.default_rng(4).standard_normal(N)
    bank = EstimatorBank([4, 4], EstimatorOptions(lags=10))
    monitor = IdentifiabilityMonitor([("1", "a", "b", "c")] * 2, [[BIAS, ANGLE, ANGLE, ANGLE]] * 2)
    for k in range(N):
        X, Z = np.stack([flat[k], x[k]]), np.array([z[k] + 0.3 * flat[k, 3], z[k]])
        bank.update(X, Z)
        monitor.add(X, Z)
    ready = bank.ready
    got, model = monitor.restrict(np.zeros((2, 4), dtype=bool), np.zeros(2, dtype=bool), bank, ready)
    assert not got.any() and not model.any() and not monitor.held_back.any() and not monitor._judged
    assert monitor.identifiable.tolist() == [[False, True, True, False], [True] * 4]  # judged when read
    flags = np.array([[True, True, False, True], [True, True, True, True]])
    got, model = monitor.restrict(flags, np.array([True, True]), bank, ready)
    assert got.tolist() == [[False, True, False, False], [True] * 4] and model.tolist() == [False, True]
    assert monitor.held_back.tolist() == [[True, False, False, True], [False] * 4]


@pytest.mark.parametrize("field,value", [
    ("max_correlation", 1.0), ("max_correlation", 0.0), ("min_r_squared", 1.0), ("min_r_squared", -0.1),
    ("angle_resolution", -1e-4), ("rate_resolution", float("nan")), ("max_correlation", True),
])
def test_invalid_thresholds_are_refused_naming_the_parameter(field, value):
    with pytest.raises(ConfigError, match=f"identifiability.{field}"):
        IdentifiabilityConfig(**{field: value})


def test_the_module_imports_numpy_only():
    code = "import sys, rls_uncertainty.datapath.identifiability; " \
           "print(sorted({m.split('.')[0] for m in sys.modules} & {'rclpy', 'rosbags', 'yaml', 'scipy', 'mcap'}))"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]"
