"""The fast bank (:class:`EstimatorBank`, :class:`RecursiveEstimator`): the reference's numbers
for every option, estimates against batch least squares, options, input checks (Eqs. 15-22)."""

from __future__ import annotations

import ast
import itertools
import math
import pathlib
import subprocess
import sys

import numpy as np
import pytest
from test_estimator_cases import RATE, ar1, indefinite_problem, rel_close, run, wide_scale_problem

from rls_uncertainty.estimator import (
    EstimatorBank,
    EstimatorNotReady,
    EstimatorOptions,
    NonFiniteInput,
    RecursiveEstimator,
    batch_estimate,
)
from rls_uncertainty.estimator.reference import RecursiveReference


# --------------------------------------------------------------------------- estimates
def test_theta_equals_batch_ols_with_scales_from_1e_4_to_1e2():
    X, z = wide_scale_problem()
    est = run(RecursiveEstimator(4, EstimatorOptions(lags=50)), X, z)
    ols = np.linalg.lstsq(X, z, rcond=None)[0]
    assert np.max(np.abs(est.theta - ols) / np.abs(ols)) < 1e-6
    assert est.n_samples == len(z)

def test_exact_initialization_agrees_with_batch_from_the_first_well_conditioned_sample():
    X, z = wide_scale_problem()
    est = RecursiveEstimator(4, EstimatorOptions(lags="all"))
    for k in range(len(z)):
        est.update(X[k], z[k])
        if est.is_ready:
            ols = np.linalg.lstsq(X[: k + 1], z[: k + 1], rcond=None)[0]
            np.testing.assert_allclose(est.theta, ols, rtol=1e-6)

def test_rank_deficient_early_samples_wait_for_excitation():
    """Elevator still at trim for 150 samples: X'X is singular until the maneuver starts."""
    X, z = wide_scale_problem()
    X = X.copy()
    X[:150, 2] = 0.0
    z = X @ np.array([0.5, 300.0, -0.01, 2.0]) + 0.01 * np.random.default_rng(2).standard_normal(len(z))
    est = RecursiveEstimator(4, EstimatorOptions(lags=50))
    full = RecursiveEstimator(4, EstimatorOptions(lags="all"))
    for k in range(len(z)):
        est.update(X[k], z[k])
        full.update(X[k], z[k])
        if k < 150:
            assert not est.is_ready
            with pytest.raises(EstimatorNotReady):
                _ = est.theta  # the property access is what raises
            with pytest.raises(EstimatorNotReady):
                est.standard_errors()
    assert est.is_ready
    ols = np.linalg.lstsq(X, z, rcond=None)[0]
    assert np.max(np.abs(est.theta - ols) / np.abs(ols)) < 1e-6
    batch = batch_estimate(X, z, 50, residuals=full.residuals())
    rel_close(est.covariance(repair=False), batch[2], 1e-9)

def test_prior_initialization_is_ridge_regression():
    """With D0 = p0 I the recursion solves (X'X + I/p0) theta = X'z exactly."""
    X, z = wide_scale_problem()
    p0 = 1e6
    est = run(RecursiveEstimator(4, EstimatorOptions(lags="all", p0=p0)), X, z)
    ridge = np.linalg.solve(X.T @ X + np.eye(4) / p0, X.T @ z)
    np.testing.assert_allclose(est.theta, ridge, rtol=1e-6)
    ols = np.linalg.lstsq(X, z, rcond=None)[0]
    # The prior visibly biases the small-scale regressor's parameter; exact init does not.
    assert abs(est.theta[1] - ols[1]) / abs(ols[1]) > 1e-3

