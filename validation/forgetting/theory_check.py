"""Closed form of the gap for the intercept-only model (a weighted mean), checked by Monte Carlo.

With ``x_k = 1`` and forgetting ``f``, in steady state ``D = 1 - f``, ``d_k = 1`` and the
standardized residual is the noise through a high-pass filter with a zero at DC,

    u = sqrt(f) (1 - q^-1) / (1 - f q^-1) eps,

i.e. the fit absorbs the noise within a band of width ``1 - f`` around zero frequency, which
is exactly where the weighted mean's variance lives. ``Lambda(i) / Lambda(0) = 2 f^i``, so

    E[corrected variance] / true variance
        = sum_{|i|<=L} c_i f^|i| r_u(i) / sum_{all i} f^|i| gamma(i),

with ``r_u = gamma * rho_g`` (``rho_g`` the autocovariance of the filter's impulse response:
``rho_g(0) = 2f/(1+f)``, ``rho_g(i) = -(1-f) f^|i| / (1+f)``). For white noise and the
truncated window this is ``2 f (1 + f^(2L+1)) / (1 + f)^2``: 0.565 for ``f = 0.98, L = 50``,
0.5 for all lags however close ``f`` is to 1, and 1 only when ``f^(2L) -> 1`` (``f = 1``).

Run: ``PYTHONPATH=$PWD python validation/forgetting/theory_check.py`` (about a minute).
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from study import make_noise, true_autocovariance

from rls_uncertainty.estimator import EstimatorBank, lag_weights


def predicted_ratio(f: float, L: int, gamma: np.ndarray, window: str = "truncated") -> float:
    """Expected corrected variance over the true variance, intercept-only model, steady state."""
    n = len(gamma)
    i = np.arange(n)
    rho = np.where(i == 0, 2 * f / (1 + f), -(1 - f) * f ** i / (1 + f))
    # r_u(m) = sum_s gamma(s) rho(m - s) over all integer s (both even functions)
    g2 = np.concatenate([gamma[:0:-1], gamma])
    r2 = np.concatenate([rho[:0:-1], rho])
    ru = np.convolve(g2, r2)[2 * (n - 1):][: L + 1]
    c = lag_weights(L, window)
    est = c[0] * ru[0] + 2 * np.sum(c[1:] * f ** i[1 : L + 1] * ru[1 : L + 1])
    true = gamma[0] + 2 * np.sum(f ** i[1:] * gamma[1:])
    return est / true


def monte_carlo(f: float, L: int, noise: str, runs: int = 2000, seed: int = 5) -> float:
    """Mean corrected variance over the exact variance of the weighted mean (bank, last sample)."""
    rng = np.random.default_rng(seed)
    N = int(30 / (1 - f))
    eps = make_noise(noise, runs, N, rng)
    bank = EstimatorBank([1] * runs, L, forgetting=f)
    ones = np.ones((runs, 1))
    for k in range(N):
        bank.update(ones, eps[:, k].copy())
    gamma = true_autocovariance(noise, 4000)
    w = f ** np.arange(N - 1, -1, -1.0)
    # exact variance of sum w eps / sum w
    gfull = np.zeros(N)
    gfull[: min(N, len(gamma))] = gamma[: min(N, len(gamma))]
    ac = np.array([np.dot(w[m:], w[: N - m]) for m in range(min(N, len(gamma)))])
    var_true = (ac[0] * gfull[0] + 2 * np.dot(ac[1:], gfull[1 : len(ac)])) / w.sum() ** 2
    return float(np.mean(bank.standard_errors_all()[:, 0] ** 2) / var_true)


if __name__ == "__main__":
    print("| f | noise | predicted E[var]/var | Monte Carlo (2000 runs) |")
    print("| --- | --- | --- | --- |")
    for f in (0.95, 0.98, 0.99, 0.999):
        for noise in ("white", "ar5", "bl2"):
            if f == 0.999 and noise != "white":
                continue
            p = predicted_ratio(f, 50, true_autocovariance(noise, 4000))
            m = monte_carlo(f, 50, noise, runs=2000 if f < 0.999 else 500)
            print(f"| {f} | {noise} | {p:.3f} | {m:.3f} |", flush=True)
