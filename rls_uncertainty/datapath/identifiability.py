"""Is a parameter identifiable from the data so far? Per model and parameter, once per sample.

A converged-looking estimate means nothing when the data cannot tell the parameter apart from
another one, when its regressor never moved, or when the model explains none of the output.
:class:`IdentifiabilityMonitor` judges three things at every sample, from what the estimator
already holds and two running statistics (nothing is refitted, nothing grows with the record):

1. **The fit.** ``R^2 = 1 - R_k(0) / var(z)`` (:func:`r_squared`): the fit-error variance of
   Eq. 16 against the output's variance, both since the estimator (re)started (weighted with
   the forgetting factor): the coefficient of determination of linear regression (Klein and
   Morelli, Aircraft System Identification, AIAA 2006, Ch. 5), the fraction of the output's
   variation the model explains. Below ``min_r_squared`` the model explains nothing
   and none of its parameters is identifiable (sensor noise only, a wrong or inconsistent
   output).
2. **Excitation.** The standard deviation of each regressor since the start
   (:class:`RegressorStatistics`), against a resolution floor in the regressor's unit
   (``angle_resolution`` rad for flow angles and surfaces, ``rate_resolution`` for the
   nondimensional rates ``p b/2V, q cbar/2V, r b/2V``). A regressor that never moved beyond the
   floor cannot be told apart from the bias (Klein and Morelli Sec. 5.5: a regressor that is a
   linear combination of others, here a constant); its parameter is not identifiable, nor is the
   bias when the regressor's mean is not zero (the bias absorbs ``mean x theta``).
   **Against its own sensor noise**: a regressor whose variance since the start is at most
   ``min_noise_ratio`` times its white-noise variance is not excited either, whatever its
   floor. The noise is estimated online from the second differences of the regression rows,
   ``d_k = x_k - 2 x_(k-1) + x_(k-2)``: for white noise of variance ``sigma^2``
   ``E[d^2] = 6 sigma^2``, while the motion passes with gain ``(2 sin(pi f / rate))^2`` (0.063
   at 2 Hz and 50 Hz), so ``sigma_hat^2 = sum_k w_k d_k^2 / (6 sum_k w_k)`` (weights ``f^(k-j)``
   as the statistics; a dropout or restart starts the differences afresh, not the sums). A
   slope estimated from ``x = s + n`` is attenuated by ``var(s) / var(x) = 1 - 1/ratio`` (errors
   in variables, Klein and Morelli Sec. 5.4), so the default ratio 10 bounds what the sensor
   noise alone does to a slope at 10 % (docs/studies/publication_and_noise/REPORT.md). The test
   measures white noise: a slowly varying sensor error looks like motion to it.
3. **Collinearity.** The correlation of each pair of parameter estimates from the corrected
   covariance (Eqs. 20/22), ``rho_ij = C_ij / sqrt(C_ii C_jj)``; where a corrected variance is
   zero (an exact fit) from the conventional covariance (Eq. 13), whose correlations are those of
   ``(X'X)^-1``: the data's. Two slopes correlated beyond ``max_correlation`` in magnitude are
   not identifiable: many weighted combinations of the two regressors fit the data equally well
   (Klein and Morelli Sec. 5.5, "Data Collinearity"). Pairs with the bias are left out: for
   least squares with a bias, the slopes' covariance is that of the centred regressors, the
   standardized form Klein and Morelli assess collinearity in, while the bias-slope correlation
   only says the regressor's mean is large against its variation (test 2 covers that).

**Thresholds.** Klein and Morelli (Sec. 5.5) assess collinearity from the pairwise correlations
of the standardized regressors (their Eq. 5.77) and the eigenvalues of their correlation
matrix; the usual rule of thumb calls a correlation beyond 0.9 in magnitude collinear, and
Belsley's condition indices (Belsley, Kuh and Welsch, Regression Diagnostics, Wiley 1980) call
30 moderate and 100 strong collinearity. For two standardized regressors correlated ``r`` the condition
index is ``sqrt((1 + r) / (1 - r))``: 0.9 is an index of 4.4, 0.998 of 30, 0.9998 of 100.
Moderate collinearity inflates the variances, and the corrected standard errors carry that: the
flag stays honest. The test is for what the data cannot separate, strong collinearity:
``max_correlation = 0.9998`` (an index of 100; a variance inflation of 2500). Measured
(docs/studies/identifiability/REPORT.md): the T-2 maneuver's regressors are correlated through
the dynamics (alpha, q and delta_e move together in a short-period response), and on the Table 3
Monte Carlo the slope estimates reach 0.895 after the flags, so 0.9 would withhold flags the
estimates deserve; on the Twin Otter lateral maneuver C_l's sideslip and roll-rate estimates
pass 0.999 for seconds while those estimates are within one standard error of their final
values; a surface commanded twice gives ``1 - 5e-8``. ``min_r_squared = 0.5``: a model that
explains less than half of its output's variation is not a model of it (the Monte Carlo's
models stay above 0.81 after their flags, the Twin Otter's above 0.96 at the end; the
noise-only and spiking cases are below 0.02). The resolutions are below any sensor's (a 12-bit
vane over +-30 deg resolves 2.6e-4 rad) and far below the maneuvers' excitation (1e-2 rad).

The statistics restart with the estimator; after a resumed state file the regressor statistics
start from the resumed samples (the output sums are in the file), so a resumed estimate is
flagged again once the new data move its regressors.

numpy only.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from ..aero.models import ANGLE, BIAS, NONDIMENSIONAL
from ..schema import check, option

if TYPE_CHECKING:  # annotations only
    from ..estimator import EstimatorBank

__all__ = [
    "IdentifiabilityConfig",
    "RegressorStatistics",
    "IdentifiabilityMonitor",
    "Problem",
    "r_squared",
    "ANGLE",
    "NONDIMENSIONAL",
    "BIAS",
]

# Regressor units (config.REGRESSOR_UNITS): a flow angle or surface deflection in rad, a
# nondimensional rate, or the bias.
_CONSTANT_OUTPUT = 1e-12  # var(z) at most this fraction of mean(z^2): R^2 undefined (model_fit)


@dataclass(frozen=True)
class IdentifiabilityConfig:
    """The three tests of the module docstring (``identifiability.*`` parameters): the largest
    magnitude of the correlation of two slope estimates, the smallest R^2 of a model whose
    parameters can be identifiable, and the excitation floors of the flow angles and surfaces
    (rad) and of the nondimensional rates. Each field's meaning and bounds are its option's."""

    max_correlation: float = option(
        0.9998, "convergence flags: two parameters whose estimates are correlated beyond this (either sign, from the "
        "corrected covariance) are not identifiable and never flagged", low=0.5, high=0.999999,
        ros="identifiability.max_correlation")
    min_r_squared: float = option(
        0.5, "convergence flags: a model whose R^2 is below this explains nothing; none of its parameters is flagged",
        low=0.0, high=0.99, ros="identifiability.min_r_squared")
    angle_resolution: float = option(
        1e-4, "convergence flags: a flow angle or surface regressor whose standard deviation since the start is at "
        "most this is not excited and its parameter never flagged", unit="rad", low=0.0, high=0.1,
        ros="identifiability.angle_resolution")
    rate_resolution: float = option(1e-6, "the same for the nondimensional rates p b/2V, q cbar/2V, r b/2V",
                                    low=0.0, high=0.01, ros="identifiability.rate_resolution")
    min_noise_ratio: float = option(
        10.0, "convergence flags: a regressor whose variance since the start is at most this many times its sensor "
        "noise variance (estimated from its second differences) is not excited and its parameter not identifiable; "
        "10 bounds the errors-in-variables attenuation of its slope at 10 %; 0 disables the test", low=0.0, high=1e6,
        ros="identifiability.min_noise_ratio")

    def __post_init__(self) -> None:
        check(self, "identifiability")

    def resolution(self, unit: str | None) -> float:
        """The excitation floor of a regressor of ``unit`` (NaN for the bias: not tested)."""
        if unit is BIAS:
            return math.nan
        return self.angle_resolution if unit == ANGLE else self.rate_resolution


def r_squared(residual_variance: np.ndarray, output_sum: np.ndarray, output_sum_squares: np.ndarray,
              weight: float) -> np.ndarray:
    """``R^2 = 1 - R_k(0) / var(z)`` of every model, ``(M,)``: ``residual_variance`` is
    ``R_k(0)`` (Eq. 16, NaN for models not ready), the output's variance comes from its
    (weighted) sum and sum of squares and their ``weight`` (``n_k``). NaN where the output is
    constant (its variance at most 1e-12 of its mean square: R^2 undefined) or not ready."""
    n = max(weight, 1e-300)
    mean_sq = output_sum_squares / n
    var = mean_sq - (output_sum / n) ** 2
    with np.errstate(divide="ignore", invalid="ignore"):
        r2: np.ndarray = np.where(var > _CONSTANT_OUTPUT * mean_sq, 1.0 - residual_variance / var, np.nan)
    return r2


class RegressorStatistics:
    """Running mean and co-moment of every model's regressors, weighted ``f^(k-j)`` like the
    estimator (West's weighted form of Welford's update: no cancellation, O(n^2) per model and
    sample). ``std`` is each regressor's standard deviation, ``correlation()`` the pairwise
    correlation of the regressors (Klein and Morelli's Eq. 5.77, the data collinearity of the
    standardized regressors)."""

    def __init__(self, shape: tuple[int, int], forgetting: float = 1.0) -> None:
        self.shape = shape
        self.forgetting = float(forgetting)
        self.reset()

    def reset(self) -> None:
        m, n = self.shape
        self.weight = 0.0
        self.samples = 0
        self.mean = np.zeros((m, n))
        self.comoment = np.zeros((m, n, n))
        self.variance_sums = self.comoment.diagonal(0, 1, 2)  # (a view: weight x variance)
        self.noise_sums = np.zeros((m, n))  # sum_k f^(k-j) d_k^2 of the second differences
        self.noise_weight = 0.0  # sum_k f^(k-j) over the second differences taken
        self._last = np.zeros((2, m, n))  # the previous two rows: _last[_newest] the newest
        self._newest = 0
        self._chain = 0  # consecutive rows in _last (a second difference needs two)
        # Scratch of add() with its views, made once (a view costs as much as a small operation).
        self._d = np.zeros((m, n))
        self._d_weighted = np.zeros((m, n))
        self._d_row = self._d[:, None, :]
        self._d_weighted_col = self._d_weighted[:, :, None]
        self._outer = np.zeros((m, n, n))

    def restart_chain(self) -> None:
        """The next row does not follow the last one (a dropout, a new timeline): the second
        differences start afresh; the sums go on."""
        self._chain = 0

    def add(self, x: np.ndarray) -> None:
        """One sample's regressors ``(M, n_max)``."""
        f = self.forgetting
        self.weight = w = f * self.weight + 1.0
        self.samples += 1
        d, scratch = self._d, self._d_weighted
        np.subtract(x, self.mean, out=d)
        self.mean += np.divide(d, w, out=scratch)
        # sum_j f^(k-j) (x_j - mean_k)(x_j - mean_k)': f C + (1 - 1/w) d d' (exactly symmetric)
        if f != 1.0:
            self.comoment *= f
            self.noise_sums *= f
            self.noise_weight *= f
        np.multiply(d, 1.0 - 1.0 / w, out=scratch)
        self.comoment += np.multiply(self._d_weighted_col, self._d_row, out=self._outer)
        last, newest = self._last, self._newest
        older = 1 - newest
        if self._chain >= 2:  # d_k = x - 2 x_(k-1) + x_(k-2)
            d2 = np.multiply(last[newest], 2.0, out=scratch)
            np.subtract(x, d2, out=d2)
            d2 += last[older]
            self.noise_sums += np.multiply(d2, d2, out=d2)
            self.noise_weight += 1.0
        else:
            self._chain += 1
        last[older] = x  # the new newest row; the previous one is now the older
        self._newest = older

    @property
    def noise_variance(self) -> np.ndarray:
        """``(M, n_max)`` white-noise variance of each regressor from its second differences,
        ``sum w d^2 / (6 sum w)`` (NaN before the first second difference)."""
        if self.noise_weight <= 0.0:
            return np.full(self.shape, np.nan)
        out: np.ndarray = self.noise_sums / (6.0 * self.noise_weight)
        return out

    @property
    def std(self) -> np.ndarray:
        """``(M, n_max)`` standard deviations (0 before any sample)."""
        return np.sqrt(np.maximum(self.variance_sums / max(self.weight, 1.0), 0.0))

    def correlation(self) -> np.ndarray:
        """``(M, n_max, n_max)`` regressor correlations, 0 where a regressor did not vary."""
        return _correlation(self.comoment)