def test_residual_options_are_the_innovation_the_a_posteriori_residual_and_their_geometric_mean():
    X, z = wide_scale_problem()
    residuals = ("a_posteriori", "a_priori", "standardized")
    est = {r: RecursiveEstimator(4, EstimatorOptions(lags="all", residual=r)) for r in residuals}
    thetas = []
    for k in range(len(z)):
        for e in est.values():
            e.update(X[k], z[k])
        thetas.append(est["standardized"].theta if est["standardized"].is_ready else None)
    k0 = next(i for i, t in enumerate(thetas) if t is not None)
    v = {r: e.residuals() for r, e in est.items()}
    for k in range(k0 + 1, len(z)):
        post = z[k] - X[k] @ thetas[k]
        prior = z[k] - X[k] @ thetas[k - 1]
        assert v["a_posteriori"][k] == pytest.approx(post, rel=1e-6, abs=1e-9)
        assert v["a_priori"][k] == pytest.approx(prior, rel=1e-6, abs=1e-9)
        assert v["standardized"][k] == pytest.approx(np.sign(prior) * np.sqrt(post * prior), rel=1e-6, abs=1e-9)
    np.testing.assert_array_equal(est["a_posteriori"].theta, est["a_priori"].theta)
    np.testing.assert_array_equal(est["a_posteriori"].theta, est["standardized"].theta)

@pytest.mark.parametrize("forgetting", [1.0, 0.98])
def test_standardized_residual_makes_eq16_the_batch_fit_error_variance_at_every_sample(forgetting):
    """RSS_k = f RSS_(k-1) + e_k^2 f / d_k: with the default residual, R_k(0) (Eq. 16) equals
    the weighted batch fit-error variance (Eq. 14) of samples 1..k with theta_k, and the
    conventional standard errors equal the batch ones; the a posteriori residual falls short.
    Under forgetting R_k(0) is the noise model's: the same identity for the
    fit weighted f_R^(k-j) (f_R = 0.99878 for 20 lags), with the estimator's D and Lambda."""
    rng = np.random.default_rng(11)
    n = 400
    X = np.column_stack([np.ones(n), rng.standard_normal((n, 2))])
    colored = np.convolve(rng.standard_normal(n + 9), np.ones(10) / 3.0, "valid")
    z = X @ [0.5, -2.0, 1.0] + colored
    est = RecursiveEstimator(3, EstimatorOptions(lags=20, forgetting=forgetting))
    post = RecursiveEstimator(3, EstimatorOptions(lags=20, forgetting=forgetting, residual="a_posteriori"))
    short = []
    for k in range(n):
        est.update(X[k], z[k])
        post.update(X[k], z[k])
        if not est.is_ready:
            continue
        f_R = est.options.noise_forgetting_used
        w = f_R ** np.arange(k, -1, -1)
        _, cov_conv, _ = batch_estimate(X[: k + 1], z[: k + 1], 20, forgetting=forgetting, noise_forgetting=f_R)
        theta_R = batch_estimate(X[: k + 1], z[: k + 1], 0, forgetting=f_R)[0]
        v = z[: k + 1] - X[: k + 1] @ theta_R
        assert est.residual_variance == pytest.approx((w * v * v).sum() / w.sum(), rel=1e-9)
        np.testing.assert_allclose(est.covariance("conventional"), cov_conv, rtol=1e-8, atol=1e-12)
        short.append(1.0 - post.residual_variance / est.residual_variance)
    assert np.mean(short) > 0.005  # the a posteriori residual is biased low

def test_forgetting_tracks_a_parameter_change():
    rng = np.random.default_rng(4)
    n = 2000
    t = np.arange(n) / RATE
    X = np.column_stack([np.ones(n), np.sin(2 * np.pi * 0.5 * t), rng.standard_normal(n)])
    theta = np.where(t[:, None] < 20, [1.0, -2.0, 0.5], [1.0, -3.0, 0.5])
    z = np.sum(X * theta, axis=1) + 0.01 * rng.standard_normal(n)
    tracking = run(RecursiveEstimator(3, EstimatorOptions(lags=11, forgetting=0.99)), X, z)
    plain = run(RecursiveEstimator(3, EstimatorOptions(lags=11)), X, z)
    assert tracking.theta[1] == pytest.approx(-3.0, abs=0.02)
    assert abs(plain.theta[1] + 3.0) > 0.3

