"""The batch reference against independent computations: the error identity behind the corrected
covariance (F6), an exact fit, and its covariance as an explicit matrix product when the
equation error's covariance is known."""

from __future__ import annotations

import numpy as np

from rls_uncertainty.frequency import FrequencyOptions, frequency_reference

RATE = 50.0


def regressors(N: int) -> np.ndarray:
    t = np.arange(N) / RATE
    return np.column_stack([np.sin(2 * np.pi * 0.35 * t) * (t > 0.5), np.cos(2 * np.pi * 1.1 * t) + 0.1 * t**2])


def test_the_estimate_error_is_the_h_weighted_sum_of_the_equation_error():
    # F6: for z_n = b + x_n' theta + e_n, theta_hat - theta = A^-1 sum_n h_n e_n exactly, whatever
    # e is (the first sample's e_0, subtracted from every sample, is carried by h_0).
    rng = np.random.default_rng(4)
    N = 240
    x = regressors(N)
    theta = np.array([2.0, -1.0])
    e = np.cumsum(rng.standard_normal(N)) * 0.05 + 0.3 * rng.standard_normal(N)  # anything
    fit = frequency_reference(x, 5.0 + x @ theta + e, FrequencyOptions(rate_hz=RATE))
    A = (fit.X.conj().T @ fit.X).real
    np.testing.assert_allclose(fit.theta - theta, np.linalg.solve(A, fit.h.T @ e), rtol=1e-10, atol=1e-13)
    assert abs(fit.h.sum(axis=0)).max() < 1e-12 * abs(fit.h).max() * N  # blind to a constant


def test_an_exact_fit_recovers_the_parameters():
    x = regressors(300)
    fit = frequency_reference(x, -1.0 + x @ [0.5, 3.0], FrequencyOptions(rate_hz=RATE, f_max=2.0))
    np.testing.assert_allclose(fit.theta, [0.5, 3.0], rtol=1e-11)


def test_with_the_true_equation_error_covariance_the_sandwich_is_an_explicit_matrix_product():
    # Known Sigma = cov(e): cov(theta_hat) = A^-1 h' Sigma h A^-1 (F6). Compare with the
    # covariance of the estimates computed as the explicit linear map of e, G Sigma G', where
    # row k of G holds theta_hat's response to a unit e at sample k (100 fits).
    N = 100
    x = regressors(N)
    options = FrequencyOptions(rate_hz=RATE, f_max=2.0, n_lags=0, dof_correction=False)  # R unused here
    base = frequency_reference(x, x @ [1.0, 1.0], options).theta
    G = np.array([frequency_reference(x, x @ [1.0, 1.0] + np.eye(N)[k], options).theta - base for k in range(N)]).T
    lag = np.abs(np.subtract.outer(np.arange(N), np.arange(N)))
    Sigma = 0.8**lag + 0.5 * (lag == 0)
    fit = frequency_reference(x, x @ [1.0, 1.0], options)
    A_inv = np.linalg.inv((fit.X.conj().T @ fit.X).real)
    np.testing.assert_allclose(A_inv @ fit.h.T @ Sigma @ fit.h @ A_inv, G @ Sigma @ G.T, rtol=1e-9)
