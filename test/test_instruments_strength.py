"""W1: the canonical correlations between instruments and regressors from running sums."""

import numpy as np
import pytest
from scipy.stats import chi2

from rls_uncertainty.instruments import WEAK_BELOW, InstrumentStrength, canonical_correlations


def sums(Z, X):
    return Z.T @ Z, X.T @ X, Z.T @ X


def qr_correlations(Z, X, bias):
    """Canonical correlations the classic way (Bjorck and Golub): the singular values of
    Qz' Qx, with Q from the QR factorization of each data matrix, the bias column removed and
    the others centred (or neither, without a bias column)."""
    keep = [i for i in range(Z.shape[1]) if i != bias]
    Zc, Xc = Z[:, keep], X[:, keep]
    if bias is not None:
        Zc, Xc = Zc - Zc.mean(axis=0), Xc - Xc.mean(axis=0)
    return np.linalg.svd(np.linalg.qr(Zc)[0].T @ np.linalg.qr(Xc)[0], compute_uv=False)


def data(n, seed, bias=0, cols=4):
    rng = np.random.default_rng(seed)
    X = rng.normal(size=(n, cols)) @ rng.normal(size=(cols, cols)) + rng.normal(size=cols)
    if bias is not None:
        X[:, bias] = 1.0
    return rng, X


def test_instruments_equal_to_the_regressors_correlate_fully():
    _, X = data(500, 1)
    rho = canonical_correlations(*sums(X, X), bias=0)
    assert rho.shape == (3,)
    np.testing.assert_allclose(rho, 1.0, atol=1e-10)


def test_independent_instruments_correlate_about_zero():
    """Bartlett: -(N - 1 - (p + q + 1)/2) sum log(1 - rho^2) is chi^2 with p q degrees of
    freedom for independent data (p = q = 3 here); the bound is its 1 - 1e-6 quantile."""
    n = 4000
    rng, X = data(n, 2)
    Z = rng.normal(size=(n, 4))
    Z[:, 0] = 1.0
    rho = canonical_correlations(*sums(Z, X), bias=0)
    statistic = -(n - 1 - 3.5) * np.log(1.0 - rho**2).sum()
    assert statistic < chi2.ppf(1 - 1e-6, 9)
    assert rho.max() < np.sqrt(chi2.ppf(1 - 1e-6, 9) / n)


@pytest.mark.parametrize("bias", [0, 2, None])
def test_canonical_correlations_match_the_qr_computation(bias):
    rng, X = data(300, 3, bias=bias)
    Z = X + rng.normal(0.0, 2.0, X.shape)
    if bias is not None:
        Z[:, bias] = 1.0
    np.testing.assert_allclose(canonical_correlations(*sums(Z, X), bias=bias), qr_correlations(Z, X, bias),
                               rtol=1e-9, atol=1e-12)


def test_an_invertible_mix_of_the_instruments_changes_nothing():
    rng, X = data(300, 4)
    Z = X + rng.normal(0.0, 1.0, X.shape)
    Z[:, 0] = 1.0
    mix = np.eye(4)
    mix[:, 1:] = rng.normal(size=(4, 3))  # any multiple of the bias added, the rest mixed
    np.testing.assert_allclose(canonical_correlations(*sums(Z @ mix, X), bias=0),
                               canonical_correlations(*sums(Z, X), bias=0), rtol=1e-9)


def test_an_instrument_that_never_moves_gives_zero_not_nan():
    _, X = data(200, 5)
    Z = X.copy()
    Z[:, 3] = 0.0  # the excitation stopped: its column is 0
    with np.errstate(all="raise"):
        rho = canonical_correlations(*sums(Z, X), bias=0)
    assert rho.min() == 0.0 and np.allclose(rho[:2], 1.0)


def test_running_sums_per_model_with_padding_and_the_weak_flag():
    rng = np.random.default_rng(6)
    strength = InstrumentStrength((3, 4), bias=(0, 0))
    assert strength.weak_below == WEAK_BELOW
    X = np.zeros((400, 2, 4))
    X[:, :, 0] = 1.0
    X[:, 0, 1:3] = rng.normal(size=(400, 2))
    X[:, 1, 1:] = rng.normal(size=(400, 3))
    Z = X.copy()
    Z[:, 0, 1:3] += 0.1 * rng.normal(size=(400, 2))  # strong
    Z[:, 1, 1:] = rng.normal(size=(400, 3))  # independent of the regressors: weak
    Z[:, 0, 3] = 5.0  # padding: ignored
    for k in range(400):
        if k == 2:
            assert np.isnan(strength.rho_min()).all() and not strength.weak().any()
        strength.update(X[k], Z[k])
    np.testing.assert_allclose(strength.correlations(0), qr_correlations(Z[:, 0, :3], X[:, 0, :3], 0), rtol=1e-9)
    assert strength.rho_min()[0] > 0.9 and strength.rho_min()[1] < WEAK_BELOW
    np.testing.assert_array_equal(strength.weak(), [False, True])