def test_bank_equals_independent_estimators():
    """The six models of Eq. 2 in one bank give what six separate estimators give."""
    rng = np.random.default_rng(9)
    sizes = (3, 4, 3, 6, 4, 4)
    n = 400
    t = np.arange(n) / RATE
    base = np.column_stack(
        [np.ones(n)] + [np.sin(2 * np.pi * (0.2 + 0.13 * i) * t + i) for i in range(5)]
    )
    rows = [base[:, :s] + 0.01 * rng.standard_normal((n, s)) * (np.arange(s) > 0) for s in sizes]
    zs = [r @ rng.standard_normal(r.shape[1]) + 0.01 * ar1(rng, 0.8, (n,)) for r in rows]
    bank = EstimatorBank(sizes, EstimatorOptions(lags=11))
    singles = [RecursiveEstimator(s, EstimatorOptions(lags=11)) for s in sizes]
    for k in range(n):
        bank.update([r[k] for r in rows], np.array([zz[k] for zz in zs]))
        for est, r, zz in zip(singles, rows, zs, strict=True):
            est.update(r[k], zz[k])
    for j, est in enumerate(singles):
        np.testing.assert_allclose(bank.theta(j), est.theta, rtol=1e-12)
        np.testing.assert_allclose(bank.standard_errors(j), est.standard_errors(), rtol=1e-10)
        np.testing.assert_allclose(bank.theta_all()[j, : sizes[j]], est.theta, rtol=1e-12)
    assert np.isnan(bank.theta_all()[0, 3:]).all()


# --------------------------------------------------------------------------- bank = reference
def equivalence_problem(n=90, seed=7):
    """Two models of 3 and 2 parameters with colored errors; model 0's last regressor is zero
    for the first 12 samples, so that it initializes late (after the 5-lag window filled)."""
    rng = np.random.default_rng(seed)
    k = np.arange(n)
    x0 = np.column_stack([np.ones(n), np.sin(0.3 * k) + 0.3 * rng.standard_normal(n),
                          np.where(k < 12, 0.0, np.cos(0.17 * k) + 0.3 * rng.standard_normal(n))])
    x1 = np.column_stack([0.5 + 0.2 * rng.standard_normal(n), np.sin(0.11 * k + 1.0)])
    X = np.zeros((n, 2, 3))
    X[:, 0] = x0
    X[:, 1, :2] = x1
    Z = np.column_stack([x0 @ [0.4, -1.2, 2.0], x1 @ [1.5, 0.7]]) + 0.2 * ar1(rng, 0.7, (2, n)).T
    return X, Z


OPTIONS = list(itertools.product(
    ["truncated", "bartlett"], ["all", 0, 5], [1.0, 0.97], ["standardized", "a_posteriori", "a_priori"], [None, 100.0]
))
CHECK_K = (2, 5, 12, 13, 14, 30, 90)  # before initialization, at it, after the window fills


def window_of(options):
    """The lag window the publication rule counts in, written out: the fixed lags, else (auto,
    all lags, the conventional covariance's 0) the longest lag span ``max_lags``."""
    return options.lags if isinstance(options.lags, int) and options.lags > 0 else options.max_lags


def fed_bank_and_references(X, Z, **options):
    """A bank of two models (3 and 2 parameters) and their reference.py twins with the same
    ``EstimatorOptions(**options)``, fed the samples of ``X, Z`` one by one: yields ``(bank,
    refs, k)`` after sample k (from 1)."""
    bank = EstimatorBank((3, 2), EstimatorOptions(**options))
    refs = [RecursiveReference(s, EstimatorOptions(**options)) for s in (3, 2)]
    for k in range(len(Z)):
        bank.update(X[k], Z[k])
        refs[0].update(X[k, 0], Z[k, 0])
        refs[1].update(X[k, 1, :2], Z[k, 1])
        yield bank, refs, k + 1


