"""Covariances (Eqs. 13, 16, 20-22): against the batch formula on the recursive residuals,
closed forms, Monte Carlo scatter, the lag windows and their repair; the published standard
errors are the covariances' diagonals."""

from __future__ import annotations

import numpy as np
import pytest
from test_estimator_cases import RATE, ar1, indefinite_problem, rel_close, run, wide_scale_problem

from rls_uncertainty.estimator import EstimatorBank, EstimatorOptions, RecursiveEstimator, batch_estimate

CHECK_AT = (40, 200, 600)


@pytest.mark.parametrize("forgetting", [1.0, 0.98])
@pytest.mark.parametrize("window", ["truncated", "bartlett"])
@pytest.mark.parametrize("lags", ["all", 0, 1, 5, 50])
def test_recursive_covariance_equals_batch_formula_on_recursive_residuals(lags, window, forgetting):
    """The estimator's own residuals (``noise_forgetting = forgetting``: the paper's formulas,
    and under forgetting those that under-report; docs/estimator.md)."""
    X, z = wide_scale_problem()
    options = EstimatorOptions(lags=lags, window=window, forgetting=forgetting, noise_forgetting=forgetting)
    est = RecursiveEstimator(4, options)
    full = RecursiveEstimator(4, EstimatorOptions(lags="all", forgetting=forgetting))  # the whole residual history
    for k in range(len(z)):
        est.update(X[k], z[k])
        full.update(X[k], z[k])
        if k + 1 not in CHECK_AT:
            continue
        history = full.residuals()
        assert len(history) == k + 1
        # The ring of the truncated estimator holds the same residuals as the full history.
        np.testing.assert_array_equal(est.residuals(), history[-len(est.residuals()) :])
        theta, cov_conv, cov_corr = batch_estimate(
            X[: k + 1], z[: k + 1], lags, window, residuals=history, forgetting=forgetting
        )
        rel_close(est.theta, theta, 1e-9)
        rel_close(est.covariance("corrected", repair=False), cov_corr, 1e-9)
        rel_close(est.covariance("conventional"), cov_conv, 1e-9)

@pytest.mark.parametrize("window", ["truncated", "bartlett"])
@pytest.mark.parametrize("lags", [1, 5, 50])
def test_noise_model_covariance_equals_batch_formula_on_noise_model_residuals(lags, window):
    """Under forgetting R_k(i) comes from the noise model (RLS with f_R): the corrected and
    conventional covariances are the batch formulas with the f-weighted D, Lambda and the
    f_R-weighted autocorrelation of the noise model's residual history, and the noise
    residual is the standardized innovation of the f_R-weighted batch fit of the samples before."""
    X, z = wide_scale_problem()
    f = 0.98
    est = RecursiveEstimator(4, EstimatorOptions(lags=lags, window=window, forgetting=f))
    f_R = est.options.noise_forgetting_used
    assert f_R == max(f, 1.0 - 1.0 / (40.0 * (lags + 1))) > f
    full = RecursiveEstimator(4, EstimatorOptions(lags="all", forgetting=f, noise_forgetting=f_R))  # the whole history
    for k in range(len(z)):
        est.update(X[k], z[k])
        full.update(X[k], z[k])
        if k + 1 not in CHECK_AT:
            continue
        history = full.noise_residuals()
        assert len(history) == k + 1
        np.testing.assert_array_equal(est.noise_residuals(), history[-len(est.noise_residuals()) :])
        np.testing.assert_array_equal(est.residuals(), full.residuals()[-len(est.residuals()) :])
        theta, cov_conv, cov_corr = batch_estimate(
            X[: k + 1], z[: k + 1], lags, window, residuals=history, forgetting=f, noise_forgetting=f_R
        )
        rel_close(est.theta, theta, 1e-9)
        rel_close(est.covariance("corrected", repair=False), cov_corr, 1e-9)
        rel_close(est.covariance("conventional"), cov_conv, 1e-9)
        th_R = batch_estimate(X[:k], z[:k], 0, forgetting=f_R)[0]
        A = X[:k].T @ (X[:k] * (f_R ** np.arange(k - 1, -1, -1.0))[:, None])
        d = f_R + X[k] @ np.linalg.solve(A, X[k])
        assert history[-1] == pytest.approx((z[k] - X[k] @ th_R) * np.sqrt(f_R / d), rel=1e-7)


