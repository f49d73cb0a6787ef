"""The executable specification (reference.py) against closed forms and independent batch
formulas: Eqs. 6, 10, 11, 13-14 written out as sums, Eq. 19, weighted and ridge least squares."""

from __future__ import annotations

import numpy as np
import pytest
from test_estimator_cases import ar1, indefinite_problem, rel_close

from rls_uncertainty.estimator import EstimatorNotReady, EstimatorOptions
from rls_uncertainty.estimator.lag_window import lag_weights
from rls_uncertainty.estimator.reference import RecursiveReference, batch_reference


def problem(n=70, seed=1):
    rng = np.random.default_rng(seed)
    k = np.arange(n)
    X = np.column_stack([np.ones(n), np.sin(0.25 * k) + 0.2 * rng.standard_normal(n), rng.standard_normal(n)])
    z = X @ [0.7, -1.5, 0.4] + 0.3 * ar1(rng, 0.8, (n,))
    return X, z


def weights(k, f):
    """w_j = f^(k-j) for j = 1..k."""
    return f ** np.arange(k - 1, -1, -1, dtype=float)


# --------------------------------------------------------------------------- batch
@pytest.mark.parametrize("forgetting", [1.0, 0.95])
@pytest.mark.parametrize("lags, window", [("all", "truncated"), (4, "truncated"), (4, "bartlett"), (0, "truncated")])
def test_batch_reference_is_eqs_6_10_11_13_14_as_sums(lags, window, forgetting):
    X, z = problem(40)
    N = len(z)
    w = weights(N, forgetting)
    theta, cov_conv, cov_corr = batch_reference(X, z, lags, window, forgetting=forgetting)
    A = sum(w[j] * np.outer(X[j], X[j]) for j in range(N))
    D = np.linalg.inv(A)
    np.testing.assert_allclose(theta, np.linalg.solve(A, sum(w[j] * X[j] * z[j] for j in range(N))),
                               rtol=1e-10)  # Eq. 6
    v = z - X @ theta  # Eq. 7
    R = [sum(w[j] * v[j] * v[j - i] for j in range(i, N)) / w.sum() for i in range(N)]  # Eq. 10
    c = lag_weights(N - 1 if lags == "all" else lags, window, N)
    middle = sum(
        w[a] * w[b] * c[abs(a - b)] * R[abs(a - b)] * np.outer(X[a], X[b]) for a in range(N) for b in range(N)
    )  # Eq. 11, weighted
    rel_close(cov_corr, D @ middle @ D, 1e-10)
    sigma2 = sum(w * v * v) / w.sum()  # Eq. 14
    white = sum(w[j] ** 2 * np.outer(X[j], X[j]) for j in range(N))
    rel_close(cov_conv, sigma2 * (D if forgetting == 1.0 else D @ white @ D), 1e-10)  # Eq. 13


# --------------------------------------------------------------------------- recursion
@pytest.mark.parametrize("forgetting", [1.0, 0.95])
def test_recursive_reference_is_weighted_least_squares_at_every_sample(forgetting):
    """After exact initialization theta_k and D_k are the weighted batch solution (Eq. 6) of
    samples 1..k; before it, there is no estimate."""
    X, z = problem()
    ref = RecursiveReference(3, EstimatorOptions(lags=5, forgetting=forgetting))
    for k in range(1, len(z) + 1):
        ref.update(X[k - 1], z[k - 1])
        if k < 3:
            assert not ref.ready
            with pytest.raises(EstimatorNotReady):
                ref.covariance()
            continue
        assert ref.ready and ref.ready_at == 3
        w = weights(k, forgetting)
        A = X[:k].T @ (w[:, None] * X[:k])
        rel_close(ref.D, np.linalg.inv(A), 1e-9)
        rel_close(ref.theta, np.linalg.solve(A, X[:k].T @ (w * z[:k])), 1e-9)