def assert_bank_equals_reference(bank, refs, k, rtol=1e-8):
    """Bank and reference agree to ``rtol`` of each quantity's largest entry, or to the
    rounding floor where the quantity is itself rounding (the residuals of a model that has
    just initialized on as many samples as parameters are zero): exact initialization forms
    R_k(i) from lagged moments, ``sum z^2 - 2 theta' X'z + theta' X'X theta``, whose rounding
    is ``eps sum z^2``; it reaches the covariance through ``D Lambda D``."""
    sizes = bank.sizes
    assert list(bank.initialized) == [r.ready for r in refs], k
    b, need = bank.options.burn_in, math.ceil(bank.options.publish_lag_windows * window_of(bank.options))
    published = [r.ready and (k - r.ready_at - b if b else k) - s >= need for r, s in zip(refs, sizes, strict=True)]
    assert list(bank.ready) == published, k
    theta_all = bank.theta_all()
    se_all = {kind: bank.standard_errors_all(kind) for kind in ("corrected", "conventional")}
    for j, (ref, s) in enumerate(zip(refs, sizes, strict=True)):
        if not published[j]:  # nothing published: NaN rows
            assert np.isnan(theta_all[j]).all() and np.isnan(se_all["corrected"][j]).all()
            assert np.isnan(bank.covariance_all()[:, j]).all()
        else:
            rel_close(theta_all[j, :s], ref.theta, 1e-9)
            np.testing.assert_array_equal(se_all["corrected"][j, :s], bank.standard_errors(j))
        if not ref.ready:
            with pytest.raises(EstimatorNotReady):
                bank.covariance(j)
            continue
        se = {kind: bank.standard_errors(j, kind) for kind in ("corrected", "conventional")}
        assert bank.ready_at[j] == ref.ready_at
        rel_close(bank.theta(j), ref.theta, 1e-9)
        floor_R = 1e-12 * np.mean(np.square(ref.z))
        R = [ref.R[i] for i in range(len(ref.R))]
        np.testing.assert_allclose(bank.autocorrelation(j), R, rtol=0, atol=rtol * np.max(np.abs(R)) + floor_R)
        floor_cov = floor_R * len(R) * np.max(np.abs(ref.D))
        for kind in ("corrected", "conventional"):
            for mine, theirs in ((bank.covariance(j, kind, repair=False), ref.covariance(kind)),
                                 (bank.covariance(j, kind), ref.published_covariance(kind))):
                np.testing.assert_allclose(mine, theirs, rtol=0, atol=rtol * np.max(np.abs(theirs)) + floor_cov)
            theirs = ref.standard_errors(kind)
            np.testing.assert_allclose(se[kind], theirs, rtol=0, atol=rtol * np.max(theirs) + np.sqrt(floor_cov))


@pytest.mark.parametrize("window, lags, forgetting, residual, p0", OPTIONS)
def test_bank_equals_the_reference_for_every_option(window, lags, forgetting, residual, p0):
    """Theta, both full covariances (unrepaired and published) and the published standard
    errors of the bank equal the literal Eqs. 15-22 of reference.py, before and at exact
    initialization, once the lag window is full, and at the end."""
    X, Z = equivalence_problem()
    options = dict(lags=lags, window=window, forgetting=forgetting, residual=residual, p0=p0)
    for bank, refs, k in fed_bank_and_references(X, Z, **options):
        if k in CHECK_K:
            assert_bank_equals_reference(bank, refs, k)
    if p0 is None:
        assert refs[0].ready_at > 12 and refs[1].ready_at <= 5


BURN_IN_OPTIONS = [  # window, lags, forgetting, residual, p0, residual_burn_in, noise_forgetting
    ("truncated", 5, 1.0, "standardized", None, 7, None),
    ("truncated", 5, 1.0, "a_posteriori", 100.0, 1, None),
    ("bartlett", 5, 0.97, "a_posteriori", None, 7, None),  # the noise model (f_R = 0.9958)
    ("truncated", 5, 0.97, "a_priori", 100.0, 30, None),
    ("truncated", 5, 0.97, "standardized", None, 7, 0.97),  # the estimator's own residuals
    ("truncated", "all", 1.0, "a_priori", None, 7, None),
    ("bartlett", "all", 0.97, "standardized", 100.0, 3, None),
    ("truncated", 0, 0.97, "standardized", None, 4, None),
    ("truncated", 0, 1.0, "a_posteriori", None, 60, None),
]


