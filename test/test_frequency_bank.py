"""FrequencyBank, the recursive estimator, against the literal batch reference at every evaluated
sample (estimates, both covariances, transforms), its corrected variance against the one of the
true noise, and its behaviour at the edges: exact fits, evaluation every m samples, refused
samples, resets, models that are not ready."""

from __future__ import annotations

import numpy as np
import pytest

from rls_uncertainty.errors import EstimatorNotReady, NonFiniteInput
from rls_uncertainty.frequency import FrequencyBank, FrequencyOptions, finite_fourier_transform, frequency_reference
from rls_uncertainty.frequency.covariance import PairGeometry, middle
from rls_uncertainty.simulation.montecarlo import level_inputs

RATE = 50.0
SIZES = (2, 3)  # the T-2's C_Z (alpha, delta_e) and C_m (alpha, q_hat, delta_e)


@pytest.fixture(scope="module")
def t2_run():
    """One T-2 run of Table 3's setting at 20 % band-limited noise, regressors without the bias."""
    _t, _red, _sizes, X, Z = level_inputs(0.20, 1, seed=11)
    x = np.zeros((X.shape[0], 2, 3))
    x[:, 0, :2] = X[:, 0, 1:3]
    x[:, 1, :3] = X[:, 1, 1:4]
    return x, Z


def feed(bank: FrequencyBank, x: np.ndarray, z: np.ndarray, start: int = 0, stop: int | None = None) -> None:
    for k in range(start, x.shape[0] if stop is None else stop):
        bank.update(x[k], z[k])


@pytest.mark.parametrize(("dof_correction", "trim"), [(True, 1), (False, 1), (True, 25)])
def test_the_bank_equals_the_batch_reference_at_every_evaluated_sample(t2_run, dof_correction, trim):
    x, z = t2_run
    options = FrequencyOptions(rate_hz=RATE, f_max=2.2, dof_correction=dof_correction, trim_samples=trim)
    bank = FrequencyBank(SIZES, options)
    checks = {12, 25, 26, 51, 52, 120, 173, 300, x.shape[0]}
    for k in range(x.shape[0]):
        bank.update(x[k], z[k])
        if k + 1 not in checks:
            continue
        assert bank.solved.all()
        for j, p in enumerate(SIZES):
            ref = frequency_reference(x[: k + 1, j, :p], z[: k + 1, j], options)
            np.testing.assert_allclose(bank.theta(j), ref.theta, rtol=1e-9)
            np.testing.assert_allclose(bank.covariance(j, "conventional"), ref.cov_conventional, rtol=1e-9,
                                       atol=1e-12 * np.abs(ref.cov_conventional).max())
            expected = ref.cov_corrected
            # The corrected covariance solves with Re(X^H X) on both sides: bank and reference, summed
            # in different orders, differ by rounding amplified by its condition number (1.5e6 for C_m
            # 12 samples in; 1e4 later), so 1e-9 or 20 eps cond, whichever is larger.
            rtol = max(1e-9, 20 * np.finfo(float).eps * np.linalg.cond(ref.cov_conventional))
            np.testing.assert_allclose(bank.covariance(j), expected, rtol=rtol, atol=1e-12 * np.abs(expected).max())
            np.testing.assert_allclose(bank.autocorrelation(j), ref.R, rtol=1e-9, atol=1e-12 * abs(ref.R[0]))
            np.testing.assert_allclose(bank.standard_errors(j), np.sqrt(np.diag(expected).clip(0)), rtol=rtol)
            # Published from n + 2 L samples on (the bias counted), unless the variance is negative.
            published = k + 1 >= p + 1 + 2 * options.n_lags and np.diag(expected).min() >= 0
            assert bank.ready[j] == published
            assert np.isnan(bank.theta_all()[j]).all() != published


@pytest.mark.parametrize("trim", [1, 25])
def test_the_recursive_transforms_equal_the_batch_transform_of_the_record(t2_run, trim):
    x, z = t2_run
    options = FrequencyOptions(rate_hz=RATE, trim_samples=trim)
    bank = FrequencyBank(SIZES, options)
    feed(bank, x, z)
    Z, X = bank.transforms()
    f = options.frequencies()
    for j, p in enumerate(SIZES):
        Zb = finite_fourier_transform(z[:, j] - z[:trim, j].mean(), f, RATE)
        Xb = finite_fourier_transform(x[:, j, :p] - x[:trim, j, :p].mean(axis=0), f, RATE)
        np.testing.assert_allclose(Z[j], Zb, rtol=0, atol=1e-9 * np.abs(Zb).max())
        np.testing.assert_allclose(X[j, :, :p], Xb, rtol=0, atol=1e-9 * np.abs(Xb).max())
        assert not X[j, :, p:].any()


