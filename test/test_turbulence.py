"""Dryden vertical gusts (MIL-F-8785C): closed forms, the exact discretisation, and sampled
sequences against the spectrum and variance they must have."""

import math

import numpy as np
import pytest
from scipy import integrate, signal

from rls_uncertainty.errors import ConfigError
from rls_uncertainty.simulation.turbulence import FT, KNOT, LOW_ALTITUDE_SIGMA_W, DrydenVertical, scale_length

V = 40.8432  # m/s, the T-2's 134 ft/s
GUST = DrydenVertical(sigma=1.3, scale_length=290.0)


def test_scale_length_is_the_height_below_1000_ft_and_1750_ft_from_2000_ft():
    assert scale_length(100.0) == 100.0
    assert scale_length(1000 * FT) == pytest.approx(1000 * FT)
    assert scale_length(2000 * FT) == pytest.approx(1750 * FT)
    assert scale_length(10_000.0) == pytest.approx(1750 * FT)
    assert scale_length(1500 * FT) == pytest.approx(1375 * FT)  # linear in between
    eps = 1e-6
    assert scale_length(1000 * FT + eps) == pytest.approx(scale_length(1000 * FT - eps), abs=1e-5)
    for bad in (0.0, -5.0, math.nan, math.inf):
        with pytest.raises(ConfigError, match="height above ground"):
            scale_length(bad)


def test_low_altitude_intensities_are_a_tenth_of_the_wind_at_20_ft():
    assert LOW_ALTITUDE_SIGMA_W["light"] == pytest.approx(0.1 * 15 * KNOT)
    assert LOW_ALTITUDE_SIGMA_W["moderate"] == pytest.approx(0.1 * 30 * 0.514444, rel=1e-5)
    assert LOW_ALTITUDE_SIGMA_W["severe"] == pytest.approx(0.1 * 45 * 0.514444, rel=1e-5)


def test_invalid_gust_parameters_name_the_parameter():
    with pytest.raises(ConfigError, match="sigma_w"):
        DrydenVertical(-0.1, 100.0)
    with pytest.raises(ConfigError, match="sigma_w"):
        DrydenVertical(math.nan, 100.0)
    with pytest.raises(ConfigError, match="scale length"):
        DrydenVertical(1.0, 0.0)
    with pytest.raises(ConfigError, match="airspeed"):
        GUST.transition(0.0, 0.01)
    with pytest.raises(ConfigError, match="dt"):
        GUST.transition(V, -0.01)


def test_spectrum_integrates_to_the_variance_and_is_the_transform_of_the_autocovariance():
    """The two closed forms against each other: int_0^inf S(f) df = sigma^2, and
    S(f) = 4 int_0^inf R(tau) cos(2 pi f tau) dtau (Wiener-Khinchin, one-sided)."""
    total, _ = integrate.quad(lambda f: float(GUST.psd(np.array(f), V)), 0, np.inf, limit=200)
    assert total == pytest.approx(GUST.sigma**2, rel=1e-8)

    def R(tau):
        return float(GUST.autocovariance(np.array(tau), V))

    assert 4 * integrate.quad(R, 0, np.inf)[0] == pytest.approx(float(GUST.psd(np.array(0.0), V)), rel=1e-6)
    for f in (0.01, 0.3, 2.0):
        transform = integrate.quad(R, 0, np.inf, weight="cos", wvar=2 * np.pi * f)[0]
        assert 4 * transform == pytest.approx(float(GUST.psd(np.array(f), V)), rel=1e-6), f


@pytest.mark.parametrize("dt", [0.001, 0.02, 1.0])
def test_discretisation_has_the_dryden_autocovariance_at_every_lag(dt):
    """x_{k+j} = F^j x_k + noise, so cov(w_{k+j}, w_k) = sigma^2 h F^j P h' for the stationary
    P = [[2, 1], [1, 1]] and h = (sqrt 3, 1 - sqrt 3) / 2; it must equal R_w(j dt), and
    P - F P F' must be the covariance of a real noise (positive definite)."""
    F, G = GUST.transition(V, dt)
    P = np.array([[2.0, 1.0], [1.0, 1.0]])
    h = np.array([math.sqrt(3.0), 1.0 - math.sqrt(3.0)]) / 2.0
    np.testing.assert_allclose(G @ G.T, P - F @ P @ F.T, rtol=1e-12, atol=1e-15)
    for j in (0, 1, 7, 100, 1000):
        cov = GUST.sigma**2 * h @ np.linalg.matrix_power(F, j) @ P @ h
        assert cov == pytest.approx(float(GUST.autocovariance(np.array(j * dt), V)), rel=1e-9, abs=1e-12)