def _correlation(c: np.ndarray) -> np.ndarray:
    """``c_ij / sqrt(c_ii c_jj)`` of a stack of matrices, 0 where a diagonal is not positive
    (or NaN)."""
    d = c.diagonal(0, 1, 2)
    s = np.sqrt(np.where(d > 0.0, d, np.inf))
    with np.errstate(invalid="ignore"):
        rho = c / (s[:, :, None] * s[:, None, :])
    return np.where(np.isfinite(rho), rho, 0.0)


@dataclass(frozen=True)
class Problem:
    """Why (some of) a model's parameters are not identifiable, in figures (:mod:`.alerts` says
    it in words). ``kind``: ``"no_fit"`` (figure R^2, NaN for a constant output; limit
    ``min_r_squared``), ``"not_excited"`` (the regressors, figures their standard deviations,
    limits their resolutions, in ``units``), ``"noise"`` (one regressor, figures its standard
    deviation and its sensor noise's, limit ``min_noise_ratio``, in ``units``) or ``"collinear"``
    (two regressors, figure the correlation of their estimates, limit ``max_correlation``); for a model not ready yet
    ``"constant"`` (regressors that did not move, as ``"not_excited"``) or ``"correlated"`` (the
    two most correlated regressors, figure their correlation in the data). ``samples``: the
    samples the figures are from."""

    kind: str
    regressors: tuple[str, ...]
    figures: tuple[float, ...]
    limits: tuple[float, ...]
    units: tuple[str, ...] = ()
    samples: int = 0


