"""Real-time smooth differentiation with a fixed lag (local polynomial fit).

Angular accelerations for Eq. 1d-f come from the measured rates. A polynomial of order
``order`` is fitted by least squares to the last ``window`` samples, and its derivative is
evaluated ``lag`` samples before the newest one: ``lag = 0`` is fully causal, ``lag =
(window-1)/2`` is the centred (Savitzky-Golay) derivative. The result for sample ``k - lag``
is available at sample ``k``, so every other signal of that sample must be delayed by the same
``lag`` (the pipeline does this). numpy only.

Invalid settings raise :class:`.errors.ConfigError` (a ``ValueError``).
"""

from __future__ import annotations

from dataclasses import dataclass
from numbers import Integral

import numpy as np
import numpy.typing as npt

from .errors import ConfigError

__all__ = ["DifferentiatorConfig", "FixedLagDifferentiator", "derivative_weights", "differentiate"]

FloatArray = npt.NDArray[np.float64]


@dataclass(frozen=True)
class DifferentiatorConfig:
    """Window length (samples), polynomial order and fixed lag (samples, 0 = causal): the
    ``differentiator.*`` parameters, validated here and nowhere else."""

    window: int = 9
    order: int = 3
    lag: int = 4

    def __post_init__(self) -> None:
        for name in ("window", "order", "lag"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, Integral):
                raise ConfigError(f"differentiator.{name} must be an integer, got {value!r}")
        if self.window < 2:
            raise ConfigError(f"differentiator.window must be >= 2 samples, got {self.window}")
        if not 1 <= self.order < self.window:
            raise ConfigError(
                f"differentiator.order must be in [1, differentiator.window - 1 = {self.window - 1}], got {self.order}"
            )
        if not 0 <= self.lag < self.window:
            raise ConfigError(
                f"differentiator.lag must be in [0, differentiator.window - 1 = {self.window - 1}], got {self.lag}"
            )


def derivative_weights(config: DifferentiatorConfig, dt: float) -> FloatArray:
    """FIR weights ``c`` (oldest sample first) with ``dy/dt(k - lag) = c @ y[k-window+1 : k+1]``.

    Exact for polynomials up to ``config.order``.
    """
    if not dt > 0:
        raise ValueError(f"sample interval must be positive, got {dt}")
    n = config.window
    tau = np.arange(n, dtype=float) - (n - 1 - config.lag)  # sample offsets from k - lag
    V = np.vander(tau, config.order + 1, increasing=True)  # columns 1, tau, tau^2, ...
    pinv = np.linalg.pinv(V)  # rows: polynomial coefficients
    weights: FloatArray = pinv[1] / dt  # derivative at tau = 0 is the linear coefficient
    return weights


def differentiate(y: FloatArray, dt: float, config: DifferentiatorConfig = DifferentiatorConfig()) -> FloatArray:
    """Apply the fixed-lag differentiator to a whole record.

    Returns ``d`` with ``d[j]`` the derivative at sample ``j`` for ``j`` in
    ``[window-1-lag, len(y)-1-lag]`` and NaN where the window is incomplete (the first
    ``window-1-lag`` and the last ``lag`` samples), exactly what the real-time filter yields.
    """
    y = np.asarray(y, dtype=float)
    c = derivative_weights(config, dt)
    n = config.window
    out = np.full(y.shape, np.nan)
    if y.shape[0] >= n:
        valid = np.lib.stride_tricks.sliding_window_view(y, n, axis=0)  # (..., n)
        d = valid @ c
        start = n - 1 - config.lag
        out[start : start + d.shape[0]] = d
    return out


class FixedLagDifferentiator:
    """Streaming form: push one sample (scalar or vector), get the derivative ``lag`` samples
    back once the window is full (``None`` before)."""

    def __init__(self, config: DifferentiatorConfig, dt: float, width: int = 1) -> None:
        self.config = config
        self.weights = derivative_weights(config, dt)
        self._buf = np.zeros((2 * config.window, width))
        self._count = 0

    @property
    def lag(self) -> int:
        return self.config.lag

    def reset(self) -> None:
        self._buf[:] = 0.0
        self._count = 0

    def push(self, y: npt.ArrayLike) -> FloatArray | None:
        n = self.config.window
        i = self._count % n
        self._buf[i] = y
        self._buf[i + n] = y
        self._count += 1
        if self._count < n:
            return None
        start = (i + 1) % n
        return self.weights @ self._buf[start : start + n]
