"""The corrected covariance in closed form (docs/frequency.md, F7-F8): the pair matrices equal the
explicit sums over the samples, the fast contraction equals the explicit sandwich and the literal
reference's sum over every pair of samples (to 1e-12 of its largest element, on random and
simulated records, several grids, lag spans and trims), and the covariance with the true noise
autocovariance matches the Monte Carlo scatter of the estimate where the conventional formula
does not."""

from __future__ import annotations

import numpy as np
import pytest

from rls_uncertainty.frequency import FrequencyOptions, finite_fourier_transform, frequency_reference
from rls_uncertainty.frequency.covariance import PairGeometry, middle, pair_matrices, sandwich
from rls_uncertainty.simulation.montecarlo import level_inputs

RATE = 50.0


def explicit_pairs(R: np.ndarray, f: np.ndarray, N: int, trim: int) -> tuple[np.ndarray, np.ndarray]:
    """E[E E^H] / dt^2 and E[E E^T] / dt^2 for E_k = dt sum_n (e_n - e_bar) exp(-j w_k t_n),
    e_bar the mean of the first ``trim`` e, e with autocovariance R (zero beyond its length),
    summed over every pair of samples."""
    c = np.exp(-2j * np.pi * np.outer(f, np.arange(N)) / RATE)
    c[:, :trim] -= c.sum(axis=1, keepdims=True) / trim  # the -e_bar of every sample, moved onto the first
    r = np.zeros(N)
    r[: R.size] = R
    T = r[np.abs(np.subtract.outer(np.arange(N), np.arange(N)))]
    return c @ T @ c.conj().T, c @ T @ c.T


@pytest.mark.parametrize(("N", "L", "trim"), [(30, 6, 1), (7, 6, 1), (50, 0, 1), (40, 39, 1), (30, 6, 4), (30, 6, 30),
                                             (60, 5, 12), (9, 8, 9)])
def test_the_pair_matrices_equal_the_sums_over_every_pair_of_samples(N, L, trim):
    rng = np.random.default_rng(N + L)
    f = np.sort(rng.uniform(0.05, 20.0, 9))  # any grid below the Nyquist frequency
    f[3] = f[4] - 1e-3  # two close frequencies: the 1 / (1 - exp(-j delta)) terms
    R = rng.standard_normal((2, L + 1))
    angles = 2 * np.pi * f / RATE
    M, P = pair_matrices(R, PairGeometry(angles).at(N), trim)
    for m in range(2):
        M_ref, P_ref = explicit_pairs(R[m], f, N, trim)
        scale = np.abs(M_ref).max()
        np.testing.assert_allclose(M[m], M_ref, rtol=0, atol=1e-11 * scale)
        np.testing.assert_allclose(P[m], P_ref, rtol=0, atol=1e-11 * scale)


@pytest.mark.parametrize(("K", "N", "L", "trim"), [(54, 173, 50, 1), (54, 173, 50, 25), (36, 1000, 50, 1),
                                                  (36, 51, 50, 1), (9, 30, 6, 4), (101, 400, 200, 1),
                                                  (36, 5000, 0, 1), (4, 12, 11, 12)])
def test_the_contraction_equals_the_explicit_sandwich(K, N, L, trim):
    rng = np.random.default_rng(K + N + L)
    f = np.sort(rng.uniform(0.05, 20.0, K)) if K < 20 else 0.1 + 0.04 * np.arange(K)
    angles = 2 * np.pi * f / RATE
    R = rng.standard_normal((5, L + 1))
    X = rng.standard_normal((5, K, 4)) + 1j * rng.standard_normal((5, K, 4))
    geometry = PairGeometry(angles).at(N)
    expected = sandwich(X, *pair_matrices(R, geometry, trim))
    np.testing.assert_allclose(middle(R, X, geometry, trim), expected, rtol=0, atol=1e-12 * np.abs(expected).max())


def records():
    """(name, x (N, p), z (N,)): random regressors and output, and the simulated T-2's C_m
    (alpha, q_hat, delta_e) at 0 and 20 % band-limited noise."""
    rng = np.random.default_rng(4)
    x = rng.standard_normal((300, 3))
    yield "random", x, x @ [0.3, -1.0, 2.0] + rng.standard_normal(300)
    for noise in (0.0, 0.2):
        _t, _red, _sizes, X, Z = level_inputs(noise, 1, seed=9)
        yield f"T-2 C_m {noise:.0%}", X[:300, 1, 1:4], Z[:300, 1]


@pytest.mark.parametrize(("grid", "n_lags", "trim"), [((0.1, 1.5, 0.04), 50, 1), ((0.2, 2.2, 0.04), 50, 25),
                                                      ((0.1, 1.5, 0.04), 0, 1), ((0.1, 5.0, 0.1), 7, 3),
                                                      ((0.3, 0.9, 0.1), 120, 1)])
