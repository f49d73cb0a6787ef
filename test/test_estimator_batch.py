"""Batch formulas (Eqs. 6-14): batch_estimate against the written-out sums and the reference."""

from __future__ import annotations

import numpy as np
import pytest
from test_estimator_cases import ar1, rel_close

from rls_uncertainty.estimator import batch_estimate
from rls_uncertainty.estimator.reference import batch_reference


def test_batch_estimate_is_eq_11_double_sum():
    rng = np.random.default_rng(3)
    n = 60
    X = np.column_stack([np.ones(n), np.cumsum(rng.standard_normal(n)), rng.standard_normal(n)])
    z = X @ [1.0, 0.2, -0.5] + ar1(rng, 0.8, (n,))
    theta, cov_conv, cov_corr = batch_estimate(X, z)
    D = np.linalg.inv(X.T @ X)
    v = z - X @ theta
    R = np.array([np.sum(v[i:] * v[: n - i]) / n for i in range(n)])  # Eq. 10
    middle = sum(
        np.outer(X[i], X[j]) * R[abs(i - j)] for i in range(n) for j in range(n)
    )  # Eq. 11
    np.testing.assert_allclose(theta, np.linalg.solve(X.T @ X, X.T @ z), rtol=1e-10)
    np.testing.assert_allclose(cov_corr, D @ middle @ D, rtol=1e-10)
    np.testing.assert_allclose(cov_conv, (v @ v / n) * D, rtol=1e-12)  # Eqs. 13-14


@pytest.mark.parametrize("forgetting", [1.0, 0.97])
@pytest.mark.parametrize("window", ["truncated", "bartlett"])
@pytest.mark.parametrize("lags", ["all", 0, 7])
@pytest.mark.parametrize("given_residuals", [False, True])
def test_batch_estimate_equals_the_papers_matrices(lags, window, forgetting, given_residuals):
    """The blocked Toeplitz evaluation of batch_estimate equals Eq. 8 with the N x N matrix of
    Eq. 9 (reference.batch_reference), weighted, windowed, with or without given residuals."""
    rng = np.random.default_rng(4)
    n = 80
    X = np.column_stack([np.ones(n), np.sin(0.2 * np.arange(n)), rng.standard_normal(n)])
    z = X @ [0.3, -1.0, 0.5] + ar1(rng, 0.8, (n,))
    v = rng.standard_normal(n) if given_residuals else None
    fast = batch_estimate(X, z, lags, window, residuals=v, forgetting=forgetting)
    literal = batch_reference(X, z, lags, window, forgetting=forgetting, residuals=v)
    for a, b in zip(fast, literal, strict=True):
        rel_close(a, b, 1e-10)
