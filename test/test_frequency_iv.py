"""FrequencyBank with instrumental variables (docs/frequency.md, F11-F12): with the regressors
as instruments it is the least-squares bank; at every evaluated sample it equals the literal
batch instrumental-variable fit; an invertible mix of the instruments changes nothing; and on
regressors measured with noise it removes the attenuation least squares has."""

from __future__ import annotations

import numpy as np
import pytest

from rls_uncertainty.frequency import FrequencyBank, FrequencyOptions, frequency_reference
from rls_uncertainty.simulation.montecarlo import level_inputs

RATE = 50.0
SIZES = (2, 3)  # the T-2's C_Z (alpha, delta_e) and C_m (alpha, q_hat, delta_e)


@pytest.fixture(scope="module")
def t2_run():
    """One T-2 run of Table 3's setting at 20 % band-limited noise, regressors without the bias,
    and instruments: the regressors smoothed over 9 samples and delayed by 2 (any signal
    correlated with the regressors serves for the algebra)."""
    _t, _red, _sizes, X, Z = level_inputs(0.20, 1, seed=11)
    x = np.zeros((X.shape[0], 2, 3))
    x[:, 0, :2] = X[:, 0, 1:3]
    x[:, 1, :3] = X[:, 1, 1:4]
    kernel = np.ones(9) / 9
    w = np.zeros_like(x)
    for j, p in enumerate(SIZES):
        for a in range(p):
            w[2:, j, a] = np.convolve(x[:, j, a], kernel, mode="same")[:-2]
    return x, Z, w


def results(bank: FrequencyBank) -> list[np.ndarray]:
    return [bank.theta_all(), bank.standard_errors_all(), bank.standard_errors_all("conventional"),
            np.array([bank.autocorrelation(j) for j in range(len(bank.sizes))])]


@pytest.mark.parametrize("trim", [1, 25])
def test_with_the_regressors_as_instruments_it_is_the_least_squares_bank(t2_run, trim):
    x, z, _w = t2_run
    options = FrequencyOptions(rate_hz=RATE, f_max=2.2, trim_samples=trim)
    ls, iv = FrequencyBank(SIZES, options), FrequencyBank(SIZES, options, instruments=True)
    compared = 0
    for k in range(x.shape[0]):
        ls.update(x[k], z[k])
        iv.update(x[k], z[k], x[k])
        if k % 37 == 36 or k + 1 == x.shape[0]:
            assert (ls.solved == iv.solved).all() and (ls.ready == iv.ready).all()
            if not ls.ready.all():
                continue
            compared += 1
            for a, b in zip(results(ls), results(iv), strict=True):
                np.testing.assert_allclose(b, a, rtol=1e-12, atol=1e-12 * np.nanmax(np.abs(a)))
    assert compared > 5


@pytest.mark.parametrize(("dof_correction", "trim"), [(True, 1), (False, 1), (True, 25)])
def test_the_bank_equals_the_batch_instrumental_variable_fit(t2_run, dof_correction, trim):
    x, z, w = t2_run
    options = FrequencyOptions(rate_hz=RATE, f_max=2.2, dof_correction=dof_correction, trim_samples=trim)
    bank = FrequencyBank(SIZES, options, instruments=True)
    checks = {26, 52, 120, 173, 300, x.shape[0]}
    for k in range(x.shape[0]):
        bank.update(x[k], z[k], w[k])
        if k + 1 not in checks:
            continue
        assert bank.solved.all()
        for j, p in enumerate(SIZES):
            ref = frequency_reference(x[: k + 1, j, :p], z[: k + 1, j], options, w[: k + 1, j, :p])
            ls = frequency_reference(x[: k + 1, j, :p], z[: k + 1, j], options)
            assert np.abs(ref.theta - ls.theta).max() > 1e-3 * np.abs(ls.theta).max()  # not least squares
            np.testing.assert_allclose(bank.theta(j), ref.theta, rtol=1e-10)
            for kind, expected in (("conventional", ref.cov_conventional), ("corrected", ref.cov_corrected)):
                np.testing.assert_allclose(bank.covariance(j, kind), expected, rtol=1e-10,
                                           atol=1e-10 * np.abs(expected).max())
            np.testing.assert_allclose(bank.autocorrelation(j), ref.R, rtol=1e-10, atol=1e-12 * abs(ref.R[0]))


