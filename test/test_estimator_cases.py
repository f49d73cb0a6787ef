"""Test problems and helpers shared by the estimator tests (no tests of its own)."""

from __future__ import annotations

import numpy as np

RATE = 50.0


def ar1(rng, rho, shape):
    """AR(1) noise with unit innovation variance along the last axis, stationary start."""
    e = rng.standard_normal(shape)
    v = np.empty_like(e)
    v[..., 0] = e[..., 0] / np.sqrt(1.0 - rho**2) if rho else e[..., 0]
    for i in range(1, shape[-1]):
        v[..., i] = rho * v[..., i - 1] + e[..., i]
    return v


def wide_scale_problem(n=600, seed=0):
    """Four regressors whose scales range from 1e-4 to 1e2, colored equation error."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) / RATE
    X = np.column_stack(
        [
            np.ones(n),
            1e-4 * np.sin(2 * np.pi * 0.7 * t) + 1e-5 * rng.standard_normal(n),
            1e2 * np.sin(2 * np.pi * 0.3 * t + 1.0),
            rng.standard_normal(n),
        ]
    )
    theta = np.array([0.5, 300.0, -0.01, 2.0])
    z = X @ theta + 0.05 * ar1(rng, 0.9, (n,))
    return X, z


def indefinite_problem(n=500):
    """A slowly varying regressor and residuals that oscillate at a frequency where the
    uniform lag window of n_lags = 5 has a negative spectral lobe."""
    rng = np.random.default_rng(5)
    k = np.arange(n)
    X = np.column_stack([np.ones(n), k / n])
    omega = 1.5 * np.pi / 5.5  # sin(5.5 w) = -1: the 5-lag Dirichlet kernel is negative
    z = X @ [0.3, 1.0] + np.sin(omega * k) + 0.01 * rng.standard_normal(n)
    return X, z


def run(est, X, z, stop=None):
    for k in range(len(z) if stop is None else stop):
        est.update(X[k], z[k])
    return est


def rel_close(a, b, rtol):
    """Elementwise closeness relative to the largest magnitude of the reference."""
    scale = np.max(np.abs(b))
    np.testing.assert_allclose(a, b, rtol=rtol, atol=rtol * scale)