def test_exact_initialization_waits_for_a_well_conditioned_normal_matrix():
    X, z = problem()
    X = X.copy()
    X[:5, 1:] = 0.0  # no excitation: A_k is singular
    X[5:25, 2] = 2.0 * X[5:25, 1] + 1e-9 * np.arange(20)  # nearly collinear: cond(A) > 1e8
    ref = RecursiveReference(3, EstimatorOptions(lags="all", init_condition=1e8))
    for k in range(1, len(z) + 1):
        ref.update(X[k - 1], z[k - 1])
        A = X[:k].T @ X[:k]
        s = np.sqrt(np.diag(A))
        well = np.all(s > 0) and np.linalg.cond(A / np.outer(s, s)) < 1e8
        if not ref.ready:
            assert not well, k
        else:
            break
    assert well and ref.ready_at == k > 25
    np.testing.assert_allclose(ref.theta, np.linalg.lstsq(X[:k], z[:k], rcond=None)[0], rtol=1e-8)


@pytest.mark.parametrize("forgetting", [1.0, 0.95])
def test_prior_initialization_is_ridge_regression(forgetting):
    """With D_0 = diag(p0): D_k^-1 = f^k D_0^-1 + X'WX and theta_k solves it with X'Wz."""
    X, z = problem()
    p0 = np.array([10.0, 2.0, 0.5])
    ref = RecursiveReference(3, EstimatorOptions(lags="all", p0=p0, forgetting=forgetting))
    for k in range(1, len(z) + 1):
        ref.update(X[k - 1], z[k - 1])
        w = weights(k, forgetting)
        info = forgetting**k * np.diag(1.0 / p0) + X[:k].T @ (w[:, None] * X[:k])
        rel_close(ref.D, np.linalg.inv(info), 1e-9)
        rel_close(ref.theta, np.linalg.solve(info, X[:k].T @ (w * z[:k])), 1e-9)


@pytest.mark.parametrize("forgetting", [1.0, 0.9])
def test_lambda_is_eq_19_with_the_sandwich_weights(forgetting):
    """Eq. 21 accumulates Eq. 19: Lambda_k(i) = sum_j w_(j+i) w_j (x_(j+i) x_j' + x_j x_(j+i)')
    for i > 0 and sum_j w_j^2 x_j x_j' at i = 0 (w_j = f^(k-j), all ones when f = 1)."""
    X, z = problem(30)
    ref = RecursiveReference(3, EstimatorOptions(lags="all", forgetting=forgetting))
    for k in range(len(z)):
        ref.update(X[k], z[k])
    N = len(z)
    w = weights(N, forgetting)
    for i in range(N):
        if i == 0:
            expected = sum(w[j] ** 2 * np.outer(X[j], X[j]) for j in range(N))
        else:
            expected = sum(
                w[j + i] * w[j] * (np.outer(X[j + i], X[j]) + np.outer(X[j], X[j + i])) for j in range(N - i)
            )
        rel_close(ref.Lam[i], expected, 1e-12)


@pytest.mark.parametrize("forgetting", [1.0, 0.95])
def test_residual_kinds_and_the_autocorrelation_of_each(forgetting):
    """a_priori is z_k - x_k' theta_(k-1), a_posteriori z_k - x_k' theta_k (Eq. 7), standardized
    the signed geometric mean; R_k(i) (Eq. 17) is sum_j w_j v_j v_(j-i) / n_k of the residual
    history; with the standardized residual R_k(0) is the batch fit error variance (Eq. 14)."""
    X, z = problem()
    own = dict(lags=6, forgetting=forgetting, noise_forgetting=forgetting)  # own residuals (noise model: next test)
    kinds = ("a_priori", "a_posteriori", "standardized")
    refs = {r: RecursiveReference(3, EstimatorOptions(residual=r, **own)) for r in kinds}
    thetas = [None]
    for k in range(1, len(z) + 1):
        for ref in refs.values():
            ref.update(X[k - 1], z[k - 1])
        thetas.append(refs["a_priori"].theta.copy() if refs["a_priori"].ready else None)
        if k <= 4:
            continue
        x, zk = X[k - 1], z[k - 1]
        prior = zk - x @ thetas[k - 1]
        post = zk - x @ thetas[k]
        assert refs["a_priori"].v[-1] == pytest.approx(prior, rel=1e-10)
        assert refs["a_posteriori"].v[-1] == pytest.approx(post, rel=1e-9, abs=1e-12)
        assert refs["standardized"].v[-1] == pytest.approx(np.sign(prior) * np.sqrt(prior * post), rel=1e-9)
        w = weights(k, forgetting)
        for ref in refs.values():
            v = np.array(ref.v)
            R = [sum(w[j] * v[j] * v[j - i] for j in range(i, k)) / w.sum() for i in range(min(k, 7))]
            np.testing.assert_allclose([ref.R[i] for i in range(len(R))], R, rtol=1e-9, atol=1e-14)
        batch_v = z[:k] - X[:k] @ refs["standardized"].theta
        assert refs["standardized"].R[0] == pytest.approx(np.sum(w * batch_v**2) / w.sum(), rel=1e-9)