def test_samples_have_variance_sigma_squared_from_the_first_one_on():
    """4000 independent sequences of 13 samples 1 s apart: the ensemble variance at the first
    and last sample is sigma^2 (started in the stationary state, no warm-up), within 4 standard
    errors of a variance from 4000 normal draws (sqrt(2/4000) = 2.2 %); the covariance of the
    two (12 s apart) is R_w(12 s), within 4 standard errors sigma^2 sqrt((1 + rho^2)/4000)."""
    M = 4000
    rng = np.random.default_rng(11)
    w = np.array([GUST.sample(13, V, 1.0, rng) for _ in range(M)])
    s2 = GUST.sigma**2
    tol = 4 * math.sqrt(2 / M)
    assert np.mean(w[:, 0] ** 2) / s2 == pytest.approx(1.0, abs=tol)
    assert np.mean(w[:, -1] ** 2) / s2 == pytest.approx(1.0, abs=tol)
    rho = float(GUST.autocovariance(np.array(12.0), V)) / s2
    assert np.mean(w[:, 0] * w[:, -1]) / s2 == pytest.approx(rho, abs=4 * math.sqrt((1 + rho**2) / M))
    assert abs(np.mean(w)) < 4 * GUST.sigma / math.sqrt(M)


def test_spectrum_of_a_long_sequence_follows_the_dryden_form():
    """2^18 samples at 50 Hz against the closed form aliased at 50 Hz, the sampled sequence's
    exact spectrum (at 20 Hz the aliases add 75 % to the continuous form, so a sequence with
    the wrong high-frequency content fails there). Welch with 4096-point Hann segments,
    averaged over 16 bins per band: over seeds 5-7 the band ratios lie within 0.94-1.09 (about
    4 % standard error); tolerance 15 %."""
    fs = 50.0
    w = GUST.sample(2**18, V, 1.0 / fs, np.random.default_rng(5))
    f, p = signal.welch(w, fs=fs, nperseg=4096)
    m = np.arange(-2000, 2001)[:, None]
    exact = GUST.psd(np.abs(f[None, :] + m * fs), V).sum(axis=0)
    for lo in (0.2, 0.5, 1.0, 2.0, 5.0, 10.0, 20.0):
        band = np.flatnonzero(f >= lo)[:16]
        assert p[band].mean() / exact[band].mean() == pytest.approx(1.0, abs=0.15), lo


def test_sequences_repeat_per_generator_and_scale_with_sigma():
    a = GUST.sample(500, V, 0.02, np.random.default_rng(3))
    b = GUST.sample(500, V, 0.02, np.random.default_rng(3))
    np.testing.assert_array_equal(a, b)
    c = DrydenVertical(2 * GUST.sigma, GUST.scale_length).sample(500, V, 0.02, np.random.default_rng(3))
    np.testing.assert_allclose(c, 2 * a, rtol=1e-12, atol=1e-15)
    assert not np.array_equal(a, GUST.sample(500, V, 0.02, np.random.default_rng(4)))
    np.testing.assert_array_equal(DrydenVertical(0.0, 100.0).sample(50, V, 0.02, np.random.default_rng(3)), 0.0)


# ------------------------------------------------------------------------------ pitch gust (G1, G3)
SPAN = 2.0875752  # m, the T-2's b


def _pitch_gust_spectrum(gust, f):
    """One-sided PSD of q_g, (rad/s)^2/Hz: |H_q(j omega)|^2 times the Dryden PSD, written here
    from G1 (not from the module)."""
    from rls_uncertainty.simulation.turbulence import pitch_gust_lag

    w = 2 * np.pi * np.asarray(f)
    tau = pitch_gust_lag(SPAN, V)
    assert tau == pytest.approx(4 * SPAN / (np.pi * V))
    return (w / V) ** 2 / (1 + (tau * w) ** 2) * gust.psd(f, V)