@pytest.mark.parametrize("window, lags, forgetting, residual, p0, burn_in, noise_forgetting", BURN_IN_OPTIONS)
def test_bank_equals_the_reference_with_a_residual_burn_in(window, lags, forgetting, residual, p0, burn_in,
                                                           noise_forgetting):
    """With a residual burn-in the bank equals reference.py at every sample: the paper's R_k(i)
    up to k0 + B, then R_k(i) of the samples after it (the models initialize at 13 and 2, or 0
    with a prior); the fixed-lag window's memory and all lags, with and without forgetting."""
    X, Z = equivalence_problem()
    options = dict(lags=lags, window=window, forgetting=forgetting, residual=residual, p0=p0,
                   residual_burn_in=burn_in, noise_forgetting=noise_forgetting)
    for bank, refs, k in fed_bank_and_references(X, Z, **options):
        assert_bank_equals_reference(bank, refs, k)
        after = [k - r.ready_at - burn_in if r.ready else 0 for r in refs]
        expected = [r.n_B if a > 0 else r.n_R for r, a in zip(refs, after, strict=True)]
        np.testing.assert_allclose(bank.n_R, expected, rtol=1e-12)
    assert bank.options.burn_in == burn_in and not (lags != "all" and bank._counts.masking)


@pytest.mark.parametrize("forgetting", [1.0, 0.99])
def test_burn_in_covariance_is_the_batch_formula_on_the_residuals_after_it(forgetting):
    """Independent of reference.py: after the burn-in the bank's covariances (40 lags, burn-in
    50) are batch_estimate (Eqs. 8-11) on the recursive residual history with the residuals of
    samples 1..k0+50 zeroed, rescaled from the weight total of all samples to that of the
    samples after the burn-in (N/n when f = 1); during the burn-in they are the paper's."""
    X, z = wide_scale_problem()
    est = RecursiveEstimator(4, EstimatorOptions(lags=40, forgetting=forgetting, residual_burn_in=50))
    g = est.options.noise_forgetting_used
    # the whole residual history:
    full = RecursiveEstimator(4, EstimatorOptions(lags="all", forgetting=forgetting, noise_forgetting=g))
    for k in range(len(z)):
        est.update(X[k], z[k])
        full.update(X[k], z[k])
        if k + 1 not in (40, 54, 55, 56, 90, 300, 600):
            continue
        end = int(est.bank.ready_at[0]) + 50
        v = full.noise_residuals()
        w = g ** np.arange(k + 1)
        scale = 1.0
        if k + 1 > end:
            v[:end] = 0.0
            scale = w.sum() / w[: k + 1 - end].sum()
        _, cov_conv, cov_corr = batch_estimate(
            X[: k + 1], z[: k + 1], 40, residuals=v, forgetting=forgetting, noise_forgetting=g
        )
        rel_close(est.covariance("corrected", repair=False), cov_corr * scale, 1e-9)
        rel_close(est.covariance("conventional"), cov_conv * scale, 1e-9)
    assert est.bank.ready_at[0] == 4  # samples 54 (the last of the burn-in), 55, 56 checked


@pytest.mark.parametrize("p0", [None, 100.0])
def test_bank_equals_the_reference_where_the_truncated_window_is_repaired(p0):
    """The published (repaired) covariance and standard errors where the uniform window makes
    the covariance indefinite."""
    X, z = indefinite_problem(240)
    bank = EstimatorBank((2,), EstimatorOptions(lags=5, p0=p0))
    ref = RecursiveReference(2, EstimatorOptions(lags=5, p0=p0))
    repaired = 0
    for k in range(len(z)):
        bank.update(X[k : k + 1], z[k : k + 1])
        ref.update(X[k], z[k])
        if k % 20 == 19:
            assert_bank_equals_reference(bank, [ref], k + 1)
            repaired += np.min(np.diag(ref.covariance())) < 0
    assert repaired >= 3 and bank.repairs[0] == repaired



