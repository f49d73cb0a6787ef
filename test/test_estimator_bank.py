"""Recursive estimator (Eqs. 15-22) against batch formulas, closed forms and Monte Carlo."""

from __future__ import annotations

import ast
import pathlib
import subprocess
import sys

import numpy as np
import pytest

from rls_uncertainty.estimator import (
    EstimatorBank,
    EstimatorNotReady,
    NonFiniteInput,
    RecursiveEstimator,
    batch_estimate,
)

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


def run(est, X, z, stop=None):
    for k in range(len(z) if stop is None else stop):
        est.update(X[k], z[k])
    return est


def rel_close(a, b, rtol):
    """Elementwise closeness relative to the largest magnitude of the reference."""
    scale = np.max(np.abs(b))
    np.testing.assert_allclose(a, b, rtol=rtol, atol=rtol * scale)


# --------------------------------------------------------------------------- estimates
def test_theta_equals_batch_ols_with_scales_from_1e_4_to_1e2():
    X, z = wide_scale_problem()
    est = run(RecursiveEstimator(4, n_lags=50), X, z)
    ols = np.linalg.lstsq(X, z, rcond=None)[0]
    assert np.max(np.abs(est.theta - ols) / np.abs(ols)) < 1e-6
    assert est.n_samples == len(z)


def test_exact_initialization_agrees_with_batch_from_the_first_well_conditioned_sample():
    X, z = wide_scale_problem()
    est = RecursiveEstimator(4)
    for k in range(len(z)):
        est.update(X[k], z[k])
        if est.is_ready:
            ols = np.linalg.lstsq(X[: k + 1], z[: k + 1], rcond=None)[0]
            np.testing.assert_allclose(est.theta, ols, rtol=1e-6)


# --------------------------------------------------------------------------- covariance
CHECK_AT = (40, 200, 600)


@pytest.mark.parametrize("forgetting", [1.0, 0.98])
@pytest.mark.parametrize("window", ["truncated", "bartlett"])
@pytest.mark.parametrize("n_lags", [None, 0, 1, 5, 50])
def test_recursive_covariance_equals_batch_formula_on_recursive_residuals(n_lags, window, forgetting):
    X, z = wide_scale_problem()
    est = RecursiveEstimator(4, n_lags=n_lags, window=window, forgetting=forgetting)
    full = RecursiveEstimator(4, forgetting=forgetting)  # keeps the whole residual history
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
            X[: k + 1], z[: k + 1], n_lags, window, residuals=history, forgetting=forgetting
        )
        rel_close(est.theta, theta, 1e-9)
        rel_close(est.covariance("corrected", repair=False), cov_corr, 1e-9)
        rel_close(est.covariance("conventional"), cov_conv, 1e-9)


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


def test_zero_lags_gives_the_conventional_covariance():
    X, z = wide_scale_problem()
    est = run(RecursiveEstimator(4, n_lags=0), X, z)
    rel_close(est.covariance("corrected"), est.covariance("conventional"), 1e-9)
    np.testing.assert_allclose(
        est.standard_errors("corrected"), est.standard_errors("conventional"), rtol=1e-9
    )


def test_corrected_standard_error_grows_with_colored_residuals():
    X, z = wide_scale_problem()
    est = run(RecursiveEstimator(4, n_lags=50), X, z)
    ratio = est.standard_errors("corrected") / est.standard_errors("conventional")
    # The constant and the 0.3 Hz regressor sit where the AR(1) spectrum is high; the
    # white regressor averages the spectrum, which the conventional formula gets right.
    assert ratio[0] > 2.0 and ratio[2] > 2.0
    assert 0.5 < ratio[3] < 1.5


# --------------------------------------------------------------------------- Monte Carlo
@pytest.mark.parametrize("rho", [0.9, 0.0])
def test_monte_carlo_standard_errors_match_observed_scatter(rho):
    """400 runs as one bank: same regressors, independent AR(1) or white residuals."""
    rng = np.random.default_rng(11)
    n, runs = 1000, 400
    t = np.arange(n) / RATE
    X = np.column_stack([np.ones(n), np.sin(2 * np.pi * 0.4 * t), np.cos(2 * np.pi * 0.9 * t + 0.3)])
    theta = np.array([1.0, 0.5, -0.3])
    Z = (X @ theta)[:, None] + 0.1 * ar1(rng, rho, (runs, n)).T
    bank = EstimatorBank([3] * runs, n_lags=50)
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