def test_the_contraction_equals_the_literal_sum_over_every_pair_of_samples(grid, n_lags, trim):
    # frequency_reference forms h' T(R) h over the samples (F6: h the estimate's weights on each
    # sample's error, T(R) the N x N Toeplitz matrix of R): the contraction of the same R and X
    # gives it to 1e-12 of its largest element.
    lo, hi, step = grid
    options = FrequencyOptions(rate_hz=RATE, f_min=lo, f_max=hi, f_step=step, n_lags=n_lags, trim_samples=trim)
    angles = 2 * np.pi * options.frequencies() / RATE
    for name, x, z in records():
        # The shortest record: the lags nearly cover it; with no lags, a few samples more than the
        # parameters (two samples leave the normal matrix singular but for rounding).
        for N in (max(n_lags + 2, 2 * x.shape[1] + 2), 64, 300):
            fit = frequency_reference(x[:N], z[:N], options)
            r = np.zeros(N)
            r[: fit.R.size] = fit.R
            literal = fit.h.T @ r[np.abs(np.subtract.outer(np.arange(N), np.arange(N)))] @ fit.h
            got = middle(fit.R[None], fit.X[None], PairGeometry(angles).at(N), min(trim, N))[0] / RATE**2
            np.testing.assert_allclose(got, literal, rtol=0, atol=1e-12 * np.abs(literal).max(),
                                       err_msg=f"{name}, N = {N}")


def test_with_the_true_autocovariance_the_covariance_matches_the_monte_carlo_scatter():
    # Fixed regressors, AR(1) equation error (phi = 0.7, so R(i) = phi^i / (1 - phi^2) is below
    # 1e-7 after 50 lags): the estimate's covariance from F7-F8 with the true R against the
    # scatter of 3000 estimates. The variance of a variance estimated from 3000 samples has a
    # relative standard error sqrt(2 / 3000) = 2.6 %: 12 % is about 4.5 of them.
    rng = np.random.default_rng(2016)
    N, runs, phi, L = 300, 3000, 0.7, 50
    t = np.arange(N) / RATE
    x = np.column_stack([np.sin(2 * np.pi * 0.45 * t) * (t > 1), np.sin(2 * np.pi * 1.3 * t + 1) + 0.3 * t])
    e = rng.standard_normal((N + 100, runs))
    for k in range(1, N + 100):
        e[k] += phi * e[k - 1]
    e = e[100:]
    f = 0.1 + 0.02 * np.arange(71)  # 0.1 to 1.5 Hz, three points per 1/T = 0.167 Hz
    X = finite_fourier_transform(x - x[0], f, RATE)  # (K, 2)
    E = finite_fourier_transform(e - e[0], f, RATE)  # (K, runs); z = x theta + e
    A = (X.conj().T @ X).real
    A_inv = np.linalg.inv(A)
    errors = (A_inv @ (X.conj().T @ E).real).T  # theta_hat - theta, every run
    R = phi ** np.arange(L + 1) / (1 - phi**2)
    angles = 2 * np.pi * f / RATE
    cov = A_inv @ (middle(R[None], X[None], PairGeometry(angles).at(N))[0] / RATE**2) @ A_inv
    observed = errors.var(axis=0, ddof=1)
    np.testing.assert_allclose(np.diag(cov), observed, rtol=0.12)
    # The conventional covariance s^2 A^-1 (s^2 from the residuals over frequency, the points
    # taken as independent) is far off on this grid:
    resid = E - X @ errors.T
    s2 = (np.abs(resid) ** 2).sum(axis=0) / (f.size - 2)
    conventional = s2.mean() * np.diag(A_inv)
    assert np.all(np.abs(conventional / observed - 1) > 0.3)


def test_the_tables_kept_while_the_record_grows_are_those_of_one_lag_count():
    """The lag count of an evaluation grows with the record up to ``frequency.n_lags + 1``: what
    the geometry and the degrees-of-freedom correction keep between evaluations stays that of
    one count (kept per count, it grew to about 130 MB here), and a table
    asked for again after another count is the same."""
    import tracemalloc

    from rls_uncertainty.frequency.lags import _bias_terms

    geometry = PairGeometry(2 * np.pi * np.arange(0.2, 2.2, 0.04) / 50.0)  # 50 frequencies at 50 Hz
    first = geometry.spectral_table(40).copy()
    tracemalloc.start()
    try:
        base = tracemalloc.get_traced_memory()[0]
        for lags in range(1, 201):
            geometry.spectral_table(lags)
            _bias_terms(2 * lags, lags - 1)
        grown = tracemalloc.get_traced_memory()[0] - base
    finally:
        tracemalloc.stop()
    one = geometry.spectral_table(200).nbytes + geometry.lag_table(200).nbytes + 5 * 201 * 201 * 8
    assert grown < 2 * one
    np.testing.assert_array_equal(geometry.spectral_table(40), first)