@pytest.mark.parametrize("problem", ["equivalence", "indefinite"])
def test_one_kind_of_covariance_is_that_kind_of_both(problem):
    """``covariance_all(kind)`` is ``covariance_all()[kind]`` bit for bit (NaN where it is), at
    every sample and whichever is formed first, also where the corrected one is repaired;
    ``standard_errors_all`` are the square roots of its diagonals."""
    if problem == "equivalence":
        X, Z = equivalence_problem(n=60)
        sizes, options = (3, 2), EstimatorOptions(lags=5, publish_lag_windows=2.0)
    else:
        x, z = indefinite_problem(120)
        X, Z, sizes, options = x[:, None, :], z[:, None], (2,), EstimatorOptions(lags=5)
    first, later = EstimatorBank(sizes, options), EstimatorBank(sizes, options)  # one kind first / both first
    for k in range(len(Z)):
        first.update(X[k], Z[k])
        later.update(X[k], Z[k])
        for i, kind in enumerate(("corrected", "conventional")):
            alone = first.covariance_all(kind)
            both = later.covariance_all()
            np.testing.assert_array_equal(alone, both[i])
            np.testing.assert_array_equal(first.covariance_all()[i], alone)
            se = np.sqrt(np.maximum(alone.diagonal(0, 1, 2), 0.0))
            np.testing.assert_array_equal(later.standard_errors_all(kind)[np.isfinite(se)], se[np.isfinite(se)])
    assert problem == "equivalence" or first.repairs[0] > 0

# --------------------------------------------------------------------------- the overflow guard
@pytest.mark.parametrize("magnitude", [1e160, 1e200, 1e300, 1.7e308])
@pytest.mark.parametrize("where", ["regressor", "output", "padding"])
def test_finite_but_huge_input_is_refused_and_leaves_the_state_bit_identical(magnitude, where):
    """A finite sample whose square overflows would make the state non-finite: refused with
    NonFiniteInput, the state unchanged bit for bit, and the bank goes on as if it never came
    (the padding, which is ignored, is accepted)."""
    rng = np.random.default_rng(3)
    n = 160
    X = np.zeros((n, 2, 3))
    X[:, :, 0] = 1.0
    X[:, :, 1:] = rng.standard_normal((n, 2, 2))
    X[:, 1, 2] = 0.0  # model 1 has two parameters
    X[:60, 0, 2] = 0.0  # model 0 waits for initialization until sample 61
    Z = X.sum(axis=2) + 0.1 * rng.standard_normal((n, 2))
    for stop in (30, 120):  # while model 0 waits, and once both are ready
        a = EstimatorBank((3, 2), EstimatorOptions(lags=20))
        b = EstimatorBank((3, 2), EstimatorOptions(lags=20))
        run(a, X, Z, stop)
        run(b, X, Z, stop)
        before = a.state()
        se_before = a.standard_errors_all()
        x_bad, z_bad = X[stop].copy(), Z[stop].copy()
        if where == "regressor":
            x_bad[0, 1] = magnitude
        elif where == "output":
            z_bad[1] = -magnitude
        else:
            x_bad[1, 2] = magnitude
        if where == "padding":
            a.update(x_bad, z_bad)
            b.update(X[stop], Z[stop])
        else:
            with pytest.raises(NonFiniteInput, match="non-finite"):
                a.update(x_bad, z_bad)
            after = a.state()
            assert after["counters"] == before["counters"]
            assert after["arrays"].keys() == before["arrays"].keys()
            for name, arr in before["arrays"].items():
                assert arr.dtype == after["arrays"][name].dtype
                assert arr.tobytes() == after["arrays"][name].tobytes(), name
            assert a.standard_errors_all().tobytes() == se_before.tobytes()
        for k in range(stop + 1, n):
            a.update(X[k], Z[k])
            b.update(X[k], Z[k])
        np.testing.assert_array_equal(a.theta_all(), b.theta_all())
        np.testing.assert_array_equal(a.standard_errors_all(), b.standard_errors_all())


def test_large_input_that_keeps_the_state_finite_is_accepted():
    """Above the bound where the update is checked (1e100) a sample is still applied when the
    state stays finite: the check refuses only what would overflow."""
    X, z = wide_scale_problem()
    est = run(RecursiveEstimator(4, EstimatorOptions(lags=5)), X, z, stop=100)
    x = X[100].copy()
    x[3] = 1e120  # its square, 1e240, and every product with it stay finite
    est.update(x, z[100])
    assert est.n_samples == 101
    assert all(np.isfinite(a).all() for a in est.state()["arrays"].values())