# --------------------------------------------------------------------------- windows
def indefinite_problem(n=500):
    """A slowly varying regressor and residuals that oscillate at a frequency where the
    uniform lag window of n_lags = 5 has a negative spectral lobe."""
    rng = np.random.default_rng(5)
    k = np.arange(n)
    X = np.column_stack([np.ones(n), k / n])
    omega = 1.5 * np.pi / 5.5  # sin(5.5 w) = -1: the 5-lag Dirichlet kernel is negative
    z = X @ [0.3, 1.0] + np.sin(omega * k) + 0.01 * rng.standard_normal(n)
    return X, z


def test_truncated_window_can_be_indefinite_and_is_repaired_and_counted():
    X, z = indefinite_problem()
    est = RecursiveEstimator(2, n_lags=5, window="truncated")
    full = RecursiveEstimator(2)
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
    est = RecursiveEstimator(2, n_lags=5, window="bartlett")
    for k in range(len(z)):
        est.update(X[k], z[k])
        if est.is_ready and k % 25 == 0:
            cov = est.covariance(repair=False)
            assert np.min(np.linalg.eigvalsh(cov)) >= -1e-10 * np.max(np.abs(cov))
    assert est.repairs == 0


# --------------------------------------------------------------------------- robustness
def test_snapshot_restore_continues_bit_identically():
    X, z = wide_scale_problem()
    for n_lags in (None, 50):
        a = run(RecursiveEstimator(4, n_lags=n_lags, forgetting=0.995), X, z, stop=300)
        b = RecursiveEstimator.from_state(a.state())
        for k in range(300, len(z)):
            a.update(X[k], z[k])
            b.update(X[k], z[k])
        np.testing.assert_array_equal(a.theta, b.theta)
        np.testing.assert_array_equal(a.covariance(), b.covariance())
        np.testing.assert_array_equal(a.standard_errors("conventional"), b.standard_errors("conventional"))


@pytest.mark.parametrize("forgetting", [1.0, 0.99])
def test_snapshot_while_a_model_waits_for_initialization_continues_bit_identically(forgetting):
    """Restore while one model still accumulates its lagged moments (its third regressor is
    not excited until sample 200): it initializes at the same sample with the same numbers."""
    rng = np.random.default_rng(5)
    n = 500
    X = np.zeros((n, 2, 3))
    X[:, 0, :2] = np.column_stack([np.ones(n), rng.standard_normal(n)])
    X[:, 1] = np.column_stack([np.ones(n), rng.standard_normal(n), np.where(np.arange(n) < 200, 0.0, rng.standard_normal(n))])
    Z = np.einsum("kmi,mi->km", X, [[1.0, 2.0, 0.0], [0.5, -1.0, 3.0]]) + 0.1 * rng.standard_normal((n, 2))
    for n_lags in (None, 20):
        a = EstimatorBank((2, 3), n_lags, forgetting=forgetting)
        for k in range(100):
            a.update(X[k], Z[k])
        assert list(a.ready) == [True, False]
        b = EstimatorBank.from_state(a.state())
        for k in range(100, n):
            a.update(X[k], Z[k])
            b.update(X[k], Z[k])
        assert list(b.ready_at) == list(a.ready_at) and a.ready_at[1] > 200
        np.testing.assert_array_equal(a.theta_all(), b.theta_all())
        np.testing.assert_array_equal(a.standard_errors_all(), b.standard_errors_all())
        np.testing.assert_array_equal(a.standard_errors_all("conventional"), b.standard_errors_all("conventional"))


