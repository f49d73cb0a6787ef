"""The bank's instrumental-variables algorithm against the batch formulas and closed forms.

The recursive estimate and both covariances equal :func:`batch_iv` with the instruments and
the bank's own residual history; with instruments equal to the regressors the algorithm is the
least-squares bank; a noiseless model is fitted exactly; in an errors-in-variables regression
least squares is attenuated by the closed-form factor and IV is not; an invertible mix of the
instruments changes nothing; the state round-trips.
"""

from __future__ import annotations

import numpy as np
import pytest

from rls_uncertainty.errors import ConfigError
from rls_uncertainty.estimator import EstimatorBank, EstimatorOptions
from rls_uncertainty.estimator.reference import batch_iv

SIZES = (3, 4, 2)


def _filtered(rng: np.random.Generator, shape: tuple[int, ...], pole: float) -> np.ndarray:
    """Coloured noise: white noise through ``1 / (1 - pole q^-1)`` along the first axis."""
    e = rng.standard_normal(shape)
    out = np.zeros(shape)
    for k in range(shape[0]):
        out[k] = e[k] + (pole * out[k - 1] if k else 0.0)
    return out


def _data(N: int, seed: int = 7) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Regressors measured with coloured noise, instruments from the clean input, outputs
    with a coloured error correlated with the regressors' noise: ``(X, Zeta, z)`` padded to
    ``(N, M, n_max)``."""
    rng = np.random.default_rng(seed)
    t = np.arange(N) / 50.0
    u = np.sin(2 * np.pi * 0.7 * t) + 0.5 * np.sin(2 * np.pi * 1.3 * t + 1.0) + 0.3 * np.sin(2 * np.pi * 2.9 * t)
    M, n = len(SIZES), max(SIZES)
    X, Zeta, z = np.zeros((N, M, n)), np.zeros((N, M, n)), np.zeros((N, M))
    for j, s in enumerate(SIZES):
        clean = np.column_stack([np.ones(N), u, np.roll(u, 3 + j), np.cos(2 * np.pi * 0.4 * t)])[:, :s]
        noise = 0.2 * _filtered(rng, (N, s), 0.8)
        noise[:, 0] = 0.0
        X[:, j, :s] = clean + noise
        Zeta[:, j, :s] = clean + 0.05 * np.roll(clean, 1, axis=0)
        eps = 0.1 * _filtered(rng, (N,), 0.7) - 0.5 * noise[:, -1]
        z[:, j] = X[:, j, :s] @ np.linspace(-1.0, 1.5, s) + eps
    return X, Zeta, z


def _run(options: EstimatorOptions, X: np.ndarray, Zeta: np.ndarray, z: np.ndarray) -> tuple[EstimatorBank, list]:
    """The bank after every sample, and each model's residual history: those of the batch
    estimate at its initialization ``k0`` (Eq. 7, samples ``1..k0``), then the newest residual
    of each later sample."""
    bank = EstimatorBank(SIZES, options)
    history: list = [None] * len(SIZES)
    for k in range(len(z)):
        bank.update(X[k], z[k], Zeta[k])
        for j, s in enumerate(SIZES):
            if bank.initialized[j]:
                if history[j] is None:
                    history[j] = list(z[: k + 1, j] - X[: k + 1, j, :s] @ bank.theta(j))
                    held = bank.residuals(j)  # the bank's, of the samples it holds
                    assert np.allclose(held, history[j][-held.size:], rtol=0, atol=1e-9)
                else:
                    history[j].append(bank.residuals(j)[-1])
    return bank, history


def _relative(a: np.ndarray, b: np.ndarray) -> float:
    """Largest difference relative to the largest entry (padding, NaN in both, ignored)."""
    assert (np.isnan(a) == np.isnan(b)).all()
    return float(np.nanmax(np.abs(a - b)) / np.nanmax(np.abs(b)))


@pytest.mark.parametrize("residual", ["standardized", "a_posteriori", "a_priori"])
@pytest.mark.parametrize(("burn_in", "small_sample", "lags"), [(0, 0.0, 20), (30, 0.5, 20), (0, 1.0, "all")])
def test_recursive_iv_equals_batch_iv(residual, burn_in, small_sample, lags):
    N = 260
    X, Zeta, z = _data(N)
    options = EstimatorOptions(lags=lags, algorithm="iv", residual=residual, residual_burn_in=burn_in,
                               small_sample=small_sample, init_condition=1e4)
    bank, history = _run(options, X, Zeta, z)
    assert bank.initialized.all() and (bank.ready_at >= options.iv_init_samples).all()
    for j, s in enumerate(SIZES):
        v = np.array(history[j])
        assert v.size == N
        first = int(bank.ready_at[j]) + burn_in if burn_in else 0
        theta, conv, corr = batch_iv(X[:, j, :s], Zeta[:, j, :s], z[:, j], lags, residuals=v, first=first,
                                     small_sample=small_sample)
        assert _relative(bank.theta(j), theta) < 1e-10
        assert _relative(bank.covariance(j, "corrected", repair=False), corr) < 1e-10
        assert _relative(bank.covariance(j, "conventional"), conv) < 1e-10


@pytest.mark.parametrize("residual", ["standardized", "a_posteriori", "a_priori"])
@pytest.mark.parametrize("burn_in", [0, 25])
def test_instruments_equal_to_regressors_give_the_least_squares_bank(residual, burn_in):
    X, _, z = _data(400, seed=11)
    common = dict(lags=30, residual=residual, residual_burn_in=burn_in)
    rls = EstimatorBank(SIZES, EstimatorOptions(**common))
    iv = EstimatorBank(SIZES, EstimatorOptions(**common, algorithm="iv", small_sample=0.0, iv_init_samples=0))
    for k in range(len(z)):
        rls.update(X[k], z[k])
        iv.update(X[k], z[k], X[k])
    assert (rls.ready_at == iv.ready_at).all() and rls.ready.all()
    assert _relative(iv.theta_all(), rls.theta_all()) < 1e-10
    for j in range(len(SIZES)):
        for kind in ("corrected", "conventional"):
            assert _relative(iv.covariance(j, kind), rls.covariance(j, kind)) < 1e-10


def test_a_noiseless_model_is_fitted_exactly():
    X, Zeta, _ = _data(200, seed=3)
    truth = np.array([[0.4, -2.0, 1.5, 0.0], [0.3, -1.0, 0.7, 2.5], [-0.2, 3.0, 0.0, 0.0]])
    z = np.einsum("kjc,jc->kj", X, truth)
    bank = EstimatorBank(SIZES, EstimatorOptions(lags=10, algorithm="iv"))
    for k in range(len(z)):
        bank.update(X[k], z[k], Zeta[k])
        if k > 100 and bank.ready.all():
            for j, s in enumerate(SIZES):
                np.testing.assert_allclose(bank.theta(j), truth[j, :s], rtol=0, atol=1e-12)


def test_errors_in_variables_least_squares_attenuated_iv_not():
    """One regressor ``x = u + w`` (``u`` the instrument) measured with noise ``n``: the mean
    least-squares slope over the runs is ``a sigma_x^2 / (sigma_x^2 + sigma_n^2)``, the mean IV
    slope ``a``, each within four standard errors of the mean over the runs (plus the
    least-squares ratio's bias of order ``1/N``)."""
    runs, N, a = 300, 400, 2.0
    var_u, var_w, var_n = 1.0, 0.5, 1.0
    rng = np.random.default_rng(2016)
    u = rng.standard_normal((N, runs)) * np.sqrt(var_u)
    x = u + rng.standard_normal((N, runs)) * np.sqrt(var_w)
    measured = x + rng.standard_normal((N, runs)) * np.sqrt(var_n)
    z = a * x + 0.3 * rng.standard_normal((N, runs))
    rls = EstimatorBank([1] * runs, EstimatorOptions(lags=0))
    iv = EstimatorBank([1] * runs, EstimatorOptions(lags=0, algorithm="iv"))
    for k in range(N):
        rls.update(measured[k][:, None], z[k])
        iv.update(measured[k][:, None], z[k], u[k][:, None])
    slope_ls, slope_iv = rls.theta_all()[:, 0], iv.theta_all()[:, 0]
    var_x = var_u + var_w
    attenuated = a * var_x / (var_x + var_n)
    tol_ls = 4.0 * slope_ls.std(ddof=1) / np.sqrt(runs) + 2.0 * abs(a) / N
    tol_iv = 4.0 * slope_iv.std(ddof=1) / np.sqrt(runs) + 2.0 * abs(a) / N
    assert abs(slope_ls.mean() - attenuated) < tol_ls
    assert abs(slope_iv.mean() - a) < tol_iv
    assert abs(slope_ls.mean() - a) > 10 * tol_ls  # the attenuation is not within the noise


def test_an_invertible_mix_of_the_instruments_changes_nothing():
    X, Zeta, z = _data(300, seed=5)
    rng = np.random.default_rng(1)
    mixed = Zeta.copy()
    for j, s in enumerate(SIZES):
        A = np.eye(s) + 0.3 * rng.standard_normal((s, s))
        mixed[:, j, :s] = Zeta[:, j, :s] @ A
    options = EstimatorOptions(lags=20, algorithm="iv", residual_burn_in=0)
    one, two = EstimatorBank(SIZES, options), EstimatorBank(SIZES, options)
    for k in range(len(z)):
        one.update(X[k], z[k], Zeta[k])
        two.update(X[k], z[k], mixed[k])
    assert (one.ready_at == two.ready_at).all() and one.ready.all()
    assert _relative(two.theta_all(), one.theta_all()) < 1e-10
    for j in range(len(SIZES)):
        for kind in ("corrected", "conventional"):
            assert _relative(two.covariance(j, kind), one.covariance(j, kind)) < 1e-9


@pytest.mark.parametrize("at", [2, 150])
def test_the_state_round_trips_an_iv_bank(at):
    """A state taken while the models wait (``at=2``) or after, restored and continued, gives
    the same numbers bit for bit."""
    X, Zeta, z = _data(260, seed=9)
    options = EstimatorOptions(lags=20, algorithm="iv")
    bank = EstimatorBank(SIZES, options)
    for k in range(at):
        bank.update(X[k], z[k], Zeta[k])
    restored = EstimatorBank.from_state(bank.state())
    for k in range(at, len(z)):
        bank.update(X[k], z[k], Zeta[k])
        restored.update(X[k], z[k], Zeta[k])
    assert bank.ready.all()
    np.testing.assert_array_equal(restored.theta_all(), bank.theta_all())
    np.testing.assert_array_equal(restored.covariance_all(), bank.covariance_all())


def test_instruments_are_required_with_iv_and_refused_without():
    iv = EstimatorBank(SIZES, EstimatorOptions(algorithm="iv"))
    with pytest.raises(ValueError, match="needs the instruments"):
        iv.update(np.ones((3, 4)), np.ones(3))
    with pytest.raises(ValueError, match="instruments"):
        iv.update(np.ones((3, 4)), np.ones(3), [np.ones(3), np.ones(4)])
    rls = EstimatorBank(SIZES)
    with pytest.raises(ValueError, match="only with estimator algorithm 'iv'"):
        rls.update(np.ones((3, 4)), np.ones(3), np.ones((3, 4)))
    assert iv.k == 0 and rls.k == 0


def test_a_non_finite_instrument_is_refused_and_changes_nothing():
    from rls_uncertainty.errors import NonFiniteInput

    X, Zeta, z = _data(60, seed=4)
    bank = EstimatorBank(SIZES, EstimatorOptions(lags=5, algorithm="iv"))
    for k in range(50):
        bank.update(X[k], z[k], Zeta[k])
    before = bank.state()
    bad = Zeta[50].copy()
    bad[1, 2] = np.nan
    with pytest.raises(NonFiniteInput, match="instrument"):
        bank.update(X[50], z[50], bad)
    after = bank.state()
    assert after["counters"] == before["counters"]
    for name, value in before["arrays"].items():
        np.testing.assert_array_equal(after["arrays"][name], value)


@pytest.mark.parametrize("options", [dict(forgetting=0.99), dict(p0=100.0), dict(small_sample=-1.0)])
def test_iv_options_refused(options):
    with pytest.raises(ConfigError):
        EstimatorOptions(algorithm="iv", **options)


@pytest.mark.parametrize("at", [2, 150])
def test_an_iv_bank_round_trips_through_the_state_file(tmp_path, at):
    """Saved to a state file and read back with its checks (layout, values, the expected
    configuration), an IV bank continues bit for bit."""
    from rls_uncertainty.state_file import EstimatorState, load_state, save_state

    X, Zeta, z = _data(200, seed=8)
    options = EstimatorOptions(lags=20, algorithm="iv")
    bank = EstimatorBank(SIZES, options)
    for k in range(at):
        bank.update(X[k], z[k], Zeta[k])
    path = tmp_path / "state.npz"
    fingerprint = {"estimator": options.resolved().as_dict()}
    save_state(path, EstimatorState(bank, at, z[:at].sum(axis=0), (z[:at] ** 2).sum(axis=0)), fingerprint)
    restored = load_state(path, fingerprint, expect=(SIZES, options)).bank
    for k in range(at, len(z)):
        bank.update(X[k], z[k], Zeta[k])
        restored.update(X[k], z[k], Zeta[k])
    assert bank.ready.all()
    np.testing.assert_array_equal(restored.theta_all(), bank.theta_all())
    np.testing.assert_array_equal(restored.covariance_all(), bank.covariance_all())


def test_a_bank_of_one_takes_instruments():
    from rls_uncertainty.estimator import RecursiveEstimator

    X, Zeta, z = _data(120, seed=6)
    options = EstimatorOptions(lags=10, algorithm="iv")
    one, bank = RecursiveEstimator(4, options), EstimatorBank(SIZES, options)
    for k in range(len(z)):
        one.update(X[k, 1], z[k, 1], Zeta[k, 1])
        bank.update(X[k], z[k], Zeta[k])
    np.testing.assert_array_equal(one.theta, bank.theta(1))
    np.testing.assert_array_equal(one.standard_errors(), bank.standard_errors(1))


def test_automatic_lags_run_with_iv():
    """With ``lags="auto"`` each model's lags are chosen from its residuals, as for least
    squares; the covariance stays the batch sandwich with the chosen lags."""
    N = 260
    X, Zeta, z = _data(N)
    options = EstimatorOptions(lags="auto", algorithm="iv", small_sample=0.0, init_condition=1e4)
    bank, history = _run(options, X, Zeta, z)
    for j, s in enumerate(SIZES):
        L = int(bank.lags_used[j])
        first = int(bank.ready_at[j]) + options.burn_in
        _, _, corr = batch_iv(X[:, j, :s], Zeta[:, j, :s], z[:, j], L, residuals=np.array(history[j]), first=first)
        assert _relative(bank.covariance(j, repair=False), corr) < 1e-10
