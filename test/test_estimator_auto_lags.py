"""Automatic lag selection in the estimator: ``lags="auto"`` chooses each model's
L of Eq. 22 by Politis' flat-top rule on its residual autocorrelation at every evaluated
sample, with the memory of ``lags=max_lags``."""

from __future__ import annotations

import numpy as np
import pytest
from test_estimator_bank import assert_bank_equals_reference, equivalence_problem, fed_bank_and_references
from test_estimator_cases import ar1, rel_close, run, wide_scale_problem

from rls_uncertainty.estimator import EstimatorBank, EstimatorOptions, RecursiveEstimator, batch_estimate
from rls_uncertainty.estimator.lag_selection import flat_top_lags
from rls_uncertainty.estimator.reference import RecursiveReference, flat_top_lag


@pytest.mark.parametrize("p0", [None, 100.0])
@pytest.mark.parametrize("residual", ["standardized", "a_posteriori"])
@pytest.mark.parametrize("forgetting", [1.0, 0.97])
@pytest.mark.parametrize(
    "max_lags, min_lags, burn_in", [(5, 0, None), (50, 0, None), (8, 3, None), (5, 0, 0), (8, 3, 7)]
)
def test_auto_bank_equals_the_reference(max_lags, min_lags, burn_in, forgetting, residual, p0):
    """Theta, covariances, standard errors and the chosen lags of the bank equal the literal
    Eqs. 15-22 with the literal flat-top rule of reference.py, at every sample; with the
    default residual burn-in (50 samples: the models initialize at 13 and 2, or 0 with a
    prior), without one (the paper) and with 7."""
    X, Z = equivalence_problem(n=160)
    options = dict(lags="auto", forgetting=forgetting, residual=residual, p0=p0, max_lags=max_lags,
                   min_lags=min_lags, residual_burn_in=burn_in)
    chosen = set()
    for bank, refs, k in fed_bank_and_references(X, Z, **options):
        assert list(bank.lags_used) == [r.lags_used() for r in refs], k - 1
        chosen.update(int(L) for L, ready in zip(bank.lags_used, bank.initialized, strict=True) if ready)
        if k % 10 == 0 or k <= 15:
            assert_bank_equals_reference(bank, refs, k)
    assert len(chosen) >= 2  # the choice moves


def test_reference_rule_is_the_vectorised_rule():
    """flat_top_lag (reference, one model, a loop) equals lag_selection.flat_top_lags."""
    rng = np.random.default_rng(1)
    for _ in range(300):
        W = int(rng.integers(1, 60))
        n = float(rng.choice([1.0, 1.5, 2.0, 7.0, 60.0, 500.0, 1e4]))
        rho = rng.uniform(0.3, 0.99)
        R = rho ** np.arange(W) * rng.choice([1.0, -1.0], W) ** rng.integers(0, 2) + 0.05 * rng.standard_normal(W)
        R[0] = abs(R[0]) if rng.random() > 0.05 else 0.0
        cap, lo = int(rng.integers(1, 70)), int(rng.integers(0, 5))
        lo = min(lo, cap)
        assert flat_top_lag(list(R), n, cap, lo) == flat_top_lags(R, n, cap=cap, min_lags=lo), (W, n, cap, lo)