@pytest.mark.parametrize("residual", ["a_priori", "a_posteriori", "standardized"])
@pytest.mark.parametrize("noise_forgetting", [None, 0.99, 1.0])
def test_noise_model_is_least_squares_weighted_f_R_and_gives_R(noise_forgetting, residual):
    """Under forgetting (f = 0.95, 6 lags) the noise model is the f_R-weighted batch fit at every
    sample, its residuals are of the chosen kind with f_R, R_k(i) (Eq. 17) is their
    f_R-weighted autocorrelation, and D_k, theta_k stay the f-weighted fit's."""
    X, z = problem()
    f = 0.95
    ref = RecursiveReference(3, EstimatorOptions(lags=6, forgetting=f, residual=residual,
                                                 noise_forgetting=noise_forgetting))
    g = ref.g
    assert g == (1.0 - 1.0 / 280.0 if noise_forgetting is None else noise_forgetting) and ref.noise
    for k in range(1, len(z) + 1):
        theta_R_before = ref.theta_R.copy()
        ref.update(X[k - 1], z[k - 1])
        if k < 3:
            assert not ref.ready
            continue
        w, w_R = weights(k, f), weights(k, g)
        A, A_R = X[:k].T @ (w[:, None] * X[:k]), X[:k].T @ (w_R[:, None] * X[:k])
        rel_close(ref.D, np.linalg.inv(A), 1e-9)
        rel_close(ref.theta, np.linalg.solve(A, X[:k].T @ (w * z[:k])), 1e-9)
        rel_close(ref.D_R, np.linalg.inv(A_R), 1e-9)
        rel_close(ref.theta_R, np.linalg.solve(A_R, X[:k].T @ (w_R * z[:k])), 1e-9)
        u = np.array(ref.u)
        if k > 3:
            x, zk = X[k - 1], z[k - 1]
            prior, post = zk - x @ theta_R_before, zk - x @ ref.theta_R
            expected = {"a_priori": prior, "a_posteriori": post, "standardized": np.sign(prior) * np.sqrt(prior * post)}
            assert u[-1] == pytest.approx(expected[residual], rel=1e-8, abs=1e-12)
        else:  # at initialization: Eq. 7 of the f_R-weighted batch fit
            np.testing.assert_allclose(u, z[:k] - X[:k] @ ref.theta_R, rtol=1e-9, atol=1e-12)
        R = [sum(w_R[j] * u[j] * u[j - i] for j in range(i, k)) / w_R.sum() for i in range(min(k, 7))]
        np.testing.assert_allclose([ref.R[i] for i in range(len(R))], R, rtol=1e-9, atol=1e-14)


@pytest.mark.parametrize("forgetting", [1.0, 0.95])
@pytest.mark.parametrize(
    "lags, window", [("all", "truncated"), ("all", "bartlett"), (6, "truncated"), (6, "bartlett"), (0, "truncated")]
)
def test_recursive_covariance_is_eq_11_on_the_recursive_residuals(lags, window, forgetting):
    """Eq. 20/22 with R_k of the recursive residual history is the batch covariance of Eq. 8
    (Eq. 11 regrouped as Eq. 18) with those residuals; the conventional one is Eq. 13. Under
    forgetting with lags (a noise model) these are the noise model's residuals, weighted f_R."""
    X, z = problem(50)
    ref = RecursiveReference(3, EstimatorOptions(lags=lags, window=window, forgetting=forgetting))
    for k in range(len(z)):
        ref.update(X[k], z[k])
    assert ref.noise == (forgetting < 1.0 and lags != "all")
    _, conv, corr = batch_reference(
        X, z, lags, window, forgetting=forgetting, residuals=np.array(ref.u if ref.noise else ref.v),
        noise_forgetting=ref.g,
    )
    rel_close(ref.covariance("corrected"), corr, 1e-9)
    rel_close(ref.covariance("conventional"), conv, 1e-9)