def test_snapshot_is_a_copy():
    X, z = wide_scale_problem()
    a = run(RecursiveEstimator(4, n_lags=5), X, z, stop=100)
    snap = a.state()
    theta = a.theta.copy()
    run(a, X[100:], z[100:])
    assert np.array_equal(RecursiveEstimator.from_state(snap).theta, theta)


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_non_finite_input_is_rejected_and_leaves_state_untouched(bad):
    X, z = wide_scale_problem()
    est = run(RecursiveEstimator(4, n_lags=5), X, z, stop=100)
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


def test_rank_deficient_early_samples_wait_for_excitation():
    """Elevator still at trim for 150 samples: X'X is singular until the maneuver starts."""
    X, z = wide_scale_problem()
    X = X.copy()
    X[:150, 2] = 0.0
    z = X @ np.array([0.5, 300.0, -0.01, 2.0]) + 0.01 * np.random.default_rng(2).standard_normal(len(z))
    est = RecursiveEstimator(4, n_lags=50)
    full = RecursiveEstimator(4)
    for k in range(len(z)):
        est.update(X[k], z[k])
        full.update(X[k], z[k])
        if k < 150:
            assert not est.is_ready
            with pytest.raises(EstimatorNotReady):
                est.theta
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
    est = run(RecursiveEstimator(4, p0=p0), X, z)
    ridge = np.linalg.solve(X.T @ X + np.eye(4) / p0, X.T @ z)
    np.testing.assert_allclose(est.theta, ridge, rtol=1e-6)
    ols = np.linalg.lstsq(X, z, rcond=None)[0]
    # The prior visibly biases the small-scale regressor's parameter; exact init does not.
    assert abs(est.theta[1] - ols[1]) / abs(ols[1]) > 1e-3


def test_residual_options_are_the_innovation_the_a_posteriori_residual_and_their_geometric_mean():
    X, z = wide_scale_problem()
    est = {r: RecursiveEstimator(4, residual=r) for r in ("a_posteriori", "a_priori", "standardized")}
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
    conventional standard errors equal the batch ones; the a posteriori residual falls short."""
    rng = np.random.default_rng(11)
    n = 400
    X = np.column_stack([np.ones(n), rng.standard_normal((n, 2))])
    colored = np.convolve(rng.standard_normal(n + 9), np.ones(10) / 3.0, "valid")
    z = X @ [0.5, -2.0, 1.0] + colored
    est = RecursiveEstimator(3, 20, forgetting=forgetting)
    post = RecursiveEstimator(3, 20, forgetting=forgetting, residual="a_posteriori")
    short = []
    for k in range(n):
        est.update(X[k], z[k])
        post.update(X[k], z[k])
        if not est.is_ready:
            continue
        w = forgetting ** np.arange(k, -1, -1)
        theta, cov_conv, _ = batch_estimate(X[: k + 1], z[: k + 1], 20, forgetting=forgetting)
        v = z[: k + 1] - X[: k + 1] @ theta
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
    tracking = run(RecursiveEstimator(3, n_lags=11, forgetting=0.99), X, z)
    plain = run(RecursiveEstimator(3, n_lags=11), X, z)
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
    bank = EstimatorBank(sizes, n_lags=11)
    singles = [RecursiveEstimator(s, n_lags=11) for s in sizes]
    for k in range(n):
        bank.update([r[k] for r in rows], np.array([zz[k] for zz in zs]))
        for est, r, zz in zip(singles, rows, zs):
            est.update(r[k], zz[k])
    for j, est in enumerate(singles):
        np.testing.assert_allclose(bank.theta(j), est.theta, rtol=1e-12)
        np.testing.assert_allclose(bank.standard_errors(j), est.standard_errors(), rtol=1e-10)
        np.testing.assert_allclose(bank.theta_all()[j, : sizes[j]], est.theta, rtol=1e-12)
    assert np.isnan(bank.theta_all()[0, 3:]).all()


@pytest.mark.parametrize(
    "kwargs, match",
    [
        (dict(n_lags=-1), "n_lags"),
        (dict(n_lags=2.5), "n_lags"),
        (dict(window="hann"), "window"),
        (dict(forgetting=0.0), "forgetting"),
        (dict(forgetting=1.5), "forgetting"),
        (dict(residual="both"), "residual"),
        (dict(p0=-1.0), "p0"),
    ],
)
def test_invalid_configuration_is_refused_clearly(kwargs, match):
    with pytest.raises(ValueError, match=match):
        RecursiveEstimator(3, **kwargs)


def test_wrong_shapes_are_refused():
    est = RecursiveEstimator(3)
    with pytest.raises(ValueError, match="regressors"):
        est.update([1.0, 2.0], 0.0)
    bank = EstimatorBank((2, 3))
    with pytest.raises(ValueError, match="model 1"):
        bank.update([[1.0, 2.0], [1.0]], [0.0, 0.0])


def test_numerical_core_imports_numpy_only():
    """Every module of the estimator package imports numpy, the standard library's math and
    typing, and the package's own modules only; importing it does not load rclpy."""
    package = pathlib.Path(__file__).resolve().parents[1] / "rls_uncertainty" / "estimator"
    modules = sorted(package.glob("*.py"))
    assert {p.name for p in modules} >= {"__init__.py", "bank.py", "reference.py", "covariance.py"}
    for path in modules:
        tree = ast.parse(path.read_text())
        imported = set()
        for node in ast.walk(tree):
            if isinstance(node, ast.ImportFrom) and node.level > 0:
                # The package's own modules, or its parent's errors module (and nothing else).
                assert node.level == 1 or node.module == "errors", (path.name, node.module)
            elif isinstance(node, ast.ImportFrom):
                imported.add(node.module.split(".")[0])
            elif isinstance(node, ast.Import):
                imported.update(alias.name.split(".")[0] for alias in node.names)
        assert imported <= {"numpy", "math", "typing", "__future__"}, (path.name, imported)
    out = subprocess.run(
        [sys.executable, "-c", "import sys, rls_uncertainty.estimator; print('rclpy' in sys.modules)"],
        capture_output=True, text=True, check=True,
    )
    assert out.stdout.strip() == "False"