@pytest.mark.parametrize("burn_in", [0, None])
@pytest.mark.parametrize("forgetting", [1.0, 0.99])
def test_auto_covariance_is_the_batch_formula_with_the_chosen_lags(forgetting, burn_in):
    """At every checked sample the covariance is Eq. 22 with L = lags_used on the residual
    history (noise-model residuals under forgetting), and lags_used is the rule applied to
    autocorrelation(). With the default residual burn-in (50 samples with auto), after the
    burn-in the history's first k0 + 50 residuals are zeroed and R rescaled to the weight
    total of the rest (the batch formula of the residual burn-in), and the
    rule's n is the count (Kish's size under forgetting) of the samples after it."""
    X, z = wide_scale_problem()
    options = EstimatorOptions(lags="auto", forgetting=forgetting, max_lags=40, residual_burn_in=burn_in)
    est = RecursiveEstimator(4, options)
    assert options.burn_in == (50 if burn_in is None else 0)
    g = options.noise_forgetting_used
    # the whole history:
    full = RecursiveEstimator(4, EstimatorOptions(lags="all", forgetting=forgetting, noise_forgetting=g))
    seen = set()
    for k in range(len(z)):
        est.update(X[k], z[k])
        full.update(X[k], z[k])
        if k + 1 not in (30, 41, 42, 100, 250, 600):
            continue
        end = int(est.bank.ready_at[0]) + options.burn_in  # the last left-out sample
        c = k + 1 - end if burn_in is None and k + 1 > end else k + 1  # samples behind R
        n = c if g == 1.0 else (1 - g**c) * (1 + g) / ((1 - g) * (1 + g**c))
        assert est.bank.rule_samples[0] == pytest.approx(n, rel=1e-12)
        L = est.lags_used
        seen.add(L)
        assert L == flat_top_lags(est.autocorrelation(), est.bank.rule_samples[0], cap=40)
        v = full.noise_residuals()
        scale = 1.0
        if c < k + 1:
            v[:end] = 0.0
            scale = np.sum(g ** np.arange(k + 1)) / np.sum(g ** np.arange(c))
        _, cov_conv, cov_corr = batch_estimate(
            X[: k + 1], z[: k + 1], L, residuals=v, forgetting=forgetting, noise_forgetting=g
        )
        rel_close(est.covariance("corrected", repair=False), cov_corr * scale, 1e-9)
        rel_close(est.covariance("conventional"), cov_conv * scale, 1e-9)
    assert len(seen) >= 2, seen


def test_white_residuals_get_no_lags_and_colored_ones_get_many():
    rng = np.random.default_rng(2)
    n = 2000
    X = np.column_stack([np.ones(n), np.sin(0.05 * np.arange(n)), rng.standard_normal(n)])
    z_white = X @ [1.0, 2.0, 3.0] + 0.1 * rng.standard_normal(n)
    z_ar = X @ [1.0, 2.0, 3.0] + 0.1 * ar1(rng, 0.9, (n,))
    bank = EstimatorBank((3, 3, 3), EstimatorOptions(lags="auto", max_lags=50))
    Xb = np.stack([X, X, X], axis=1)
    Z = np.column_stack([z_white, z_ar, X @ [1.0, 2.0, 3.0]])  # the third fits exactly
    run(bank, Xb, Z)
    L = bank.lags_used
    assert L[0] <= 4 and 16 <= L[1] <= 50 and L[2] == 0
    assert np.all(bank.covariance(2) == 0.0) or np.all(np.abs(bank.covariance(2)) < 1e-20)


