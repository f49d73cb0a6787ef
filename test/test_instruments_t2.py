"""The instruments on the simulated T-2 maneuver (Section IV.A): they follow the part of the
regressors the injected elevator drives, and are strong."""

import numpy as np
import pytest

from rls_uncertainty.instruments import WEAK_BELOW, InstrumentStrength, ShortPeriodAuxiliary
from rls_uncertainty.settings import load_aircraft
from rls_uncertainty.simulation.t2 import (
    SIGNALS,
    T2_MODELS,
    T2_TRUE,
    reduce_short_period,
    simulate_maneuver,
    simulate_short_period,
)
from rls_uncertainty.simulation.turbulence import LOW_ALTITUDE_SIGMA_W, DrydenVertical, scale_length

T2 = load_aircraft("t2")


def model_rows(out):
    """The two models' regressors ``(N, 2, 4)`` (C_Z padded) and outputs ``(N, 2)``."""
    (Xc, zc), (Xm, zm) = out["CZ"], out["Cm"]
    X = np.zeros((zc.size, 2, 4))
    X[:, 0, :3], X[:, 1] = Xc, Xm
    return X, np.column_stack([zc, zm])


def corr(a, b):
    return np.corrcoef(a, b)[0, 1]


def test_with_the_true_model_the_instruments_are_the_simulated_response():
    """The auxiliary model with Table 3's values, replayed over the elevator input, against the
    simulation's response (integrated on its 1 kHz grid): the zero-order hold at 50 Hz is the
    only difference."""
    rec = simulate_short_period()
    aux = ShortPeriodAuxiliary(T2_MODELS, T2, rec.config.rate)
    theta = np.array([[0.0, T2_TRUE["CZ_alpha"], T2_TRUE["CZ_delta_e"], 0.0],
                      [0.0, T2_TRUE["Cm_alpha"], T2_TRUE["Cm_q"], T2_TRUE["Cm_delta_e"]]])
    assert aux.set_model(theta, rec.qbar, rec.V)
    u = rec.delta_e - rec.config.delta_e_trim
    zeta = aux.replay(u, np.full(u.size, rec.V))
    alpha = rec.alpha - rec.config.alpha_trim
    q_hat = rec.q * T2.cbar / (2 * rec.V)
    assert corr(zeta[:, 1, 1], alpha) > 0.99 and corr(zeta[:, 1, 2], q_hat) > 0.99
    np.testing.assert_allclose(zeta[:, 1, 1].std(), alpha.std(), rtol=0.05)
    np.testing.assert_allclose(zeta[:, 1, 2].std(), q_hat.std(), rtol=0.05)
    np.testing.assert_array_equal(zeta[:, 0, [0, 1, 2]], zeta[:, 1, [0, 1, 3]])


@pytest.mark.parametrize(("gust", "rho_floor"), [(None, 0.5), ("severe", WEAK_BELOW)])
def test_instruments_on_a_noisy_maneuver_follow_the_true_regressors(gust, rho_floor):
    """20 % band-limited noise on all four signals (and a severe Dryden gust on alpha, without
    its pitch gust: with it the bare least squares that builds the first auxiliary model is
    biased in C_m_alpha, and the alpha instrument follows the true alpha less, about 0.6;
    docs/studies/instrumental_variables): every sample is
    handed over once, in order; the alpha and q_hat instruments correlate with the regressors
    of the noise-free calm-air maneuver, the elevator instrument is the injected input, and the
    instruments are strong: the smallest canonical correlation is above the weak threshold,
    in calm air far above it (gusts lower it: the regressors move with them, the instruments
    do not)."""
    dryden = None if gust is None else DrydenVertical(LOW_ALTITUDE_SIGMA_W[gust], scale_length(1370 * 0.3048))
    rec = simulate_maneuver(0.2, seed=3, gust=dryden, band_limited_on=SIGNALS, pitch_gust=False)
    t, out = reduce_short_period(rec)
    X, z = model_rows(out)
    calm = simulate_short_period(rec.config)
    _, calm_out = reduce_short_period(calm)
    X_true, _ = model_rows(calm_out)
    u = calm.delta_e[np.searchsorted(rec.t, t)] - rec.config.delta_e_trim  # the injected input
    aux = ShortPeriodAuxiliary(T2_MODELS, T2, rec.config.rate)
    strength = InstrumentStrength((3, 4), bias=(0, 0))
    delivered = []
    for k in range(t.size):
        for sample in aux.update(X[k], z[k], u[k], rec.qbar, rec.V):
            delivered.append(sample)
            strength.update(sample.X, sample.instruments)
    assert aux.has_model and aux.dropped == 0 and len(delivered) == t.size
    np.testing.assert_array_equal(np.stack([s.X for s in delivered]), X)
    zeta = np.stack([s.instruments for s in delivered])
    assert corr(zeta[:, 1, 1], X_true[:, 1, 1]) > 0.9
    assert corr(zeta[:, 1, 2], X_true[:, 1, 2]) > 0.9
    np.testing.assert_array_equal(zeta[:, 1, 3], u)
    np.testing.assert_array_equal(zeta[:, 0, :3], zeta[:, 1, [0, 1, 3]])
    assert (strength.rho_min() > rho_floor).all() and not strength.weak().any()


def test_without_the_excitation_the_instruments_are_weak():
    """The maneuver flown but its excitation not received (``u`` = 0): the auxiliary model
    still forms from the bare RLS (the sensor noise excites it), but the instruments stay at
    rest, so every model's smallest canonical correlation is 0 and it is flagged weak."""
    rec = simulate_maneuver(0.2, seed=3, band_limited_on=SIGNALS)
    t, out = reduce_short_period(rec)
    X, z = model_rows(out)
    aux = ShortPeriodAuxiliary(T2_MODELS, T2, rec.config.rate)
    strength = InstrumentStrength((3, 4), bias=(0, 0))
    for k in range(t.size):
        for sample in aux.update(X[k], z[k], 0.0, rec.qbar, rec.V):
            strength.update(sample.X, sample.instruments)
    assert strength.k == t.size
    np.testing.assert_array_equal(strength.rho_min(), [0.0, 0.0])
    assert strength.weak().all()