def test_an_invertible_mix_of_the_instruments_changes_nothing(t2_run):
    x, z, w = t2_run
    rng = np.random.default_rng(3)
    mix = [rng.standard_normal((p, p)) + 2 * np.eye(p) for p in SIZES]
    mixed = np.zeros_like(w)
    for j, p in enumerate(SIZES):
        mixed[:, j, :p] = w[:, j, :p] @ mix[j]
    options = FrequencyOptions(rate_hz=RATE, f_max=2.2, trim_samples=25)
    banks = FrequencyBank(SIZES, options, instruments=True), FrequencyBank(SIZES, options, instruments=True)
    for k in range(x.shape[0]):
        banks[0].update(x[k], z[k], w[k])
        banks[1].update(x[k], z[k], mixed[k])
    assert banks[0].ready.all()
    for j in range(len(SIZES)):
        for kind in ("corrected", "conventional"):
            expected = banks[0].covariance(j, kind)
            np.testing.assert_allclose(banks[1].covariance(j, kind), expected, rtol=1e-8,
                                       atol=1e-10 * np.abs(expected).max())
    for a, b in zip(results(banks[0]), results(banks[1]), strict=True):
        np.testing.assert_allclose(b, a, rtol=1e-8)


def test_regressors_measured_with_noise_attenuate_least_squares_but_not_instrumental_variables():
    # 200 runs (one model each): z = 2 a - 1 b + e, a a multisine input, b its first-order lag,
    # both measured with in-band noise (a 1.2 Hz low-passed white noise, 40 % of the signals'
    # size). Instruments: the input and the input delayed by 0.2 s, which carry no noise. The
    # mean estimate of least squares falls short of the truth by many of its standard errors
    # (scatter / sqrt(runs)); that of instrumental variables is within 4 of its own.
    rng = np.random.default_rng(7)
    N, runs, truth = 1000, 200, np.array([2.0, -1.0])
    t = np.arange(N) / RATE
    u = sum(np.sin(2 * np.pi * f * t + ph) for f, ph in ((0.3, 0.0), (0.55, 1.0), (0.9, 2.0), (1.3, 0.5)))
    b = np.zeros(N)
    for k in range(1, N):
        b[k] = 0.9 * b[k - 1] + 0.1 * u[k - 1]
    clean = np.column_stack([u, b * 4.0])
    delayed = np.concatenate([np.zeros(10), u[:-10]])
    white = rng.standard_normal((N, runs, 2))
    noise = np.zeros_like(white)
    alpha = 1 - np.exp(-2 * np.pi * 1.2 / RATE)
    for k in range(1, N):
        noise[k] = noise[k - 1] + alpha * (white[k] - noise[k - 1])
    noise *= 0.4 * clean.std(axis=0) / noise.std(axis=(0, 1))
    measured = clean[:, None, :] + noise
    z = clean @ truth + 0.05 * rng.standard_normal((runs, N))
    options = FrequencyOptions(rate_hz=RATE, f_min=0.2, f_max=1.6, every=N)
    ls, iv = FrequencyBank((2,) * runs, options), FrequencyBank((2,) * runs, options, instruments=True)
    instruments = np.broadcast_to(np.column_stack([u, delayed]), (runs, N, 2))
    for k in range(N):
        ls.update(measured[k], z[:, k])
        iv.update(measured[k], z[:, k], instruments[:, k])
    assert ls.solved.all() and iv.solved.all()
    for bank, biased in ((ls, True), (iv, False)):
        theta = np.array([bank.theta(j) for j in range(runs)])
        error = theta.mean(axis=0) - truth
        standard_error = theta.std(axis=0, ddof=1) / np.sqrt(runs)
        if biased:
            assert (np.abs(error) > 10 * standard_error).any()
            assert abs(error[0]) > 0.05 * abs(truth[0])
        else:
            assert (np.abs(error) < 4 * standard_error).all()
