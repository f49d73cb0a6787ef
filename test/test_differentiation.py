"""Fixed-lag smooth differentiator: exact weights over the whole declared range, polynomials,
sinusoids, alignment."""

import math
from fractions import Fraction

import numpy as np
import pytest

from rls_uncertainty.aero.differentiation import (
    MAX_ORDER,
    MAX_WINDOW,
    MIN_WINDOW,
    DifferentiatorConfig,
    FixedLagDifferentiator,
    derivative_weights,
    differentiate,
)
from rls_uncertainty.errors import ConfigError

DT = 0.02
EPS = np.finfo(float).eps
# Every (window, order) the differentiator.* parameters accept.
PAIRS = [(n, o) for n in range(MIN_WINDOW, MAX_WINDOW + 1) for o in range(1, min(MAX_ORDER, n - 1) + 1)]


def _lags(window: int, rng: np.random.Generator) -> list[int]:
    """Lags of a window to check: 0 (causal), the centre and window - 1
    (the ends are the least smooth), and one drawn at random, so that a sweep of every pair
    also visits lags all over the range."""
    return sorted({0, (window - 1) // 2, window - 1, int(rng.integers(window))})


def _oracle(window: int, order: int, lag: int) -> list[Fraction]:
    """The exact weights (unit interval), another way: Gauss elimination in Fractions on the
    normal equations of the monomial fit, then the fitted polynomial's derivative at 0 applied
    to each unit sample."""
    tau = [i - (window - 1 - lag) for i in range(window)]
    m = order + 1
    A = [[Fraction(sum(t ** (i + j) for t in tau)) for j in range(m)] for i in range(m)]
    weights = []
    for t_unit in range(window):  # the fit of the unit sample e_t: right-hand side V' e_t
        b = [Fraction(tau[t_unit] ** i) for i in range(m)]
        M = [[*row, b[i]] for i, row in enumerate(A)]
        for k in range(m):
            for i in range(k + 1, m):
                f = M[i][k] / M[k][k]
                for j in range(k, m + 1):
                    M[i][j] -= f * M[k][j]
        a = [Fraction(0)] * m
        for k in reversed(range(m)):
            a[k] = (M[k][m] - sum(M[k][j] * a[j] for j in range(k + 1, m))) / M[k][k]
        weights.append(a[1])  # d/dtau of sum a_j tau^j at tau = 0
    return weights


@pytest.mark.parametrize("window, order, lag", [(5, 3, 2), (9, 3, 4), (3, 1, 0), (3, 2, 2), (17, 3, 8),
                                                (21, 10, 0), (201, 10, 0), (201, 10, 100), (201, 1, 200)])
def test_weights_are_the_exact_least_squares_weights_rounded_once(window, order, lag):
    """Each weight is the nearest double to the exact rational (computed here another way),
    at the defaults, the Monte Carlo's setting and the worst-conditioned corners."""
    c = derivative_weights(DifferentiatorConfig(window, order, lag), 1.0)
    assert c.tolist() == [float(w) for w in _oracle(window, order, lag)]


def test_the_classic_stencils():
    """The 5-point cubic is the classic central difference (1, -8, 0, 8, -1)/12; the default
    9-point cubic the Savitzky-Golay (86, -142, -193, -126, 0, 126, 193, 142, -86)/1188
    (Savitzky & Golay 1964, Table III), each weight correctly rounded."""
    five = derivative_weights(DifferentiatorConfig(5, 3, 2), 1.0)
    assert five.tolist() == [float(Fraction(k, 12)) for k in (1, -8, 0, 8, -1)]
    nine = derivative_weights(DifferentiatorConfig(9, 3, 4), 1.0)
    assert nine.tolist() == [float(Fraction(k, 1188)) for k in (86, -142, -193, -126, 0, 126, 193, 142, -86)]


def test_exact_on_polynomials_over_the_whole_declared_range():
    """Every (window, order) accepted, at the lags of :func:`_lags`: applied to the monomials
    ``(tau/h)^d`` for every ``d <= order`` (``h = window - 1``: every value in [-1, 1]) the
    weights give the derivative at ``tau = 0`` (``1/h`` for ``d = 1``, else 0). Tolerance from
    the conditioning of the sum ``c @ y`` (``||c||_1 ||y||_inf``): each weight within half an
    ulp, each monomial within ``d + 1`` roundings, the dot product ``window`` more, so
    ``|error| <= (window + order + 2) eps ||c||_1``."""
    rng = np.random.default_rng(19)
    worst = 0.0
    for window, order in PAIRS:
        h = window - 1
        for lag in _lags(window, rng):
            c = derivative_weights(DifferentiatorConfig(window, order, lag), 1.0)
            tau = np.arange(window) - (window - 1 - lag)
            Y = (tau[:, None] / h) ** np.arange(order + 1)  # (window, order + 1)
            truth = np.zeros(order + 1)
            truth[1] = 1.0 / h
            bound = (window + order + 2) * EPS * np.abs(c).sum()
            err = np.abs(c @ Y - truth).max()
            assert err <= bound, (window, order, lag, err, bound)
            worst = max(worst, err / bound)
    assert worst > 0  # the check compared numbers (not every error is exactly 0)


def test_sines_the_window_resolves_over_the_whole_declared_range():
    """A sine ``sin(w t + phi)`` differs from its Taylor polynomial of degree ``order`` about
    the evaluation point by at most ``(w |t|)^(order+1) / (order+1)!``, and the weights are
    exact on that polynomial, so the error is at most ``B(w) = sum_i |c_i| (w |tau_i| dt)^(order+1)
    / (order+1)!``. At the frequency where ``B(w) = 1e-4 w`` (the window resolves the sine to
    0.01 %), every accepted (window, order) at the lags of :func:`_lags` must stay within
    ``B(w)`` plus the rounding bound ``(window + 3) eps ||c||_1``, so well within 0.1 %."""
    rng = np.random.default_rng(20)
    phi = 0.3
    for window, order in PAIRS:
        for lag in _lags(window, rng):
            c = derivative_weights(DifferentiatorConfig(window, order, lag), DT)
            t = (np.arange(window) - (window - 1 - lag)) * DT
            k = order + 1
            moment = np.abs(c) @ np.abs(t) ** k / math.factorial(k)  # B(w) = moment w^k
            w = (1e-4 / moment) ** (1.0 / order)
            err = abs(c @ np.sin(w * t + phi) - w * math.cos(phi))
            bound = moment * w**k + (window + 3) * EPS * np.abs(c).sum()
            assert err <= bound, (window, order, lag, w, err, bound)
            assert err < 1e-3 * w * math.cos(phi)


@pytest.mark.parametrize("lag", [0, 100, 200])
def test_the_longest_highest_order_window_is_the_least_squares_fit(lag):
    """Window 201, order 10 over a 0.5 Hz unit sine at 50 Hz (two periods in the window):
    the derivative is that of the least-squares polynomial, here computed independently by
    numpy's Polynomial.fit (abscissae mapped to [-1, 1], where the degree-10 power basis is
    conditioned near 1e4: its fit is good to about 1e-12). A pseudo-inverse of the unscaled
    Vandermonde matrix returned 2.5e-13 here. (The fit itself differs from the true pi by 16 %
    at the ends: an order-10 polynomial does not follow two periods there.)"""
    c = derivative_weights(DifferentiatorConfig(201, 10, lag), DT)
    t = (np.arange(201) - (200 - lag)) * DT
    y = np.sin(np.pi * t)
    fit = np.polynomial.Polynomial.fit(t, y, 10).deriv()(0.0)
    assert c @ y == pytest.approx(fit, rel=1e-9)
    assert c @ y == pytest.approx(np.pi, rel=0.2)


@pytest.mark.parametrize(
    "cfg", [DifferentiatorConfig(9, 3, 4), DifferentiatorConfig(7, 2, 0), DifferentiatorConfig(11, 4, 2)]
)
def test_exact_on_polynomials_up_to_the_fit_order(cfg):
    t = np.arange(80) * DT
    rng = np.random.default_rng(0)
    coef = rng.standard_normal(cfg.order + 1)
    y = np.polyval(coef, t)
    dy = np.polyval(np.polyder(coef), t)
    d = differentiate(y, DT, cfg)
    ok = np.isfinite(d)
    assert ok.sum() == len(t) - cfg.window + 1
    np.testing.assert_allclose(d[ok], dy[ok], rtol=1e-9, atol=1e-9)


def test_gain_and_phase_in_the_band_of_interest():
    """0-3 Hz at 50 Hz: the default (window 9, cubic, lag 4) is within 2% in gain and 1 deg in
    phase of the true derivative, measured on sampled sinusoids."""
    cfg = DifferentiatorConfig()
    t = np.arange(500) * DT
    for f in (0.25, 0.5, 1.0, 2.0, 3.0):
        w = 2 * np.pi * f
        d = differentiate(np.sin(w * t), DT, cfg)
        ok = np.isfinite(d)
        # Fit A cos(wt) + B sin(wt) to the output: gain and phase against w cos(wt).
        M = np.column_stack([np.cos(w * t[ok]), np.sin(w * t[ok])])
        a, b = np.linalg.lstsq(M, d[ok], rcond=None)[0]
        gain = np.hypot(a, b) / w
        phase = np.degrees(np.arctan2(-b, a))
        assert abs(gain - 1) < 0.02, (f, gain)
        assert abs(phase) < 1.0, (f, phase)


def test_misalignment_would_be_caught():
    """The streamed derivative belongs to sample k - lag: pairing it with sample k leaves an
    RMS error of w * 2 sin(w lag dt / 2) / sqrt(2), far above the aligned error."""
    cfg = DifferentiatorConfig()
    t = np.arange(300) * DT
    w = 2 * np.pi * 1.0
    stream = FixedLagDifferentiator(cfg, DT)
    out = np.array([np.nan if (o := stream.push(np.sin(w * tk))) is None else o[0] for tk in t])
    k = np.arange(cfg.window - 1, len(t))
    aligned = np.sqrt(np.mean((out[k] - w * np.cos(w * t[k - cfg.lag])) ** 2))
    misaligned = np.sqrt(np.mean((out[k] - w * np.cos(w * t[k])) ** 2))
    expected = w * 2 * np.sin(w * cfg.lag * DT / 2) / np.sqrt(2)
    assert aligned < 0.01 * w
    assert misaligned == pytest.approx(expected, rel=0.05)
    assert misaligned > 20 * aligned


def test_streaming_equals_batch_and_waits_for_a_full_window():
    cfg = DifferentiatorConfig(9, 3, 2)
    y = np.random.default_rng(1).standard_normal((60, 3))
    stream = FixedLagDifferentiator(cfg, DT, width=3)
    outs = [stream.push(row) for row in y]
    assert all(o is None for o in outs[: cfg.window - 1])
    batch = np.column_stack([differentiate(y[:, i], DT, cfg) for i in range(3)])
    for k in range(cfg.window - 1, len(y)):
        np.testing.assert_allclose(outs[k], batch[k - cfg.lag], rtol=1e-12)


@pytest.mark.parametrize("kw, field", [
    (dict(window=1), "window"),
    (dict(order=0), "order"),
    (dict(window=5, order=5), "order"),
    (dict(window=5, lag=5), "lag"),
    (dict(lag=-1), "lag"),
    (dict(window=9.5), "window"),
    (dict(window=2, order=1, lag=0), "window"),
    (dict(window=MAX_WINDOW + 1, lag=0), "window"),
    (dict(window=30, order=MAX_ORDER + 1), "order"),
])
def test_invalid_configuration(kw, field):
    """Validated here and only here (the parameters reach it unchanged): a ConfigError, which
    is a ValueError, naming the parameter."""
    with pytest.raises(ConfigError, match=f"differentiator.{field}"):
        DifferentiatorConfig(**kw)
    with pytest.raises(ValueError):
        DifferentiatorConfig(**kw)
    with pytest.raises(ValueError):
        derivative_weights(DifferentiatorConfig(), 0.0)
    assert DifferentiatorConfig(np.int64(7), np.int64(2), np.int64(3)).window == 7
