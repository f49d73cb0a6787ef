"""FrequencyBank's evaluation against the one it replaced, kept literally in frequency_before.py:
at every checked sample, estimates, both covariances and standard errors, the residual
autocovariance, the fit metrics and the flags agree to 1e-12 relative, for the T-2's two models,
six models of up to five regressors on 36 and 120 frequencies, instrumental variables, a trim
over many samples, no lags, a model without a usable regressor and an exactly fitting model."""

from __future__ import annotations

import numpy as np
import pytest
from frequency_before import evaluate_before

from rls_uncertainty.errors import EstimatorNotReady, NonFiniteInput
from rls_uncertainty.frequency import FrequencyBank, FrequencyOptions
from rls_uncertainty.simulation.montecarlo import level_inputs

RATE = 50.0
RTOL = 1e-12
# Before the publication rule (a record of a few lag windows or less) the frequency grid barely
# resolves the regressors: the estimates move with the last bits of Re(X^H X) (condition numbers
# up to 1e7) and the old formulas' own covariances carry rounding of up to 1e-7
# relative at 50 samples and 1e-5 at 10 (their asymmetry shows it); nothing is published from them.
RTOL_EARLY = 1e-4


def close(new: np.ndarray, old: np.ndarray, what: str, scale: float | None = None, rtol: float = RTOL) -> None:
    """Equal to ``rtol`` relative, element by element or against ``scale`` (the array's largest
    value unless given)."""
    if scale is None:
        scale = np.nanmax(np.abs(old)) if np.isfinite(old).any() else 0.0
    np.testing.assert_allclose(new, old, rtol=rtol, atol=rtol * scale, err_msg=what)


def check(bank: FrequencyBank) -> None:
    """Every output of ``bank`` now against :func:`evaluate_before` of its state."""
    old = evaluate_before(bank)
    for flag in ("solved", "ready", "withheld"):
        np.testing.assert_array_equal(getattr(bank, flag), old[flag], err_msg=flag)
    ready = old["ready"]
    for j, p in enumerate(bank.sizes):
        if not old["solved"][j]:
            with pytest.raises(EstimatorNotReady):
                bank.theta(j)
            continue
        rtol = RTOL if bank.n_samples >= bank.publish_at[j] else RTOL_EARLY
        close(bank.theta(j), old["theta"][j, :p], f"theta of model {j} at {bank.n_samples} samples", rtol=rtol)
        if old["exact"][j]:  # its residuals and corrected covariance are rounding
            close(bank.autocorrelation(j), old["R"][j], f"R of model {j}", scale=old["z_variance"][j])
            continue
        for kind in ("corrected", "conventional"):
            cov = old[kind][j, :p, :p]
            what = f"{kind} covariance of model {j} at {bank.n_samples} samples"
            close(bank.covariance(j, kind), cov, what, rtol=rtol)
            close(bank.standard_errors(j, kind), np.sqrt(np.diag(cov).clip(0.0)), f"SEs: {what}", rtol=rtol)
        close(bank.autocorrelation(j), old["R"][j], f"R of model {j}")
    expected = np.where(ready[:, None], old["theta"], np.nan)
    close(bank.theta_all(), expected, "published estimates")
    for kind in ("corrected", "conventional"):
        se = np.sqrt(np.diagonal(old[kind], axis1=1, axis2=2).clip(0.0))
        se = np.where(ready[:, None] & bank._real, se, np.nan)  # no exact fit is ready
        close(bank.standard_errors_all(kind), se, f"published {kind} SEs")
    r2, rho1 = bank.fit()
    R, var, fits = old["R"], old["z_variance"], ~old["exact"]  # an exact fit's R(1) / R(0) is rounding
    with np.errstate(divide="ignore", invalid="ignore"):
        close(r2, np.where(var > 0, 1.0 - R[:, 0] / var, np.nan), "R^2", scale=1.0)  # both on [-1, 1]
        if R.shape[1] > 1:
            close(rho1[fits], (R[:, 1] / R[:, 0])[fits], "rho_1", scale=1.0)


def run(bank: FrequencyBank, x: np.ndarray, z: np.ndarray, at: set[int], w: np.ndarray | None = None) -> int:
    """Feed the samples, checking after each count in ``at``; returns the checks made."""
    checks = 0
    for k in range(x.shape[0]):
        bank.update(x[k], z[k], None if w is None else w[k])
        if bank.n_samples in at:
            check(bank)
            checks += 1
    return checks