class IdentifiabilityMonitor:
    """The tests of the module docstring for ``M`` models of ``regressors`` (names per model)
    with ``units`` (:data:`ANGLE`, :data:`NONDIMENSIONAL` or :data:`BIAS` per regressor), for an
    estimator of forgetting factor ``forgetting``.

    Per sample the estimator used: :meth:`add` its regressors ``(M, n_max)`` and outputs
    ``(M,)``, then :meth:`restrict` takes the parameters that are not identifiable out of the
    sample's convergence flags. The judgement reads the bank (its corrected and conventional
    covariances, Eq. 16's ``R_k(0)``) and is made when a flag needs it, else when it is read
    (:attr:`identifiable`, :meth:`problems`, :meth:`report`): the same numbers either way, at
    no cost while nothing is flagged. ``output_sum`` and ``output_sum_squares`` (weighted
    ``f^(k-j)``, the bank's ``n_k`` their weight) give R^2 and go into the state file."""

    def __init__(self, regressors: Sequence[Sequence[str]], units: Sequence[Sequence[str | None]],
                 config: IdentifiabilityConfig = IdentifiabilityConfig(), forgetting: float = 1.0) -> None:
        self.config = config
        self.regressors = [tuple(r) for r in regressors]
        sizes = [len(r) for r in self.regressors]
        m, n = len(sizes), max(sizes)
        self.shape = (m, n)
        self.real = np.arange(n) < np.array(sizes)[:, None]
        self.bias = np.zeros((m, n), dtype=bool)
        self.units = np.full((m, n), "", dtype=object)
        self.resolution = np.full((m, n), np.nan)
        for j, row in enumerate(units):
            for i, unit in enumerate(row):
                self.bias[j, i] = unit is BIAS
                self.units[j, i] = "" if unit is BIAS else unit
                self.resolution[j, i] = config.resolution(unit)
        slope = self.real & ~self.bias
        self._pairs = slope[:, :, None] & slope[:, None, :] & ~np.eye(n, dtype=bool)
        self._variance_floor = self.resolution**2  # NaN for the bias and padding: never flat
        self._noise_ratio = config.min_noise_ratio
        self._slopes = self.real & ~self.bias
        self._max_square = config.max_correlation**2
        self._unexplained = 1.0 - config.min_r_squared  # R^2 >= min  <=>  R_k(0) <= (1 - min) var(z)
        self._nothing = np.zeros((m, n), dtype=bool)
        self._padding = ~self.real
        self._square = np.zeros((m, n, n))  # scratch of the collinearity test
        self._bound = np.zeros((m, n, n))
        self._beyond = np.zeros((m, n, n), dtype=bool)
        self.forgetting = float(forgetting)
        self.stats = RegressorStatistics((m, n), forgetting)
        self.reset()

    def reset(self) -> None:
        """Forget the data (with the estimator)."""
        self.stats.reset()
        m, n = self.shape
        self.output_sum = np.zeros(m)
        self.output_sum_squares = np.zeros(m)
        self._bank: EstimatorBank | None = None
        self.ready = np.zeros(m, dtype=bool)
        self._judged = True
        self._covariance = np.zeros((m, n, n))
        self.collinear = self.not_excited = self.noisy = self._identifiable = self._nothing
        self.no_fit = np.zeros(m, dtype=bool)
        self.held_back = self._nothing

    def resume(self, output_sum: np.ndarray, output_sum_squares: np.ndarray) -> None:
        """Continue from a state file's output sums; the regressor statistics start afresh."""
        self.reset()
        self.output_sum = np.array(output_sum, dtype=float)
        self.output_sum_squares = np.array(output_sum_squares, dtype=float)

    def restart_chain(self) -> None:
        """The next sample does not follow the last one (a dropout, a new timeline): the
        sensor-noise estimate's second differences start afresh."""
        self.stats.restart_chain()

    def add(self, x: np.ndarray, z: np.ndarray) -> None:
        """A sample the estimator used: regressors ``(M, n_max)``, outputs ``(M,)``."""
        self.stats.add(x)
        if self.forgetting != 1.0:
            self.output_sum *= self.forgetting
            self.output_sum_squares *= self.forgetting
        self.output_sum += z
        self.output_sum_squares += z * z

    def fit(self, bank: EstimatorBank) -> np.ndarray:
        """R^2 of every model now (:func:`r_squared`), NaN where undefined or not ready."""
        return r_squared(bank.residual_variances(), self.output_sum, self.output_sum_squares, bank.n_eff)

    def restrict(self, flags: np.ndarray, model_flags: np.ndarray, bank: EstimatorBank,
                 ready: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The convergence flags ``(M, n_max)``, ``(M,)`` of the sample ``bank`` just took
        without the parameters that are not identifiable (a model is flagged when all its
        parameters still are); ``ready``: the models whose outputs are published.
        :attr:`held_back` keeps the flags taken out."""
        self._bank, self.ready, self._judged = bank, ready, False
        if not np.logical_or.reduce(flags, axis=None):
            self.held_back = self._nothing
            return flags, model_flags
        ok = self._judge()
        self.held_back = np.greater(flags, ok)  # (flagged and not identifiable)
        return flags & ok, model_flags & np.logical_and.reduce(ok | self._padding, axis=1)

    def judge(self, bank: EstimatorBank, ready: np.ndarray) -> np.ndarray:
        """``identifiable`` ``(M, n_max)`` of ``bank``'s current sample (module docstring)."""
        self._bank, self.ready, self._judged = bank, ready, False
        return self._judge()

    @property
    def identifiable(self) -> np.ndarray:
        """``(M, n_max)``: the parameters identifiable at the last sample (False on padding and
        models not ready)."""
        return self._judge()

    @property
    def correlation(self) -> np.ndarray:
        """``(M, n_max, n_max)`` correlations of the parameter estimates at the last sample
        (0 where undefined)."""
        self._judge()
        return _correlation(self._covariance)

    @property
    def r_squared(self) -> np.ndarray:
        """``(M,)`` R^2 at the last sample (NaN where undefined or not ready)."""
        return self.fit(self._bank) if self._bank is not None else np.full(self.shape[0], np.nan)

    def _judge(self) -> np.ndarray:
        """The three tests on the pending sample, once (a few vectorised steps, no division)."""
        bank = self._bank
        if self._judged or bank is None:
            return self._identifiable
        ready = self.ready
        c = bank.covariance_all("corrected")  # NaN off the ready models' blocks
        d = c.diagonal(0, 1, 2)
        if np.fmin.reduce(d, axis=None) <= 0.0:  # a ready model whose corrected variances are zero fits exactly:
            exact = ready & ~np.logical_or.reduce(d > 0.0, axis=1)  # its correlations: (X'X)^-1's, the conventional
            if np.logical_or.reduce(exact):  # (zero variances of a model withheld: nothing to replace)
                c = np.where(exact[:, None, None], bank.covariance_all("conventional"), c)
                d = c.diagonal(0, 1, 2)
        self._covariance = c
        # |rho_ij| > max  <=>  c_ij^2 > max^2 c_ii c_jj  (NaN compares False)
        bound = np.multiply(d[:, :, None], d[:, None, :], out=self._bound)
        bound *= self._max_square
        beyond = np.greater(np.multiply(c, c, out=self._square), bound, out=self._beyond)
        self.collinear = np.logical_or.reduce(np.logical_and(beyond, self._pairs, out=beyond), axis=2)
        stats = self.stats
        weight = max(stats.weight, 1.0)
        variance_sums = stats.variance_sums
        flat = variance_sums <= self._variance_floor * weight
        # A regressor that moves no more than its own sensor noise (var <= R sigma^2): not excited.
        self.noisy = self._nothing
        if self._noise_ratio > 0.0 and stats.noise_weight > 0.0:
            noisy = variance_sums * (6.0 * stats.noise_weight) <= (self._noise_ratio * weight) * stats.noise_sums
            noisy &= self._slopes
            self.noisy = np.greater(noisy, flat, out=noisy)  # (and not flat)
            flat |= noisy
        if np.logical_or.reduce(flat, axis=None):  # the bias is confounded with a flat regressor whose mean is off zero
            offset = np.logical_or.reduce(flat & (np.abs(stats.mean) > self.resolution), axis=1, keepdims=True)
            flat |= self.bias & offset
        self.not_excited = flat
        n = max(bank.n_eff, 1e-300)
        mean_square = self.output_sum_squares / n
        var = mean_square - np.square(self.output_sum / n)
        fits = bank.residual_variances() <= self._unexplained * var
        fits &= var > _CONSTANT_OUTPUT * mean_square  # not ready (R_k(0) NaN) or a constant output: no fit
        self.no_fit = ~fits
        fits &= ready
        ok = np.greater(self.real, flat | self.collinear)  # (real and neither)
        ok &= fits[:, None]
        self._identifiable, self._judged = ok, True
        return ok

    # ------------------------------------------------------------------ reporting
    def problems(self, j: int, named_after: int = 0) -> list[Problem]:
        """Why model ``j``'s parameters are not all identifiable at the last judgement, most
        fundamental first (empty when they are); for a model not ready, once ``named_after``
        samples have not initialized it, what in the data keeps its regressors from being
        informative (empty when nothing is named)."""
        self._judge()
        if not self.ready[j]:
            if self._bank is not None and self._bank.initialized[j]:
                return []  # initialized, not yet published (the publication rule): nothing wrong
            return self._not_ready(j) if self.stats.samples >= max(named_after, 1) else []
        cfg, names, n = self.config, self.regressors[j], len(self.regressors[j])
        out = []
        samples = self.stats.samples
        if self.no_fit[j]:
            out.append(Problem("no_fit", (), (float(self.r_squared[j]),), (cfg.min_r_squared,), samples=samples))
        flat = [i for i in range(n) if self.not_excited[j, i] and not self.bias[j, i] and not self.noisy[j, i]]
        if flat:
            out.append(self._flat(j, flat))
        out.extend(self._noise(j, i) for i in range(n) if self.noisy[j, i])
        pair = self._worst_pair(j, self.correlation[j], self._pairs[j])
        if pair is not None and abs(pair[2]) > cfg.max_correlation:
            a, b, r = pair
            out.append(Problem("collinear", (names[a], names[b]), (r,), (cfg.max_correlation,), samples=samples))
        return out

    def _flat(self, j: int, which: list[int], kind: str = "not_excited") -> Problem:
        std, names = self.stats.std[j], self.regressors[j]
        return Problem(kind, tuple(names[i] for i in which), tuple(float(std[i]) for i in which),
                       tuple(float(self.resolution[j, i]) for i in which), tuple(str(self.units[j, i]) for i in which),
                       self.stats.samples)

    def _noise(self, j: int, i: int) -> Problem:
        noise = math.sqrt(max(float(self.stats.noise_variance[j, i]), 0.0))
        return Problem("noise", (self.regressors[j][i],), (float(self.stats.std[j, i]), noise),
                       (self._noise_ratio,), (str(self.units[j, i]),), self.stats.samples)

    def _worst_pair(self, j: int, rho: np.ndarray, pairs: np.ndarray) -> tuple[int, int, float] | None:
        a = np.where(pairs, np.abs(rho), -1.0)
        i, k = divmod(int(np.argmax(a)), a.shape[1])
        return None if a[i, k] < 0 else (i, k, float(rho[i, k]))

    def _not_ready(self, j: int) -> list[Problem]:
        """A model still waiting for its exact initialization: regressors that never moved,
        else the two most correlated ones in the data (their correlation)."""
        n = len(self.regressors[j])
        std = self.stats.std[j]
        flat = [i for i in range(n) if not self.bias[j, i] and std[i] <= self.resolution[j, i]]
        if flat:
            return [self._flat(j, flat, "constant")]
        slope = self.real[j] & ~self.bias[j]
        pairs = slope[:, None] & slope[None, :] & ~np.eye(self.shape[1], dtype=bool)
        pair = self._worst_pair(j, self.stats.correlation()[j], pairs)
        if pair is None:
            return []
        a, b, r = pair
        names = self.regressors[j]
        return [Problem("correlated", (names[a], names[b]), (r,), (self.config.max_correlation,),
                        samples=self.stats.samples)]

    def report(self, j: int, names: Sequence[str]) -> dict:
        """Model ``j``'s figures for ``/diagnostics`` (parameters ``names``): ``identifiable``
        (every parameter), ``not_identifiable`` and ``held_back`` (the parameters whose
        convergence flag was taken out at the last sample), ``max_parameter_correlation`` (the
        largest magnitude over slope pairs, with its sign) and ``excitation.<regressor>`` (the
        standard deviation since the start, in its unit) and ``noise.<regressor>`` (its sensor
        noise's standard deviation from its second differences)."""
        n = len(names)
        ok = self.identifiable[j, :n]
        out: dict = {
            "identifiable": bool(ok.all()),
            "not_identifiable": ",".join(p for p, good in zip(names, ok.tolist(), strict=True) if not good),
            "held_back": ",".join(p for p, held in zip(names, self.held_back[j, :n].tolist(), strict=True) if held),
        }
        pair = self._worst_pair(j, self.correlation[j], self._pairs[j])
        if pair is not None and self.ready[j]:
            out["max_parameter_correlation"] = round(pair[2], 6)
        std, noise = self.stats.std[j], np.sqrt(self.stats.noise_variance[j])
        for i, name in enumerate(self.regressors[j]):
            if not self.bias[j, i]:
                out[f"excitation.{name}"] = float(f"{std[i]:.4g}")
                if math.isfinite(noise[i]):
                    out[f"noise.{name}"] = float(f"{noise[i]:.4g}")
        return out
