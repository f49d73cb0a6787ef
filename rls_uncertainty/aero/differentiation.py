"""Real-time smooth differentiation with a fixed lag (local polynomial fit).

Angular accelerations for Eq. 1d-f come from the measured rates. A polynomial of order
``order`` is fitted by least squares to the last ``window`` samples, and its derivative is
evaluated ``lag`` samples before the newest one: ``lag = 0`` is fully causal, ``lag =
(window-1)/2`` is the centred (Savitzky-Golay) derivative. The result for sample ``k - lag``
is available at sample ``k``, so every other signal of that sample must be delayed by the same
``lag`` (the pipeline does this). numpy only.

The weights are computed exactly, in integer arithmetic, and each is rounded once to the
nearest double (:func:`derivative_weights`): the fit's normal equations on the sample offsets
are a Hankel matrix of power sums (up to ``200^20`` at window 201, order 10) whose condition
number reaches 1e37, far beyond what any floating-point solve can invert (a pseudo-inverse
there drops the small singular values and returns a derivative of ~0). Exact arithmetic has
no conditioning to lose, costs about a millisecond at the largest setting, and gives the same
weights on every machine. docs/estimator.md states the sweep over the whole declared range.

Invalid settings raise :class:`.errors.ConfigError` (a ``ValueError``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from fractions import Fraction
from functools import lru_cache

import numpy as np
import numpy.typing as npt

from ..errors import ConfigError
from ..schema import check, option

__all__ = ["DifferentiatorConfig", "FixedLagDifferentiator", "derivative_weights", "differentiate", "MIN_WINDOW",
           "MAX_WINDOW", "MAX_ORDER", "pass_band"]

FloatArray = npt.NDArray[np.float64]

# The declared range (the differentiator.* parameters take it from here). Every setting in it
# is exact (module docstring); the bounds keep the weights' computation about a millisecond and
# the window within 4 s of samples at 50 Hz, longer than any local fit of a maneuver needs.
MIN_WINDOW, MAX_WINDOW, MAX_ORDER = 3, 201, 10


@dataclass(frozen=True)
class DifferentiatorConfig:
    """Window length (samples), polynomial order and fixed lag (samples, 0 = causal): the
    ``differentiator.*`` parameters, validated here and nowhere else."""

    window: int = option(9, "angular-acceleration differentiator window", unit="samples", low=MIN_WINDOW,
                         high=MAX_WINDOW, ros="differentiator.window")
    order: int = option(3, "local polynomial order of the differentiator (below differentiator.window; weights "
                        "exact at every setting)", low=1, high=MAX_ORDER, ros="differentiator.order")
    lag: int = option(4, "differentiator fixed lag (0 = causal); every signal is delayed by it", unit="samples",
                      low=0, high=MAX_WINDOW - 1, ros="differentiator.lag")

    def __post_init__(self) -> None:
        check(self, "differentiator")
        if not self.order < self.window:
            raise ConfigError(f"differentiator.order must be below differentiator.window = {self.window}, "
                              f"got {self.order}", parameter="differentiator.order")
        if not self.lag < self.window:
            raise ConfigError(f"differentiator.lag must be in [0, differentiator.window - 1 = {self.window - 1}], "
                              f"got {self.lag}", parameter="differentiator.lag")


def derivative_weights(config: DifferentiatorConfig, dt: float) -> FloatArray:
    """FIR weights ``c`` (oldest sample first) with ``dy/dt(k - lag) = c @ y[k-window+1 : k+1]``.

    Exact for polynomials up to ``config.order``: the weights for a unit interval are the exact
    rationals of the least-squares fit (:func:`_unit_weights`), each rounded once to the
    nearest double, then divided by ``dt``.
    """
    if not dt > 0:
        raise ValueError(f"sample interval must be positive, got {dt}")
    weights: FloatArray = np.array(_unit_weights(int(config.window), int(config.order), int(config.lag))) / dt
    return weights


@lru_cache(maxsize=64)
def _unit_weights(window: int, order: int, lag: int) -> tuple[float, ...]:
    """The weights for a unit sample interval, computed in integers.

    With sample offsets ``tau_i = i - (window - 1 - lag)`` from sample ``k - lag`` (integers)
    and ``V_ij = tau_i^j``, the fit ``a = (V'V)^-1 V'y`` has the derivative ``a_1`` at
    ``tau = 0``, so ``c_i = sum_j b_j tau_i^j`` with ``(V'V) b = e_1``. ``V'V`` is the Hankel
    matrix of the power sums ``s_(j+l) = sum_i tau_i^(j+l)``, integers; Bareiss' fraction-free
    elimination keeps every entry an integer (each division is exact), and ``V'V`` is positive
    definite (``window > order`` distinct offsets), so no pivot is zero. The rational ``b``
    share one denominator ``D``; ``c_i = (sum_j N_j tau_i^j) / D`` is one integer division,
    which Python rounds correctly to the nearest double.
    """
    tau = range(lag + 1 - window, lag + 1)
    m = order + 1
    s = [sum(t**p for t in tau) for p in range(2 * m - 1)]
    rows = [[s[j + col] for col in range(m)] + [int(j == 1)] for j in range(m)]  # [V'V | e_1]
    previous = 1
    for p in range(m - 1):
        pivot_row = rows[p]
        pivot = pivot_row[p]
        for row in rows[p + 1:]:
            f = row[p]
            for col in range(p + 1, m + 1):
                row[col] = (row[col] * pivot - f * pivot_row[col]) // previous
            row[p] = 0
        previous = pivot
    b = [Fraction(0)] * m
    for j in reversed(range(m)):
        row = rows[j]
        b[j] = (row[m] - sum(row[col] * b[col] for col in range(j + 1, m))) / Fraction(row[j])
    D = math.lcm(*(x.denominator for x in b))
    N = [x.numerator * (D // x.denominator) for x in b]
    weights = []
    for t in tau:
        acc = 0
        for n_j in reversed(N):  # Horner: sum_j N_j t^j
            acc = acc * t + n_j
        weights.append(acc / D)
    return tuple(weights)


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


@lru_cache(maxsize=64)
def pass_band(config: DifferentiatorConfig, rate: float, tolerance: float = 0.05) -> float:
    """The highest frequency (Hz) up to which the lag-compensated derivative of ``config`` at
    ``rate`` Hz is within ``tolerance`` of the ideal ``j omega`` (the pipeline delays every other
    signal by the same lag): its gain ``H(f) / (j 2 pi f)`` with ``H`` the FIR response of
    :func:`derivative_weights`. ``rate / 2`` when it holds up to Nyquist. A window of 9 samples
    (order 3, lag 4) at 50 Hz passes 4.34 Hz; 201 samples (4 s) only 0.185 Hz."""
    w = derivative_weights(config, 1.0 / rate)
    f = np.linspace(1e-3, rate / 2.0, 20000)
    offsets = (np.arange(config.window) - (config.window - 1 - config.lag)) / rate  # oldest first
    H = np.exp(2j * np.pi * f[:, None] * offsets[None, :]) @ w
    error = np.abs(H / (2j * np.pi * f) - 1.0)
    bad = np.flatnonzero(error > tolerance)
    return float(f[bad[0]]) if bad.size else rate / 2.0