@pytest.mark.parametrize("min_lags", [0, 3])
@pytest.mark.parametrize("forgetting", [1.0, 0.99])
def test_an_exact_fit_gets_min_lags_whatever_its_rounding(min_lags, forgetting):
    """A model that fits exactly has residuals at rounding level, whose pattern depends on
    the floating-point kernels of the machine: it gets min_lags at every sample from its
    initialization, in the bank and in the reference, even with a strongly colored error of
    1e-8 of its output (R(0) ~ 1e-16 of the output's mean square, below EXACT_FIT = 1e-12),
    which the rule alone would read as 50 lags; with 1e-4 (1e-8, above it) it does read it.
    (min_lags as far as the samples behind R allow: right after the residual burn-in, one.)"""
    rng = np.random.default_rng(8)
    n = 400
    X = np.column_stack([np.ones(n), np.sin(0.05 * np.arange(n)), rng.standard_normal(n)])
    clean = X @ [1.0, 2.0, 3.0]
    colored = ar1(rng, 0.99, (n,))
    options = EstimatorOptions(lags="auto", max_lags=50, min_lags=min_lags, forgetting=forgetting)
    bank = EstimatorBank((3, 3, 3), options)
    refs = [RecursiveReference(3, options) for _ in range(3)]
    Z = np.column_stack([clean, clean + 1e-8 * colored, clean + 1e-4 * colored])
    for k in range(n):
        bank.update(np.stack([X[k]] * 3), Z[k])
        for ref, z in zip(refs, Z[k], strict=True):
            ref.update(X[k], z)
        if bank.ready.all() and k > 3:
            L = [r.lags_used() for r in refs]
            assert list(bank.lags_used) == L, k
            as_zero = [int(flat_top_lags(np.zeros(bank.n_window), bank.rule_samples[j], cap=50, min_lags=min_lags))
                       for j in range(2)]  # the rule for R = 0: min_lags, as far as the samples allow
            assert L[:2] == as_zero and (k < 60 or as_zero == [min_lags] * 2), k
    assert bank.lags_used[2] >= 40  # the same colored error, visible: many lags
    R = bank.autocorrelation(1)
    assert flat_top_lags(R, n, cap=50) == 50  # what the rule alone would choose for model 1


def test_edge_cases():
    bank = EstimatorBank((2,), EstimatorOptions(lags="auto", max_lags=10, min_lags=3))
    assert list(bank.lags_used) == [0]  # no sample: nothing held
    rng = np.random.default_rng(0)
    for _ in range(30):
        bank.update(np.array([[1.0, 0.0]]), rng.standard_normal(1))  # never ready
    assert not bank.ready[0] and list(bank.lags_used) == [3]
    assert np.isnan(bank.standard_errors_all()).all()
    # The residual burn-in defaults to 50 samples with auto, to the paper (0) with fixed lags.
    assert [EstimatorOptions(lags=n).burn_in for n in ("auto", 5, 0, "all")] == [50, 0, 0, 0]
    assert EstimatorOptions(lags="auto", residual_burn_in=0).burn_in == 0
    fixed = run(EstimatorBank((4,), EstimatorOptions(lags=7)), *(a[:, None] for a in wide_scale_problem()), stop=5)
    assert list(fixed.lags_used) == [4]


@pytest.mark.parametrize("forgetting", [1.0, 0.99])
def test_auto_state_continues_bit_identically_with_the_memory_of_max_lags(forgetting):
    """state()/from_state() round-trips lags="auto", max_lags, min_lags (also while a model
    waits); the state has exactly the arrays of lags=max_lags."""
    rng = np.random.default_rng(5)
    n = 500
    X = np.zeros((n, 2, 3))
    X[:, 0, :2] = np.column_stack([np.ones(n), rng.standard_normal(n)])
    X[:, 1] = np.column_stack([np.ones(n), rng.standard_normal(n), np.where(np.arange(n) < 200, 0.0, 1.0)])
    Z = np.einsum("kmi,mi->km", X, [[1.0, 2.0, 0.0], [0.5, -1.0, 3.0]]) + 0.1 * ar1(rng, 0.8, (2, n)).T
    for stop in (100, 300):
        a = EstimatorBank((2, 3), EstimatorOptions(lags="auto", forgetting=forgetting, max_lags=20, min_lags=1))
        run(a, X, Z, stop)
        saved = a.state()
        fixed = run(EstimatorBank((2, 3), EstimatorOptions(lags=20, forgetting=forgetting)), X, Z, stop).state()
        assert {k: v.shape for k, v in saved["arrays"].items()} == {k: v.shape for k, v in fixed["arrays"].items()}
        b = EstimatorBank.from_state(saved)
        assert (b.options.lags, b.options.max_lags, b.options.min_lags) == ("auto", 20, 1)
        for k in range(stop, n):
            a.update(X[k], Z[k])
            b.update(X[k], Z[k])
            if k % 50 == 0:
                np.testing.assert_array_equal(a.lags_used, b.lags_used)
                np.testing.assert_array_equal(a.standard_errors_all(), b.standard_errors_all())
        np.testing.assert_array_equal(a.theta_all(), b.theta_all())