def test_zero_lags_gives_the_conventional_covariance():
    X, z = wide_scale_problem()
    est = run(RecursiveEstimator(4, EstimatorOptions(lags=0)), X, z)
    rel_close(est.covariance("corrected"), est.covariance("conventional"), 1e-9)
    np.testing.assert_allclose(
        est.standard_errors("corrected"), est.standard_errors("conventional"), rtol=1e-9
    )

def test_corrected_standard_error_grows_with_colored_residuals():
    X, z = wide_scale_problem()
    est = run(RecursiveEstimator(4, EstimatorOptions(lags=50)), X, z)
    ratio = est.standard_errors("corrected") / est.standard_errors("conventional")
    # The constant and the 0.3 Hz regressor sit where the AR(1) spectrum is high; the
    # white regressor averages the spectrum, which the conventional formula gets right.
    assert ratio[0] > 2.0 and ratio[2] > 2.0
    assert 0.5 < ratio[3] < 1.5

@pytest.mark.parametrize("rho", [0.9, 0.0])
def test_monte_carlo_standard_errors_match_observed_scatter(rho):
    """400 runs as one bank: same regressors, independent AR(1) or white residuals."""
    rng = np.random.default_rng(11)
    n, runs = 1000, 400
    t = np.arange(n) / RATE
    X = np.column_stack([np.ones(n), np.sin(2 * np.pi * 0.4 * t), np.cos(2 * np.pi * 0.9 * t + 0.3)])
    theta = np.array([1.0, 0.5, -0.3])
    Z = (X @ theta)[:, None] + 0.1 * ar1(rng, rho, (runs, n)).T
    bank = EstimatorBank([3] * runs, EstimatorOptions(lags=50))
    rows = np.ascontiguousarray(np.broadcast_to(X[:, None, :], (n, runs, 3)))
    for k in range(n):
        bank.update(rows[k], Z[k])
    estimates = bank.theta_all()
    scatter = estimates.std(axis=0, ddof=1)
    corrected = bank.standard_errors_all("corrected").mean(axis=0) / scatter
    conventional = bank.standard_errors_all("conventional").mean(axis=0) / scatter
    assert np.all(np.abs(corrected - 1.0) < 0.15), corrected
    if rho:
        assert np.all(conventional < 0.5), conventional
    else:
        assert np.all(np.abs(conventional - 1.0) < 0.15), conventional
    np.testing.assert_allclose(estimates.mean(axis=0), theta, atol=4 * scatter.max() / np.sqrt(runs))

def test_truncated_window_can_be_indefinite_and_is_repaired_and_counted():
    X, z = indefinite_problem()
    est = RecursiveEstimator(2, EstimatorOptions(lags=5, window="truncated"))
    full = RecursiveEstimator(2, EstimatorOptions(lags="all"))
    for k in range(len(z)):
        est.update(X[k], z[k])
        full.update(X[k], z[k])
        if est.is_ready:
            se = est.standard_errors()
            assert np.all(np.isfinite(se)) and np.all(se >= 0)
    raw = est.covariance(repair=False)
    batch_raw = batch_estimate(X, z, 5, "truncated", residuals=full.residuals())[2]
    assert np.min(np.diag(batch_raw)) < 0  # independent confirmation that it is indefinite
    rel_close(raw, batch_raw, 1e-9)
    repaired = est.covariance()
    assert np.min(np.linalg.eigvalsh(repaired)) > -1e-12 * np.max(np.abs(raw))
    np.testing.assert_allclose(repaired, repaired.T)
    assert est.repairs > 0

def test_bartlett_window_stays_positive_semidefinite():
    X, z = indefinite_problem()
    est = RecursiveEstimator(2, EstimatorOptions(lags=5, window="bartlett"))
    for k in range(len(z)):
        est.update(X[k], z[k])
        if est.is_ready and k % 25 == 0:
            cov = est.covariance(repair=False)
            assert np.min(np.linalg.eigvalsh(cov)) >= -1e-10 * np.max(np.abs(cov))
    assert est.repairs == 0