def test_zero_lags_corrected_is_the_conventional_covariance():
    """Eq. 22 with n_tau = 0 is Eq. 13: D Lambda(0) D R(0) = R(0) D when f = 1."""
    X, z = problem()
    ref = RecursiveReference(3, EstimatorOptions(lags=0))
    for k in range(len(z)):
        ref.update(X[k], z[k])
    rel_close(ref.covariance("corrected"), ref.covariance("conventional"), 1e-9)


def test_published_covariance_is_repaired_to_the_nearest_positive_semidefinite_matrix():
    X, z = indefinite_problem(300)
    ref = RecursiveReference(2, EstimatorOptions(lags=5))
    for k in range(len(z)):
        ref.update(X[k], z[k])
    raw = ref.covariance()
    assert np.min(np.diag(raw)) < 0
    published = ref.published_covariance()
    vals, vecs = np.linalg.eigh(0.5 * (raw + raw.T))
    np.testing.assert_allclose(published, (vecs * np.maximum(vals, 0)) @ vecs.T, rtol=1e-12, atol=1e-15)
    np.testing.assert_array_equal(ref.standard_errors(), np.sqrt(np.maximum(np.diag(published), 0)))
    exact = RecursiveReference(2, EstimatorOptions(lags=5))
    for k in range(60):
        exact.update(X[k], X[k] @ [0.3, 1.0])  # no noise: an exact fit publishes zero
    assert np.all(exact.published_covariance() == 0.0) or np.min(np.diag(exact.covariance())) >= 0


# --------------------------------------------------------------------------- residual burn-in
@pytest.mark.parametrize("residual", ["a_priori", "a_posteriori", "standardized"])
@pytest.mark.parametrize(
    "lags, window, forgetting",
    [(6, "truncated", 1.0), ("all", "bartlett", 1.0), (6, "truncated", 0.95), ("all", "truncated", 0.95),
     (0, "truncated", 0.95)],
)
def test_burn_in_is_eq_17_on_the_residuals_after_it(lags, window, forgetting, residual):
    """With residual_burn_in B, R_k(i) is the paper's up to k0 + B and afterwards
    sum_{j > k0+B, j-i > k0+B} w_j v_j v_(j-i) / sum_{j > k0+B} w_j (w_j = f_R^(k-j); the noise
    model's residuals under forgetting with lags); the covariances are then Eq. 8 (batch) with
    the residuals of samples 1..k0+B zeroed and Eq. 10 normalised by the weight total of the
    samples after them."""
    X, z = problem()
    B = 9
    options = dict(lags=lags, window=window, forgetting=forgetting, residual=residual)
    ref = RecursiveReference(3, EstimatorOptions(residual_burn_in=B, **options))
    paper = RecursiveReference(3, EstimatorOptions(residual_burn_in=0, **options))
    g = ref.g
    for k in range(1, len(z) + 1):
        ref.update(X[k - 1], z[k - 1])
        paper.update(X[k - 1], z[k - 1])
        if not ref.ready:
            continue
        end = ref.ready_at + B
        if k <= end:
            assert ref.R == paper.R
            continue
        w = weights(k, g)
        v = np.array(ref.u if ref.noise else ref.v)
        held = range(ref.largest_lag() + 1)
        R = [sum(w[j] * v[j] * v[j - i] for j in range(end + i, k)) / w[end:].sum() for i in held]
        np.testing.assert_allclose([ref.R[i] for i in held], R, rtol=1e-9, atol=1e-15)
    assert ref.ready_at == 3 and len(z) > ref.ready_at + B
    v = np.array(ref.u if ref.noise else ref.v)
    v[:end] = 0.0
    scale = w.sum() / w[end:].sum()
    _, conv, corr = batch_reference(X, z, lags, window, forgetting=forgetting, residuals=v, noise_forgetting=g)
    rel_close(ref.covariance("corrected"), corr * scale, 1e-9)
    rel_close(ref.covariance("conventional"), conv * scale, 1e-9)


def test_burn_in_defaults_by_lag_selection():
    assert [RecursiveReference(3, EstimatorOptions(lags=lags)).B for lags in ("auto", 50, "all")] == [50, 0, 0]
    assert RecursiveReference(3, EstimatorOptions(lags="auto", residual_burn_in=0)).B == 0