# --------------------------------------------------------------------------- configuration, pipeline, CLI
def test_parameters_reach_the_bank_and_are_validated():
    from rls_uncertainty.errors import ConfigError
    from rls_uncertainty.settings import pipeline_config

    cfg = pipeline_config({"estimator.lag_selection": "auto", "estimator.max_lag_span": 1.6})
    assert cfg.estimator.lags == "auto" and cfg.estimator.max_lags == 80
    assert cfg.fingerprint()["estimator"]["lags"] == "auto" and cfg.fingerprint()["estimator"]["max_lags"] == 80
    fixed = pipeline_config({"estimator.max_lag_span": 1.6})
    assert fixed.estimator.lags == 50 and fixed.estimator.held == 50
    for params, match in [
        ({"estimator.lag_selection": "auto", "estimator.window": "bartlett"}, "truncated"),
        ({"estimator.lag_selection": "sometimes"}, "estimator.lag_selection"),
        ({"estimator.max_lag_span": 0}, "estimator.max_lag_span"),
    ]:
        with pytest.raises(ConfigError, match=match):
            pipeline_config(params)
    with pytest.raises(ConfigError, match=r"estimator\.max_lags"):
        EstimatorOptions(max_lags=2.5)


def test_pipeline_publishes_the_chosen_lags_per_sample_and_in_the_model_fit():
    from test_pipeline import T2_PARAMS, feed_streams

    from rls_uncertainty.datapath.pipeline import Pipeline
    from rls_uncertainty.settings import pipeline_config
    from rls_uncertainty.simulation.t2 import simulate_sensor_streams

    st = simulate_sensor_streams(0.2, 250)
    pipe = Pipeline(pipeline_config({**T2_PARAMS, "estimator.lag_selection": "auto"}))
    outs = feed_streams(pipe, st)
    assert pipe.bank.options.lags == "auto" and pipe.bank.options.max_lags == 50
    lags = np.array([o.lags for o in outs])
    ready = np.array([o.ready for o in outs])
    assert lags.dtype.kind == "i" and np.all(lags[~ready] == 0) and lags.max() <= 50
    assert len(np.unique(lags[ready[:, 0], 0])) > 2  # the choice follows the data
    np.testing.assert_array_equal(outs[-1].lags, pipe.bank.lags_used)
    assert [pipe.model_fit(j)["lags"] for j in range(2)] == list(pipe.bank.lags_used)
    fixed = Pipeline(pipeline_config(T2_PARAMS))
    outs = feed_streams(fixed, st)
    assert np.all(outs[-1].lags == 50) and fixed.model_fit(0)["lags"] == 50


def test_monte_carlo_with_auto_lags_uses_the_default_burn_in(tmp_path):
    """run_level with lags="auto" runs the bank's default residual burn-in (50 samples) unless
    told otherwise; the estimates do not depend on it, the standard errors do, and the table
    says which was used."""
    from rls_uncertainty.simulation.montecarlo import run_level, write_outputs

    default = run_level(0.0, 3, options=EstimatorOptions(lags="auto"))
    paper = run_level(0.0, 3, options=EstimatorOptions(lags="auto", residual_burn_in=0))
    assert (default.residual_burn_in, paper.residual_burn_in) == (50, 0)
    np.testing.assert_array_equal(default.estimates, paper.estimates)
    assert not np.array_equal(default.se_corrected, paper.se_corrected)
    assert run_level(0.0, 2).residual_burn_in == 0  # fixed lags: the paper
    assert "Residual burn-in 50 samples" in write_outputs([default], tmp_path, figures=False)["md"].read_text()

