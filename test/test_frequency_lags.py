"""Lag-product sums (docs/frequency.md, F9-F10): the centered lag sums equal the products of the
centered samples, the residual autocovariance equals that of an explicit least-squares fit and,
corrected for the fit's degrees of freedom, the literal reference's, and the correction removes
the fit's bias of R on average."""

from __future__ import annotations

import numpy as np
import pytest

from rls_uncertainty.frequency import FrequencyOptions, frequency_reference
from rls_uncertainty.frequency.lags import LagSums, residual_autocovariance
from rls_uncertainty.simulation.montecarlo import level_inputs


def brute_centered(u: np.ndarray, lags: int) -> np.ndarray:
    """sum_(n=i..N-1) (u_n - m)(u_(n-i) - m)' for i = 0..lags, from the samples."""
    c = u - u.mean(axis=0)
    return np.array([c[i:].T @ c[: len(c) - i] for i in range(lags + 1)])


@pytest.mark.parametrize("n_lags", [0, 1, 7, 40])
def test_centered_lag_sums_equal_the_products_of_the_centered_samples(n_lags):
    rng = np.random.default_rng(n_lags)
    u = rng.standard_normal((90, 2, 3)) + np.array([5.0, -2.0, 0.5])
    sums = LagSums(2, 3, n_lags)
    for k in range(u.shape[0]):
        sums.update(u[k])
        N = k + 1
        if N in (1, 2, n_lags, n_lags + 1, n_lags + 2, 90):
            got = sums.centered()
            lags = min(n_lags, N - 1)
            assert got.shape == (2, lags + 1, 3, 3)
            for m in range(2):
                np.testing.assert_allclose(got[m], brute_centered(u[:N, m], lags), rtol=1e-10, atol=1e-11)


def brute_augmented(u: np.ndarray, lags: int) -> np.ndarray:
    """sum_(n=i..N-1) (u_n, 1)(u_(n-i), 1)' for i = 0..lags, from the samples."""
    a = np.column_stack([u, np.ones(len(u))])
    return np.array([a[i:].T @ a[: len(a) - i] for i in range(lags + 1)])


@pytest.mark.parametrize("n_lags", [0, 3, 40])
def test_the_augmented_sums_new_or_reused_equal_the_products_of_the_samples(n_lags):
    rng = np.random.default_rng(10 + n_lags)
    u = rng.standard_normal((60, 2, 3))
    sums = LagSums(2, 3, n_lags)
    kept = None
    for k in range(60):
        sums.update(u[k])
        N = k + 1
        lags = min(n_lags, N - 1)
        new, reused = sums.augmented(), sums.augmented(reuse=True)
        assert new.shape == reused.shape == (2, lags + 1, 4, 4) and reused.flags.c_contiguous
        for m in range(2):
            np.testing.assert_allclose(new[m], brute_augmented(u[:N, m], lags), rtol=1e-12, atol=1e-12)
        np.testing.assert_array_equal(reused, new)
        np.testing.assert_array_equal(sums.sums[:, : lags + 1], new)
        if kept is not None and kept.shape == reused.shape:  # the lags stay: the same array, overwritten
            assert reused is kept
        kept = reused
        new[...] = np.nan  # a new array: the sums are not changed through it
        assert np.isfinite(sums.augmented()).all()


def test_the_residual_autocovariance_is_that_of_the_least_squares_fit_with_a_bias():
    rng = np.random.default_rng(1)
    N, L = 120, 10
    x = rng.standard_normal((N, 2))
    z = 3.0 + x @ [1.0, -2.0] + np.convolve(rng.standard_normal(N + 4), np.ones(5) / 5, "valid")
    sums = LagSums(1, 3, L)
    for k in range(N):
        sums.update(np.r_[z[k], x[k]][None])
    R = residual_autocovariance(sums.augmented(), np.ones((1, 3), bool), N, correct=False)[0][0]
    design = np.column_stack([np.ones(N), x])
    v = z - design @ np.linalg.lstsq(design, z, rcond=None)[0]
    np.testing.assert_allclose(R, [v[i:] @ v[: N - i] / N for i in range(L + 1)], rtol=1e-10, atol=1e-14)