def test_an_exactly_fitted_model_has_zero_corrected_errors_without_repairs():
    rng = np.random.default_rng(5)
    X = np.column_stack([np.ones(300), rng.standard_normal(300), rng.standard_normal(300)])
    z = X @ np.array([0.3, -1.2, 0.7])  # no noise: residuals are rounding only
    bank = EstimatorBank([3], EstimatorOptions(lags=50))
    for k in range(300):
        bank.update(X[k : k + 1], z[k : k + 1])
    se = bank.standard_errors(0, "corrected")
    cov = bank.covariance(0, "corrected")
    assert np.all(np.isfinite(se)) and np.all(se < 1e-8)  # rounding-level, never NaN
    assert np.all(np.abs(cov) < 1e-16)
    assert bank.repairs[0] == 0
    # A constant output fitted exactly by its bias (the T-2 bag's CX): rounding makes the
    # corrected variances slightly negative; they are zero, not a repair.
    const = EstimatorBank([3], EstimatorOptions(lags=50))
    for k in range(300):
        const.update(X[k : k + 1], [-0.03])
    assert np.all(const.standard_errors(0, "corrected") == 0.0) or np.all(const.standard_errors(0, "corrected") < 1e-8)
    const.covariance(0, "corrected")
    assert const.repairs[0] == 0


@pytest.mark.parametrize("forgetting", [1.0, 0.99])
@pytest.mark.parametrize("lags, window", [("all", "truncated"), (5, "truncated"), (20, "bartlett"), (0, "truncated")])
def test_published_standard_errors_are_the_square_roots_of_the_covariance_diagonals(lags, window, forgetting):
    """standard_errors_all, standard_errors(j), covariance(j) and covariance_all() are one
    computation: the standard errors are exactly (bit for bit) sqrt(max(diag(covariance), 0))
    for both kinds, repaired covariances included, and the bank of six models equals its
    models alone."""
    X, z = indefinite_problem(300)
    rng = np.random.default_rng(2)
    rows = np.zeros((300, 3, 3))
    rows[:, 0, :2] = X
    rows[:, 1] = np.column_stack([X, rng.standard_normal(300)])
    rows[:, 2, :2] = X * [1.0, 3.0]
    Z = np.column_stack([z, z + rng.standard_normal(300), 0.5 * z])
    bank = EstimatorBank((2, 3, 2), EstimatorOptions(lags=lags, window=window, forgetting=forgetting))
    checked = repaired = 0
    due = [k for k in range(300) if k % 37 == 36 and k + 1 >= 3 + 2 * bank.options.publish_lags]
    for k in range(300):
        bank.update(rows[k], Z[k])
        if k % 37 != 36 or not bank.ready.all():  # (published from 2 lag windows on)
            continue
        every = bank.covariance_all()
        for i, kind in enumerate(("corrected", "conventional")):
            se_all = bank.standard_errors_all(kind)
            for j, s in enumerate(bank.sizes):
                cov = bank.covariance(j, kind)
                assert every[i, j, :s, :s].tobytes() == cov.tobytes()  # all at once: the same
                assert np.isnan(every[i, j, s:]).all() and np.isnan(every[i, j, :, s:]).all()
                expected = np.sqrt(np.maximum(np.diag(cov), 0.0))
                assert se_all[j, :s].tobytes() == expected.tobytes()
                assert bank.standard_errors(j, kind).tobytes() == expected.tobytes()
                assert np.isnan(se_all[j, s:]).all()
                raw = bank.covariance(j, kind, repair=False)
                np.testing.assert_array_equal(raw, raw.T)  # P + P' is exactly symmetric
                repaired += not np.array_equal(raw, cov)
                checked += 1
    assert checked == len(due) * 2 * 3 and len(due) >= 5
    if lags == 5:
        assert repaired > 0 and bank.repairs.sum() > 0

