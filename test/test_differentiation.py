"""Fixed-lag smooth differentiator: polynomials, sinusoids, alignment."""

import numpy as np
import pytest

from rls_uncertainty.differentiation import (
    DifferentiatorConfig,
    FixedLagDifferentiator,
    derivative_weights,
    differentiate,
)
from rls_uncertainty.errors import ConfigError

DT = 0.02


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
