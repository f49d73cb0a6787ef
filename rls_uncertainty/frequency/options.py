"""The frequency-domain estimator's options, defined and validated once.

:class:`FrequencyOptions` is frozen and checks itself in its constructor; a bad value raises
:class:`~rls_uncertainty.errors.ConfigError` naming the option as the node's parameter
(``frequency.f_max``; :func:`rls_uncertainty.settings.config.frequency_options` maps the parameters).
Nothing downstream re-checks it. The frequency grid of the recursive Fourier transform is
:meth:`FrequencyOptions.frequencies`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from ..errors import ConfigError

__all__ = ["FrequencyOptions", "MAX_FREQUENCIES", "MAX_LAGS", "MAX_TRIM"]

FloatArray = npt.NDArray[np.float64]

# Largest grid: the covariance works on K x K frequency-pair matrices per model.
MAX_FREQUENCIES = 1000
# Largest n_lags: the lag-product sums hold (n_lags + 1) (p + 1)^2 numbers per model.
MAX_LAGS = 100_000
# Largest trim_samples: the covariance sums over trim_samples + n_lags samples per evaluation.
MAX_TRIM = 10_000
# Tolerance of the grid end: f_max is on the grid when it is within 1e-9 steps of a point.
_GRID_TOLERANCE = 1e-9


def _number(name: str, value: object) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise ConfigError(f"frequency.{name} must be a number, got {value!r}")
    out = float(value)
    if not math.isfinite(out):
        raise ConfigError(f"frequency.{name} must be finite, got {value!r}")
    return out


def _count(name: str, value: object, low: int, high: int) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or not low <= int(value) <= high:
        raise ConfigError(f"frequency.{name} must be an integer in [{low}, {high}], got {value!r}")
    return int(value)


@dataclass(frozen=True)
class FrequencyOptions:
    """Options of :class:`~rls_uncertainty.frequency.FrequencyBank` (docs/frequency.md).

    rate_hz:
        Sample rate of the regression rows, Hz: sample ``n`` (from 0) is at ``t_n = n / rate_hz``.
        Required: the transform's phases depend on it.
    f_min, f_max, f_step:
        The frequency grid, Hz: ``f_min + k f_step`` for ``k = 0, 1, ...`` up to ``f_max``
        (inclusive, within ``1e-9`` steps). Default 0.1 to 1.5 Hz every 0.04 Hz, the grid of
        NASA SIDPAC's real-time demo. Every frequency must lie below the Nyquist frequency
        ``rate_hz / 2``.
    trim_samples:
        The trim subtracted from every signal before the transform: the mean of its first
        ``trim_samples`` samples (until that many have arrived, of those so far). 1, the
        default, is the first sample, as SIDPAC's real-time code; a longer steady stretch before
        the excitation (e.g. 25 samples, the half second before the T-2's input) puts less of
        one sample's noise into every sample (docs/frequency.md, "The trim").
    n_lags:
        Lags of the residual autocovariance kept in the corrected covariance (the ``n_tau``
        of the paper's Eq. 22); 0 keeps only ``R(0)``.
    every:
        Estimates and both covariances are computed every ``every`` samples (on the sample
        counts that are multiples of it); in between the last ones are returned. The
        transforms and lag sums are updated at every sample.
    dof_correction:
        Correct the residual autocovariance for the degrees of freedom of the least-squares
        fit its residuals come from (docs/frequency.md, Eq. F10).
    init_condition:
        A model is ready once its column-scaled normal matrix ``Re(X^H X)`` has a condition
        number below this (like the time-domain estimator's exact initialization).
    """

    rate_hz: float
    f_min: float = 0.1
    f_max: float = 1.5
    f_step: float = 0.04
    trim_samples: int = 1
    n_lags: int = 50
    every: int = 1
    dof_correction: bool = True
    init_condition: float = 1e8

    def __post_init__(self) -> None:
        rate = _number("rate_hz", self.rate_hz)
        f_min, f_max, step = (_number(n, getattr(self, n)) for n in ("f_min", "f_max", "f_step"))
        if rate <= 0:
            raise ConfigError(f"frequency.rate_hz must be positive, got {self.rate_hz!r}")
        if f_min <= 0:
            raise ConfigError(f"frequency.f_min must be positive (the transform drops the bias at 0 Hz), got {f_min!r}")
        if f_max < f_min:
            raise ConfigError(f"frequency.f_max must be >= f_min = {f_min}, got {f_max!r}")
        if step <= 0:
            raise ConfigError(f"frequency.f_step must be positive, got {step!r}")
        count = math.floor((f_max - f_min) / step + _GRID_TOLERANCE) + 1
        if count > MAX_FREQUENCIES:
            raise ConfigError(
                f"frequency.f_step {step} gives {count} frequencies from {f_min} to {f_max} Hz, more than "
                f"{MAX_FREQUENCIES}; raise f_step or narrow the band"
            )
        top = f_min + (count - 1) * step
        if top >= rate / 2:
            raise ConfigError(
                f"frequency.f_max must stay below the Nyquist frequency rate / 2 = {rate / 2} Hz, "
                f"the grid reaches {top} Hz"
            )
        _count("trim_samples", self.trim_samples, 1, MAX_TRIM)
        _count("n_lags", self.n_lags, 0, MAX_LAGS)
        _count("every", self.every, 1, 1_000_000)
        if not isinstance(self.dof_correction, (bool, np.bool_)):
            raise ConfigError(f"frequency.dof_correction must be true or false, got {self.dof_correction!r}")
        if not _number("init_condition", self.init_condition) > 1.0:
            raise ConfigError(f"frequency.init_condition must be > 1, got {self.init_condition!r}")

    def frequencies(self) -> FloatArray:
        """The grid in Hz, ``f_min + k f_step``."""
        count = math.floor((self.f_max - self.f_min) / self.f_step + _GRID_TOLERANCE) + 1
        grid: FloatArray = self.f_min + self.f_step * np.arange(count, dtype=np.float64)
        return grid

    @property
    def dt(self) -> float:
        """Sample interval, s."""
        return 1.0 / float(self.rate_hz)