@pytest.fixture(scope="module")
def t2_run():
    """One T-2 run of Table 3's setting at 20 % band-limited noise (C_Z and C_m without the bias)
    and instruments: the regressors smoothed over 9 samples and delayed by 2."""
    _t, _red, _sizes, X, Z = level_inputs(0.20, 1, seed=11)
    x = np.zeros((X.shape[0], 2, 3))
    x[:, 0, :2] = X[:, 0, 1:3]
    x[:, 1, :3] = X[:, 1, 1:4]
    w = np.zeros_like(x)
    for j, p in enumerate((2, 3)):
        for a in range(p):
            w[2:, j, a] = np.convolve(x[:, j, a], np.ones(9) / 9, mode="same")[:-2]
    return x, Z, w


def six_models(n: int, seed: int = 3) -> tuple[tuple[int, ...], np.ndarray, np.ndarray]:
    """Six models of 2 to 5 regressors (multisines with a little noise), outputs with AR(1) noise
    of 1 % of the signal: nearly exact fits, where rounding shows most."""
    sizes = (2, 3, 2, 5, 3, 3)
    rng = np.random.default_rng(seed)
    t = np.arange(n) / RATE
    x = np.zeros((n, len(sizes), max(sizes)))
    for j, s in enumerate(sizes):
        for c in range(s):
            x[:, j, c] = np.sin(2 * np.pi * (0.2 + 0.17 * c + 0.05 * j) * t + c + j) + 0.02 * rng.standard_normal(n)
    noise = np.zeros((n, len(sizes)))
    e = rng.standard_normal((n, len(sizes)))
    for k in range(1, n):
        noise[k] = 0.9 * noise[k - 1] + e[k]
    z = np.einsum("kjc,jc->kj", x, rng.standard_normal((len(sizes), max(sizes)))) + 0.01 * noise + 0.3
    return sizes, x, z


CHECKED = {1, 2, 3, 10, 40, 51, 52, 90, 200, 377, 500, 596}  # the T-2 run has 596 samples


@pytest.mark.parametrize(("dof", "trim", "lags"), [(True, 1, 50), (False, 1, 50), (True, 25, 50), (True, 1, 0)])
def test_the_t2_models_evaluate_as_before(t2_run, dof, trim, lags):
    x, z, _w = t2_run
    opts = FrequencyOptions(rate_hz=RATE, f_min=0.2, f_max=2.2, trim_samples=trim, n_lags=lags, dof_correction=dof)
    assert run(FrequencyBank((2, 3), opts), x, z, CHECKED) == len(CHECKED)


@pytest.mark.parametrize("trim", [1, 25])
def test_instrumental_variables_evaluate_as_before(t2_run, trim):
    x, z, w = t2_run
    opts = FrequencyOptions(rate_hz=RATE, f_min=0.2, f_max=2.2, trim_samples=trim)
    assert run(FrequencyBank((2, 3), opts, instruments=True), x, z, CHECKED, w) == len(CHECKED)


@pytest.mark.parametrize(("frequencies", "step"), [(36, 0.04), (120, 0.02)])
def test_six_models_evaluate_as_before(frequencies, step):
    sizes, x, z = six_models(1000)
    opts = FrequencyOptions(rate_hz=RATE, f_min=0.1, f_max=0.1 + (frequencies - 1) * step, f_step=step)
    bank = FrequencyBank(sizes, opts)
    assert bank.frequencies.size == frequencies
    assert run(bank, x, z, CHECKED) == len(CHECKED)


def test_edge_models_evaluate_as_before(t2_run):
    """A model whose only regressor is zero (never solved, its time-domain fit left out), an
    exactly fitting one (solved, withheld), one that is fine; and a refused sample."""
    x, z, _w = t2_run
    n = 400
    X = np.zeros((n, 3, 3))
    Z = np.zeros((n, 3))
    X[:, 0, :2] = x[:n, 0, :2]
    X[:, 1, :2] = x[:n, 0, :2]
    Z[:, 0], Z[:, 1] = z[:n, 0], X[:, 1, :2] @ np.array([0.7, -1.3])
    X[:, 2, :3] = x[:n, 1, :3]
    Z[:, 2] = z[:n, 1]
    X[:, 0, 1] = 0.0  # model 0: a regressor that is always zero
    bank = FrequencyBank((2, 2, 3), FrequencyOptions(rate_hz=RATE, f_min=0.2, f_max=2.2))
    assert run(bank, X[:200], Z[:200], {1, 2, 60, 200}) == 4
    bad = X[200].copy()
    bad[2, 0] = np.nan
    with pytest.raises(NonFiniteInput):
        bank.update(bad, Z[200])
    check(bank)
    assert run(bank, X[200:], Z[200:], {260, 400}) == 2
    assert not bank.solved[0] and bank.withheld[1] and bank.ready[2]