# --------------------------------------------------------------------------- inputs and options
@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_non_finite_input_is_rejected_and_leaves_state_untouched(bad):
    X, z = wide_scale_problem()
    est = run(RecursiveEstimator(4, EstimatorOptions(lags=5)), X, z, stop=100)
    before = est.state()
    x_bad = X[100].copy()
    x_bad[2] = bad
    with pytest.raises(NonFiniteInput, match="model"):
        est.update(x_bad, z[100])
    with pytest.raises(NonFiniteInput):
        est.update(X[100], bad)
    after = est.state()
    assert before["counters"] == after["counters"]
    for name, arr in before["arrays"].items():
        np.testing.assert_array_equal(arr, after["arrays"][name], err_msg=name)

def test_wrong_shapes_are_refused():
    est = RecursiveEstimator(3, EstimatorOptions(lags="all"))
    with pytest.raises(ValueError, match="regressors"):
        est.update([1.0, 2.0], 0.0)
    bank = EstimatorBank((2, 3), EstimatorOptions(lags="all"))
    with pytest.raises(ValueError, match="model 1"):
        bank.update([[1.0, 2.0], [1.0]], [0.0, 0.0])

def test_numerical_core_imports_numpy_only():
    """Every module of the estimator package imports numpy, the standard library's math,
    typing and collections (collections.abc, where the typing ABCs live), and the package's
    own modules only; importing it does not load rclpy."""
    package = pathlib.Path(__file__).resolve().parents[1] / "rls_uncertainty" / "estimator"
    modules = sorted(package.glob("*.py"))
    assert {p.name for p in modules} >= {"__init__.py", "bank.py", "reference.py", "covariance.py"}
    for path in [*modules, package.parent / "errors.py", package.parent / "schema.py"]:
        tree = ast.parse(path.read_text())
        imported = set()
        for node in ast.walk(tree):
            if isinstance(node, ast.ImportFrom) and node.level > 0:
                # The package's own modules, or its parent's errors and schema modules (both
                # import the standard library only: test_structure's layering keeps them so).
                assert node.level == 1 or node.module in {"errors", "schema"}, (path.name, node.module)
            elif isinstance(node, ast.ImportFrom):
                imported.add(node.module.split(".")[0])
            elif isinstance(node, ast.Import):
                imported.update(alias.name.split(".")[0] for alias in node.names)
        allowed = {"numpy", "math", "typing", "collections", "__future__"}
        if path.name == "options.py":  # the options object: a frozen dataclass
            allowed |= {"dataclasses"}
        if path.name in {"schema.py", "errors.py"}:  # option() fields, typed refusals
            allowed |= {"dataclasses", "numbers"}
        assert imported <= allowed, (path.name, imported)
    out = subprocess.run(
        [sys.executable, "-c", "import sys, rls_uncertainty.estimator; print('rclpy' in sys.modules)"],
        capture_output=True, text=True, check=True,
    )
    assert out.stdout.strip() == "False"

def test_estimator_package_has_no_import_cycle():
    """No module of the estimator package imports, even for type checking only, one that
    imports it back (directly or through others): each is readable and testable on its own."""
    package = pathlib.Path(__file__).resolve().parents[1] / "rls_uncertainty" / "estimator"
    names = {p.stem for p in package.glob("*.py")} - {"__init__"}
    graph = {}
    for name in names:
        deps = set()
        for node in ast.walk(ast.parse((package / f"{name}.py").read_text())):
            if isinstance(node, ast.ImportFrom) and node.level == 1:
                deps |= {node.module} if node.module else {a.name for a in node.names}
        graph[name] = deps & names
    done, path = set(), []

    def visit(name):
        assert name not in path, f"import cycle: {' -> '.join([*path[path.index(name):], name])}"
        if name in done:
            return
        path.append(name)
        for dep in sorted(graph[name]):
            visit(dep)
        path.pop()
        done.add(name)

    for name in sorted(names):
        visit(name)
    assert "bank" not in graph["initialization"] | graph["state"] | graph["evaluation"]