def test_padded_and_constant_regressors_are_left_out_of_the_fit():
    rng = np.random.default_rng(2)
    N = 60
    x = rng.standard_normal(N)
    z = 2 * x + rng.standard_normal(N)
    u = np.column_stack([z, x, np.full(N, 4.0), np.zeros(N)])  # a constant and a padded column
    sums = LagSums(1, 4, 5)
    for k in range(N):
        sums.update(u[k][None])
    cols = np.array([[True, True, True, False]])
    R = residual_autocovariance(sums.augmented(), cols, N, correct=False)[0][0]
    design = np.column_stack([np.ones(N), x])
    v = z - design @ np.linalg.lstsq(design, z, rcond=None)[0]
    np.testing.assert_allclose(R[0], v @ v / N, rtol=1e-10)


def test_the_dof_correction_removes_the_fits_bias_of_the_autocovariance_on_average():
    # White noise through a 2-regressor fit over 80 samples: E[R_v(0)] = sigma^2 (N - 3) / N for
    # the residuals of a fit with a bias (3 parameters) -- a bias of 3.75 %. Over 3000 records the
    # mean uncorrected R(0) shows it; the corrected one must be within its Monte Carlo error.
    rng = np.random.default_rng(7)
    N, runs, L = 80, 3000, 4
    t = np.arange(N) / 50
    x = np.column_stack([np.sin(2 * np.pi * 0.8 * t), np.cos(2 * np.pi * 1.9 * t) + t])
    e = rng.standard_normal((runs, N))
    sums = LagSums(runs, 3, L)
    for k in range(N):
        sums.update(np.column_stack([e[:, k] + x[k] @ [1.0, 2.0], np.broadcast_to(x[k], (runs, 2))]))
    C = sums.augmented()
    cols = np.ones((runs, 3), bool)
    plain = residual_autocovariance(C, cols, N, correct=False)[0][:, 0].mean()
    corrected = residual_autocovariance(C, cols, N, correct=True)[0][:, 0].mean()
    tolerance = 4 * np.sqrt(2 / (N * runs))  # four standard errors of the mean of R(0)
    assert plain == pytest.approx((N - 3) / N, abs=tolerance)
    assert corrected == pytest.approx(1.0, abs=tolerance)


def records():
    """(name, x (N, p), z (N,)): random regressors and output, and the simulated T-2's C_m
    (alpha, q_hat, delta_e) at 0 and 20 % band-limited noise."""
    rng = np.random.default_rng(3)
    x = rng.standard_normal((240, 3))
    yield "random", x, x @ [0.3, -1.0, 2.0] + rng.standard_normal(240)
    for noise in (0.0, 0.2):
        _t, _red, _sizes, X, Z = level_inputs(noise, 1, seed=5)
        yield f"T-2 C_m {noise:.0%}", X[:240, 1, 1:4], Z[:240, 1]


@pytest.mark.parametrize("n_lags", [0, 7, 50])
@pytest.mark.parametrize("correct", [True, False])
def test_the_autocovariance_equals_the_literal_references(n_lags, correct):
    # The reference forms R from the explicit residuals and writes F10 over the samples; the lag
    # sums give the same numbers to 1e-12 of R(0) (rounding of the record's cancellation).
    options = FrequencyOptions(rate_hz=50.0, n_lags=n_lags, dof_correction=correct)
    for name, x, z in records():
        sums = LagSums(1, 4, n_lags)
        for k in range(x.shape[0]):
            sums.update(np.r_[z[k] - z[0], x[k] - x[0]][None])
            N = k + 1
            if N not in (n_lags + 1, n_lags + 2, 60, 240) or N < 8:
                continue
            R = residual_autocovariance(sums.augmented(), np.ones((1, 4), bool), N, correct)[0][0]
            ref = frequency_reference(x[:N], z[:N], options).R
            np.testing.assert_allclose(R, ref, rtol=0, atol=1e-12 * ref[0], err_msg=f"{name}, N = {N}")