def test_pitch_gust_variance_is_the_integral_of_its_spectrum_and_the_thin_wing_limit():
    """G3's closed form against the spectrum integrated numerically, for the T-2 and for a
    wing a third of pi L_w / 4; for b << L_w it tends to 3 pi sigma_w^2 / (8 L_w b)."""
    from rls_uncertainty.simulation.turbulence import pitch_gust_variance

    for gust in (GUST, DrydenVertical(2.0, 4 * SPAN / (np.pi * 0.3))):
        numeric = integrate.quad(lambda f, g=gust: float(_pitch_gust_spectrum(g, f)), 0, np.inf, limit=400)[0]
        assert pitch_gust_variance(gust, SPAN, V) == pytest.approx(numeric, rel=1e-8)
    far = DrydenVertical(1.3, 1e6)
    limit = 3 * np.pi * far.sigma**2 / (8 * far.scale_length * SPAN)
    assert pitch_gust_variance(far, SPAN, V) == pytest.approx(limit, rel=1e-4)
    with pytest.raises(ConfigError, match="span shorter"):
        pitch_gust_variance(DrydenVertical(1.0, 2.0), SPAN, V)


def test_sampled_pitch_gust_has_the_g3_variance():
    """The mean square of q_g sampled at 1 kHz (the integration grid) over 20 independent
    60 s gusts, against G3, within four standard deviations of the estimate: for a Gaussian
    process observed for T s the mean square's variance is 2 int R_q(tau)^2 d tau / T =
    int_0^inf S_q(f)^2 df / T (Parseval, S_q one-sided). The step's own error, about 2e-5 of
    the gain (the sine test), is far below it."""
    from rls_uncertainty.simulation.turbulence import pitch_gust, pitch_gust_variance

    dt, runs, n = 1e-3, 20, 60_000
    rng = np.random.default_rng(3)
    squares = [np.mean(pitch_gust(GUST.sample(n, V, dt, rng), dt, SPAN, V) ** 2) for _ in range(runs)]
    exact = pitch_gust_variance(GUST, SPAN, V)
    s2 = integrate.quad(lambda f: float(_pitch_gust_spectrum(GUST, f)) ** 2, 0, np.inf, limit=400)[0]
    sd = math.sqrt(s2 / (runs * n * dt))
    assert 0.005 < sd / exact < 0.05  # the tolerance is a real one
    assert abs(np.mean(squares) - exact) < 4 * sd


@pytest.mark.parametrize("f", [0.1, 1.3, 5.0, 20.0])
def test_pitch_gust_filter_has_the_g1_gain_and_phase_on_a_sine(f):
    """G1 on a sine at 1 kHz: amplitude and phase of the steady output (least squares on sin
    and cos after 20 lags) against |H_q(j omega)| and arg H_q(j omega). The trapezoidal step of
    the lag errs to leading order by (dt/tau)^2 / 12 in gain and omega dt^2 / (12 tau) in
    phase; twice that is allowed."""
    from rls_uncertainty.simulation.turbulence import pitch_gust, pitch_gust_lag

    dt, tau = 1e-3, pitch_gust_lag(SPAN, V)
    w = 2 * np.pi * f
    t = np.arange(int(round(max(40.0, 20 / f) / dt))) * dt
    q = pitch_gust(np.sin(w * t), dt, SPAN, V)
    keep = t > 20 * tau
    fit = np.linalg.lstsq(np.column_stack([np.sin(w * t[keep]), np.cos(w * t[keep])]), q[keep], rcond=None)[0]
    H = (1j * w / V) / (1 + 1j * w * tau)
    assert abs(np.hypot(*fit) / abs(H) - 1) < 2 * (dt / tau) ** 2 / 12
    assert abs(np.arctan2(fit[1], fit[0]) - np.angle(H)) < 2 * w * dt**2 / (12 * tau)
    assert abs(np.angle(H) - np.pi / 2) > 1e-3  # the lag's phase is seen


def test_turbulence_options_take_on_or_off():
    from rls_uncertainty.simulation.turbulence import TurbulenceOptions

    assert TurbulenceOptions().pitch and not TurbulenceOptions("off").pitch
    with pytest.raises(ConfigError, match="--pitch-gust must be one of"):
        TurbulenceOptions("maybe")