def test_an_exactly_fitted_model_has_zero_corrected_errors_without_repairs():
    rng = np.random.default_rng(5)
    X = np.column_stack([np.ones(300), rng.standard_normal(300), rng.standard_normal(300)])
    z = X @ np.array([0.3, -1.2, 0.7])  # no noise: residuals are rounding only
    bank = EstimatorBank([3], 50)
    for k in range(300):
        bank.update(X[k : k + 1], z[k : k + 1])
    se = bank.standard_errors(0, "corrected")
    cov = bank.covariance(0, "corrected")
    assert np.all(np.isfinite(se)) and np.all(se < 1e-8)  # rounding-level, never NaN
    assert np.all(np.abs(cov) < 1e-16)
    assert bank.repairs[0] == 0
    # A constant output fitted exactly by its bias (the T-2 bag's CX): rounding makes the
    # corrected variances slightly negative; they are zero, not a repair.
    const = EstimatorBank([3], 50)
    for k in range(300):
        const.update(X[k : k + 1], [-0.03])
    assert np.all(const.standard_errors(0, "corrected") == 0.0) or np.all(const.standard_errors(0, "corrected") < 1e-8)
    const.covariance(0, "corrected")
    assert const.repairs[0] == 0


def test_numpy_126_vecdot_fallback_gives_the_same_standard_errors(monkeypatch):
    """numpy < 2.0 has no vecdot; the einsum fallback must give the same covariances."""
    from rls_uncertainty.estimator import bank as bank_module

    X, z = wide_scale_problem()
    ref = run(RecursiveEstimator(4, n_lags=20, forgetting=0.99), X, z)
    monkeypatch.setattr(bank_module, "vecdot", bank_module._einsum_vecdot)
    alt = run(RecursiveEstimator(4, n_lags=20, forgetting=0.99), X, z)
    np.testing.assert_allclose(alt.standard_errors(), ref.standard_errors(), rtol=1e-12)
    np.testing.assert_allclose(alt.standard_errors("conventional"), ref.standard_errors("conventional"), rtol=1e-12)
    np.testing.assert_allclose(alt.theta, ref.theta, rtol=1e-12)