def test_numpy_126_vecdot_fallback_gives_the_same_standard_errors(monkeypatch):
    """numpy < 2.0 has no vecdot; the einsum fallback must give the same covariances."""
    from rls_uncertainty.estimator import covariance, evaluation, numpy_compat, rls_fit

    X, z = wide_scale_problem()
    ref = run(RecursiveEstimator(4, EstimatorOptions(lags=20, forgetting=0.99)), X, z)
    for module in (rls_fit, evaluation, covariance):
        monkeypatch.setattr(module, "vecdot", numpy_compat.einsum_vecdot)
    alt = run(RecursiveEstimator(4, EstimatorOptions(lags=20, forgetting=0.99)), X, z)
    np.testing.assert_allclose(alt.standard_errors(), ref.standard_errors(), rtol=1e-12)
    np.testing.assert_allclose(alt.standard_errors("conventional"), ref.standard_errors("conventional"), rtol=1e-12)
    np.testing.assert_allclose(alt.theta, ref.theta, rtol=1e-12)


@pytest.mark.parametrize("lags", [0, 50, "all", "auto"])
def test_a_bank_that_has_seen_no_sample_reports_nan_standard_errors_and_no_estimates(lags):
    """Before the first sample no model is ready: every published array is NaN (never an
    IndexError from an empty lag window)."""
    bank = EstimatorBank((3, 4), EstimatorOptions(lags=lags))
    for kind in ("corrected", "conventional"):
        se = bank.standard_errors_all(kind)
        assert se.shape == (2, 4) and np.isnan(se).all()
    assert np.isnan(bank.theta_all()).all() and not bank.ready.any()


# --------------------------------------------------------------------------- publication rule
@pytest.mark.parametrize("lags, windows, burn_in", [(5, 2.0, None), (7, 1.5, None), ("all", 2.0, None),
                                                     (0, 1.0, None), ("auto", 2.0, None), ("auto", 1.0, 4)])
def test_a_model_publishes_first_at_n_plus_the_lag_windows(lags, windows, burn_in):
    """The first published sample of each model is exactly ``n + ceil(c L)`` (or its
    initialization, when later; with a burn-in counted after it); before it every published
    quantity is NaN, after it the model stays published."""
    X, Z = equivalence_problem(n=120)
    options = EstimatorOptions(lags=lags, max_lags=9, publish_lag_windows=windows, residual_burn_in=burn_in)
    L = window_of(options)
    first = {}
    for bank, _, k in fed_bank_and_references(X, Z, lags=lags, max_lags=9, publish_lag_windows=windows,
                                              residual_burn_in=burn_in):
        for j in np.flatnonzero(bank.ready):
            first.setdefault(int(j), k)
        for j in range(2):
            if j not in first:
                assert np.isnan(bank.theta_all()[j]).all() and np.isnan(bank.standard_errors_all()[j]).all()
            else:
                assert bank.ready[j] and np.isfinite(bank.standard_errors_all()[j, : bank.sizes[j]]).all()
        ready_at = bank.ready_at
    for j, n in enumerate((3, 2)):
        b = options.burn_in
        rule = n + math.ceil(windows * L)
        expect = int(ready_at[j]) + b + rule if b else max(int(ready_at[j]), rule)
        assert first[j] == expect, (j, first, ready_at)


@pytest.mark.parametrize("lags, windows, burn_in", [(5, 2.0, None), ("auto", 1.0, 4)])
def test_both_standard_errors_at_once_are_each_kinds(lags, windows, burn_in):
    """``standard_errors_both()`` is ``standard_errors_all()`` of the corrected and the
    conventional kind at every sample, NaN where they are (before and after publication), and
    ``ready`` is the models whose estimates are finite."""
    X, Z = equivalence_problem(n=60)
    for bank, refs, k in fed_bank_and_references(X, Z, lags=lags, max_lags=9, publish_lag_windows=windows,
                                                 residual_burn_in=burn_in):
        se, se_conv = bank.standard_errors_both()
        np.testing.assert_array_equal(se, bank.standard_errors_all("corrected"))
        np.testing.assert_array_equal(se_conv, bank.standard_errors_all("conventional"))
        ready = bank.ready
        assert (np.isfinite(bank.theta_all()[:, 0]) == ready).all(), k
        for j, ref in enumerate(refs):
            if ready[j]:  # the reference twin publishes too: its standard errors, both kinds
                n = bank.sizes[j]
                np.testing.assert_allclose(se[j, :n], ref.standard_errors("corrected"), rtol=1e-6)
                np.testing.assert_allclose(se_conv[j, :n], ref.standard_errors("conventional"), rtol=1e-6)
