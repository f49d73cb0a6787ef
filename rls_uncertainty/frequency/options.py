"""The frequency-domain estimator's options, defined and validated once.

:class:`FrequencyOptions` is frozen and checks itself in its constructor; a bad value raises
:class:`~rls_uncertainty.errors.ConfigError` naming the option (``frequency.f_max``). Each
field is a :func:`..schema.option` with its default, bounds, unit, meaning and node parameter
(the trim and the lags in seconds there, in samples here);
:mod:`rls_uncertainty.settings.parameters` builds the object from the parameters. Nothing
downstream re-checks it. The frequency grid of the recursive Fourier transform is
:meth:`FrequencyOptions.frequencies`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from ..errors import ConfigError
from ..estimator.options import PUBLISH_LAG_WINDOWS, PUBLISH_LAG_WINDOWS_RANGE, PUBLISH_MEANING
from ..schema import Span, Special, check, option

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
    publish_lag_windows:
        The publication rule, as the time-domain estimator's (the node's
        ``estimator.publish_lag_windows`` sets both): a model publishes once ``N - n >=
        publish_lag_windows x L``, ``N`` the samples of the record, ``n`` its regressors with the
        bias of Eq. 2 (the residual autocovariance F9 comes from a fit with it), ``L`` the lag
        window :attr:`publish_lags`.
    """

    rate_hz: float
    f_min: float = option(0.1, "frequency-domain method: lowest frequency of the grid", unit="Hz", low=1e-6,
                          high=1000.0, ros="frequency.f_min")
    f_max: float = option(1.5, "frequency-domain method: highest frequency of the grid (included when a whole "
                          "number of f_step from f_min); below rate / 2", unit="Hz", low=1e-6, high=1000.0,
                          ros="frequency.f_max")
    f_step: float = option(0.04, "frequency-domain method: grid step (at most 1000 frequencies)", unit="Hz",
                           low=1e-6, high=1000.0, ros="frequency.f_step")
    trim_samples: int = option(
        1, "frequency-domain method: the trim subtracted from every signal is the mean of the samples of this first "
        "span (steady flight before the excitation)", unit="samples", low=1, high=MAX_TRIM, ros="frequency.trim_span",
        span=Span(0.0, 200.0, (Special(0.0, 1, "", "the first sample"),)))
    n_lags: int = option(
        50, "frequency-domain method: time span of the residual autocorrelation kept in the corrected covariance "
        "(lags = lag_span x rate)", unit="samples", low=0, high=MAX_LAGS, ros="frequency.lag_span",
        span=Span(0.0, 2000.0, (Special(0.0, 0, "", "keeps R(0) only"),)))
    every: int = option(1, "frequency-domain method: estimates and standard errors computed and published every this "
                        "many samples (the transform advances every sample)", unit="samples", low=1, high=1_000_000,
                        ros="frequency.every")
    dof_correction: bool = option(True, "correct the residual autocovariance for the degrees of freedom of the fit "
                                  "(docs/frequency.md, Eq. F10)")
    init_condition: float = option(1e8, "a model is ready once its column-scaled Re(X^H X) is better conditioned "
                                   "than this", low=1.0, low_open=True)
    publish_lag_windows: float = option(PUBLISH_LAG_WINDOWS, PUBLISH_MEANING, low=PUBLISH_LAG_WINDOWS_RANGE[0],
                                        high=PUBLISH_LAG_WINDOWS_RANGE[1])

    def __post_init__(self) -> None:
        rate = _number("rate_hz", self.rate_hz)
        if rate <= 0:
            raise ConfigError(f"frequency.rate_hz must be positive, got {self.rate_hz!r}")
        check(self, "frequency")
        f_min, f_max, step = self.f_min, self.f_max, self.f_step
        if f_max < f_min:
            raise ConfigError(f"frequency.f_max must be >= f_min = {f_min}, got {f_max!r}", parameter="frequency.f_max")
        count = math.floor((f_max - f_min) / step + _GRID_TOLERANCE) + 1
        if count > MAX_FREQUENCIES:
            raise ConfigError(
                f"frequency.f_step {step} gives {count} frequencies from {f_min} to {f_max} Hz, more than "
                f"{MAX_FREQUENCIES}; raise f_step or narrow the band", parameter="frequency.f_step"
            )
        top = f_min + (count - 1) * step
        if top >= rate / 2:
            raise ConfigError(
                f"frequency.f_max must stay below the Nyquist frequency rate / 2 = {rate / 2} Hz, "
                f"the grid reaches {top} Hz", parameter="frequency.f_max"
            )

    def frequencies(self) -> FloatArray:
        """The grid in Hz, ``f_min + k f_step``."""
        count = math.floor((self.f_max - self.f_min) / self.f_step + _GRID_TOLERANCE) + 1
        grid: FloatArray = self.f_min + self.f_step * np.arange(count, dtype=np.float64)
        return grid

    @property
    def publish_lags(self) -> int:
        """The lag window of the publication rule: ``n_lags``, or with ``n_lags = 0`` (no
        window) one second of samples, the default span."""
        return self.n_lags if self.n_lags > 0 else max(1, round(float(self.rate_hz)))

    def publish_samples(self, n: int) -> int:
        """Samples a model of ``n`` parameters (with the bias) needs before it publishes."""
        return n + math.ceil(self.publish_lag_windows * self.publish_lags - 1e-9)

    @property
    def dt(self) -> float:
        """Sample interval, s."""
        return 1.0 / float(self.rate_hz)