def test_an_exactly_fitting_model_gives_its_parameters_but_publishes_nothing():
    t = np.arange(400) / RATE
    x = np.column_stack([np.sin(2 * np.pi * 0.3 * t), np.sin(2 * np.pi * 0.9 * t + 1) * t])
    theta = np.array([-3.9, 0.215])
    z = 0.7 + x @ theta  # a bias too: it drops out with the first sample
    bank = FrequencyBank((2,), FrequencyOptions(rate_hz=RATE))
    feed(bank, x[:, None, :], z[:, None])
    np.testing.assert_allclose(bank.theta(0), theta, rtol=1e-10)
    assert np.all(bank.standard_errors(0, "conventional") < 1e-9 * np.abs(theta))
    assert bank.solved[0] and not bank.ready[0] and bank.withheld[0]
    assert np.isnan(bank.theta_all()).all() and np.isnan(bank.standard_errors_all()).all()


def test_evaluating_every_m_samples_gives_the_every_sample_results_of_the_last_multiple(t2_run):
    x, z = t2_run
    every = FrequencyBank(SIZES, FrequencyOptions(rate_hz=RATE, every=7))
    each = FrequencyBank(SIZES, FrequencyOptions(rate_hz=RATE))
    last = None
    for k in range(200):
        every.update(x[k], z[k])
        each.update(x[k], z[k])
        if (k + 1) % 7 == 0:
            last = (each.theta_all(), each.standard_errors_all(), each.standard_errors_all("conventional"))
        if last is not None:
            assert every.evaluated_at == 7 * ((k + 1) // 7)
            for got, want in zip(
                (every.theta_all(), every.standard_errors_all(), every.standard_errors_all("conventional")),
                last,
                strict=True,
            ):
                np.testing.assert_array_equal(got, want)


def test_a_refused_sample_leaves_the_state_as_it_was(t2_run):
    x, z = t2_run
    plain = FrequencyBank(SIZES, FrequencyOptions(rate_hz=RATE))
    hit = FrequencyBank(SIZES, FrequencyOptions(rate_hz=RATE))
    feed(plain, x, z, 0, 150)
    feed(hit, x, z, 0, 100)
    bad = x[100].copy()
    bad[1, 2] = np.nan
    with pytest.raises(NonFiniteInput, match=r"models \[1\]"):
        hit.update(bad, z[100])
    with pytest.raises(NonFiniteInput):
        hit.update(x[100], [1e150, 0.0])
    feed(hit, x, z, 100, 150)
    assert hit.n_samples == plain.n_samples == 150
    np.testing.assert_array_equal(hit.theta_all(), plain.theta_all())
    np.testing.assert_array_equal(hit.standard_errors_all(), plain.standard_errors_all())


def test_after_a_reset_the_bank_is_a_fresh_one(t2_run):
    x, z = t2_run
    used = FrequencyBank(SIZES, FrequencyOptions(rate_hz=RATE))
    feed(used, x, z, 0, 120)
    used.theta_all()
    used.reset()
    assert not used.ready.any() and used.n_samples == 0
    fresh = FrequencyBank(SIZES, FrequencyOptions(rate_hz=RATE))
    feed(used, x, z, 200, 400)
    feed(fresh, x, z, 200, 400)
    np.testing.assert_array_equal(used.theta_all(), fresh.theta_all())
    np.testing.assert_array_equal(used.standard_errors_all(), fresh.standard_errors_all())


def test_a_model_that_is_not_ready_gives_nan_and_refuses_its_estimate(t2_run):
    x, z = t2_run
    bank = FrequencyBank(SIZES, FrequencyOptions(rate_hz=RATE))
    bank.update(x[0], z[0])  # one sample: every transform is zero
    assert not bank.ready.any()
    assert np.isnan(bank.theta_all()).all() and np.isnan(bank.standard_errors_all()).all()
    with pytest.raises(EstimatorNotReady):
        bank.theta(0)
    feed(bank, x, z, 1, 60)
    assert bank.solved.all() and not bank.ready.any()  # solved, not yet published
    feed(bank, x, z, 60, 104)
    assert bank.ready.all()
    assert np.isnan(bank.theta_all()[0, 2])  # C_Z's padding
    with pytest.raises(ValueError, match="kind"):
        bank.standard_errors_all("batch")


def test_a_model_is_solved_exactly_when_its_scaled_normal_matrix_is_conditioned_below_the_limit(t2_run):
    """The eigenvalues of the column-scaled ``Re(X^H X)`` of the transforms decide
    (``lambda_min init_condition > lambda_max``), whichever way the bank finds it: a bound from
    the inverse's trace settles most limits, not those between the condition number and ``p``
    times ``tr(S^-1)``, nor a matrix that rounding leaves indefinite (3 samples)."""
    x, z = t2_run
    for n in (3, 30, 200):
        bank = FrequencyBank(SIZES, FrequencyOptions(rate_hz=RATE))
        feed(bank, x, z, 0, n)
        _Z, X = bank.transforms()
        extremes, limits = [], []
        for j, p in enumerate(SIZES):
            A = (X[j, :, :p].conj().T @ X[j, :, :p]).real
            s = 1.0 / np.sqrt(np.diag(A))
            S = A * np.outer(s, s)
            eig = np.linalg.eigvalsh(S)
            extremes.append((eig[0], eig[-1]))
            if eig[0] > 0:  # the condition number and the bound (padding: unit diagonal)
                bound = max(SIZES) * (np.trace(np.linalg.inv(S)) + max(SIZES) - p)
                assert eig[-1] / eig[0] <= bound
                limits += [eig[-1] / eig[0], bound]
        limits.sort()
        for limit in [0.5 * limits[0], *np.sqrt(np.multiply(limits[:-1], limits[1:])), 2.0 * limits[-1]]:
            bank = FrequencyBank(SIZES, FrequencyOptions(rate_hz=RATE, init_condition=limit))
            feed(bank, x, z, 0, n)
            expected = [low * limit > high for low, high in extremes]
            np.testing.assert_array_equal(bank.solved, expected, err_msg=f"{n} samples, limit {limit:g}")


@pytest.mark.parametrize("phi", [0.0, 0.5, -0.5])
def test_the_corrected_variance_is_unbiased_for_the_true_noise_on_average(phi):
    # 400 models with the same regressors (one of them a switched-on cosine: energy outside the
    # grid) and AR(1) equation error of known autocovariance R(i) = 0.01 phi^i / (1 - phi^2).
    # The mean corrected variance (R estimated from each model's residuals) against
    # the variance F7 gives with the true R: within 7 % (about 5 of its standard errors). Without
    # the degrees-of-freedom correction (F10) the switched-on regressor's is 9-30 % low.
    rng = np.random.default_rng(5)
    N, runs = 200, 400
    t = np.arange(N) / RATE
    x = np.column_stack([np.sin(2 * np.pi * 0.4 * t + 1) + 0.5 * np.sin(2 * np.pi * 1.1 * t),
                         np.cos(2 * np.pi * 0.7 * t) * (t > 0.5)])
    e = rng.standard_normal((N + 200, runs))
    for k in range(1, N + 200):
        e[k] += phi * e[k - 1]
    e = 0.1 * e[200:]
    mean_variance = {}
    for correct in (True, False):
        bank = FrequencyBank((2,) * runs, FrequencyOptions(rate_hz=RATE, f_max=2.0, dof_correction=correct, every=N))
        for k in range(N):
            bank.update(np.broadcast_to(x[k], (runs, 2)), x[k] @ [1.5, -0.7] + 0.3 + e[k])
        # The raw variances of F7 (a negative one too: a model withheld is still part of the average).
        mean_variance[correct] = np.mean([np.diag(bank.covariance(j)) for j in range(runs)], axis=0)
    X = bank.transforms()[1][:1]
    A_inv = np.linalg.inv((np.swapaxes(X.conj(), 1, 2) @ X).real[0])
    R = 0.01 * phi ** np.arange(51) / (1 - phi**2)
    geometry = PairGeometry(2 * np.pi * bank.frequencies / RATE).at(N)
    truth = np.diag(A_inv @ (middle(R[None], X, geometry)[0] / RATE**2) @ A_inv)
    np.testing.assert_allclose(mean_variance[True], truth, rtol=0.07)
    assert mean_variance[False][1] < 0.92 * truth[1]
