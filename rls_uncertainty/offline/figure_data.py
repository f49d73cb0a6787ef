"""What a replay's figures need, collected as the run goes in bounded memory (numpy only).

:class:`FigureData` receives every estimator sample of a run with its regression row and
keeps, whatever the recording's length:

* per model, the measured coefficient ``z_k`` (Eq. 1), the modelled one ``x_k' theta_k``
  (the estimate of that sample, Eq. 15c) and the regressors, at most ``2 * capacity``
  evenly spaced samples (:class:`.results.History`): the time histories of Figs. 3-4 and the
  excitation onset (:func:`excitation_start`);
* per model, the power spectral density of the residual ``z_k - x_k' theta_k`` over every
  sample in which the model was ready (:class:`WelchSpectrum`, Fig. 4);
* per model, the lagged sums of the regression rows (:class:`LaggedProducts`), from which the
  batch least-squares estimate, the batch residual autocorrelation (Eq. 10) and the batch
  conventional (Eq. 13) and corrected (Eqs. 8-11) standard errors follow for every number of
  retained lags up to :data:`SWEEP_MAX_LAGS` (Fig. 7) -- the quantities
  :func:`.estimator.batch.batch_estimate` computes from the stored rows, computed from sums
  that do not grow with the recording;
* per parameter, the stamp from which its convergence flag has stayed set.

The drawing is in :mod:`.figures`.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING, Any, NamedTuple

import numpy as np
from numpy.lib.stride_tricks import sliding_window_view

from ..estimator.lag_window import lag_weights
from .results import History

if TYPE_CHECKING:  # annotations only
    from ..datapath.pipeline import Pipeline, SampleOutput

__all__ = ["SWEEP_MAX_LAGS", "SPECTRUM_SEGMENT", "EXCITED_FRACTION", "LaggedProducts", "BatchSweep",
           "WelchSpectrum", "FitStatistics", "excitation_start", "ModelFinal", "FigureData"]

# The most retained lags of the Fig. 7 sweep: 20 s at 50 Hz, beyond the whole of the paper's
# 12 s maneuver (about 600 samples). Cost per sample and model: (lags + 1) (n + 1)^2 products.
SWEEP_MAX_LAGS = 1000
# Samples per segment of the residual's Welch spectrum (0.2 Hz resolution at 50 Hz).
SPECTRUM_SEGMENT = 256
# A regressor is excited from the first sample at which it has moved this fraction of its
# range over the run away from its first value (docs/tools.md, "Figures").
EXCITED_FRACTION = 0.2


class BatchSweep:
    """Batch least squares of one model from :class:`LaggedProducts`, for every number of
    retained lags: ``theta`` (Eq. 6), ``autocorrelation`` ``R(i)`` of the batch residuals
    (Eq. 10, ``i = 0..max_lag``), ``se_conventional`` (Eq. 13) and :meth:`se_corrected`
    (Eqs. 8-11 with lags ``0..L``). ``samples``: N."""

    def __init__(self, G: np.ndarray, samples: int) -> None:
        n = G.shape[1] - 1
        self.samples = samples
        A = G[0, :n, :n]
        self.D = np.linalg.inv(A)  # Eq. 6: (X'X)^-1
        self.theta = self.D @ G[0, :n, n]  # Eq. 6
        a = np.append(-self.theta, 1.0)  # v_j = a' [x_j; z_j] (Eq. 7)
        self.autocorrelation = np.einsum("a,kab,b->k", a, G, a) / samples  # Eq. 10
        # The lag-k terms of Eq. 11's double sum: sum_{|j-l| = k} x_j x_l'.
        S = G[:, :n, :n] + G[:, :n, :n].transpose(0, 2, 1)
        S[0] = A
        self._terms = S
        self.se_conventional = np.sqrt(self.autocorrelation[0] * np.diag(self.D))  # Eqs. 13-14

    @property
    def max_lag(self) -> int:
        return self.autocorrelation.size - 1

    def se_corrected(self, lags: int, window: str = "truncated") -> np.ndarray:
        """Corrected standard errors with lags ``0..min(lags, max_lag)`` weighted by the lag
        window (Eq. 22; ``"all"`` when ``lags >= N - 1``): the square roots of the diagonal of
        ``D [sum_k c_k R(k) S_k] D`` (Eq. 11)."""
        L = min(int(lags), self.max_lag)
        c = lag_weights(L, window, self.max_lag + 1) * self.autocorrelation
        middle = np.tensordot(c, self._terms, axes=1)
        return np.sqrt(np.maximum(np.diag(self.D @ middle @ self.D), 0.0))


class LaggedProducts:
    """Streamed lagged sums of one model's regression rows ``w_j = [x_j; z_j]`` (``n``
    regressors and the measured output): ``G(k) = sum_j w_j w_{j-k}'`` for ``k = 0..max_lag``.
    Rows are added one at a time and folded in blocks of ``block`` (one batched matrix
    product per block); memory ``(max_lag + block) (n + 1)`` rows plus the sums."""

    def __init__(self, n: int, max_lag: int = SWEEP_MAX_LAGS, block: int = 128) -> None:
        self.n, self.max_lag, self.block = n, max_lag, block
        self.G = np.zeros((max_lag + 1, n + 1, n + 1))
        self._buf = np.zeros((max_lag + block, n + 1))  # the last max_lag rows, then the block
        self._fill = 0
        self.count = 0

    def add(self, x: np.ndarray, z: float) -> None:
        row = self._buf[self.max_lag + self._fill]
        row[: self.n] = x
        row[self.n] = z
        self._fill += 1
        self.count += 1
        if self._fill == self.block:
            self._fold()

    def _fold(self) -> None:
        m, L = self._fill, self.max_lag
        if not m:
            return
        block = self._buf[L : L + m]
        # Window i is the block shifted back by L - i samples: prod[i] = window_i' block.
        windows = sliding_window_view(self._buf[: L + m], m, axis=0)  # (L + 1, n + 1, m)
        prod = windows @ block
        self.G += prod[::-1].transpose(0, 2, 1)  # G(k)[a, b] += sum_j w_j[a] w_{j-k}[b]
        self._buf[:L] = self._buf[m : m + L].copy()
        self._fill = 0

    def sweep(self) -> BatchSweep | None:
        """The batch fit of the rows so far (lags up to ``min(max_lag, N - 1)``), or None
        while ``X'X`` is singular (fewer rows than regressors, or a regressor never moved)."""
        self._fold()
        N = self.count
        if N <= self.n:
            return None
        G = self.G[: min(self.max_lag, N - 1) + 1]
        if np.linalg.cond(G[0, : self.n, : self.n]) > 1e12:
            return None
        return BatchSweep(G, N)


def _hann(n: int) -> np.ndarray:
    """The periodic Hann window (what ``scipy.signal.get_window("hann", n)`` gives)."""
    return 0.5 - 0.5 * np.cos(2.0 * np.pi * np.arange(n) / n)


class WelchSpectrum:
    """One-sided power spectral density of a signal fed sample by sample (Welch's method:
    periodic Hann window of ``segment`` samples, half overlap, each segment's mean removed,
    periodograms averaged), in signal units squared per Hz at sample ``rate`` (Hz). With
    fewer samples than a segment, one periodogram of what there is. Memory: one segment."""

    def __init__(self, rate: float, segment: int = SPECTRUM_SEGMENT) -> None:
        self.rate, self.segment, self.step = rate, segment, segment // 2
        self._buf = np.zeros(segment)
        self._fill = 0
        self._sum = np.zeros(segment // 2 + 1)
        self.segments = 0

    def add(self, value: float) -> None:
        self._buf[self._fill] = value
        self._fill += 1
        if self._fill == self.segment:
            self._sum += self._periodogram(self._buf)
            self.segments += 1
            self._buf[: self.segment - self.step] = self._buf[self.step :].copy()
            self._fill = self.segment - self.step

    def _periodogram(self, x: np.ndarray) -> np.ndarray:
        w = _hann(x.size)
        P = np.abs(np.fft.rfft(w * (x - x.mean()))) ** 2 / (self.rate * np.dot(w, w))
        P[1 : (x.size + 1) // 2] *= 2.0  # one-sided: every bin but 0 and Nyquist twice
        return P

    def psd(self) -> tuple[np.ndarray, np.ndarray]:
        """``(frequencies in Hz, PSD)``; empty with fewer than 8 samples."""
        if self.segments:
            return np.fft.rfftfreq(self.segment, 1.0 / self.rate), self._sum / self.segments
        if self._fill < 8:
            return np.zeros(0), np.zeros(0)
        return np.fft.rfftfreq(self._fill, 1.0 / self.rate), self._periodogram(self._buf[: self._fill])


class FitStatistics:
    """The coefficient of determination of a model's fit, accumulated sample by sample:
    ``R^2 = 1 - sum v^2 / sum (z - mean z)^2`` over the samples with an estimate (``v`` the
    residual with that sample's estimate)."""

    def __init__(self) -> None:
        self.n = 0
        self.sum_z = self.sum_z2 = self.sum_v2 = 0.0

    def add(self, z: float, v: float) -> None:
        self.n += 1
        self.sum_z += z
        self.sum_z2 += z * z
        self.sum_v2 += v * v

    @property
    def r_squared(self) -> float:
        total = self.sum_z2 - self.sum_z * self.sum_z / self.n if self.n > 1 else 0.0
        return 1.0 - self.sum_v2 / total if total > 0.0 else float("nan")


def excitation_start(t: np.ndarray, X: np.ndarray, fraction: float = EXCITED_FRACTION) -> float:
    """The time from which every regressor of a model that moves has been excited: for each
    column of ``X`` (samples x regressors; NaN rows ignored) that is not constant, the first
    time it is ``fraction`` of its range away from its first value; the latest of these
    (``t[0]`` when nothing moves, NaN without data)."""
    ok = np.isfinite(X).all(axis=1)
    t, X = t[ok], X[ok]
    if not t.size:
        return float("nan")
    start = float(t[0])
    for col in X.T:
        span = float(col.max() - col.min())
        if span > 0.0:
            moved = np.abs(col - col[0]) >= fraction * span
            start = max(start, float(t[int(np.argmax(moved))]))
    return start


class ModelFinal(NamedTuple):
    """A model's state at the end of a run, for the figures: ``autocorrelation`` the recursive
    ``R_k(i)`` (Eq. 17, None when the model never became ready), ``samples`` k, ``lags`` the
    retained lags of its last sample (Eq. 22), ``lag_setting`` the configured ``estimator.lags``
    (an integer, ``"all"`` or ``"auto"``), ``window`` the lag window."""

    autocorrelation: np.ndarray | None
    samples: int
    lags: int
    lag_setting: Any
    window: str


class FigureData:
    """Everything the replay's figures draw besides the estimates' history (module
    docstring), for the models ``outputs`` with regressors ``regressors`` (per model) and
    parameter names ``parameters`` at sample ``rate`` (Hz). :meth:`add` after each message
    with the samples it produced and the regression rows the pipeline recorded for them;
    :meth:`finish` at the end. A restarted estimator starts the collection afresh."""

    def __init__(self, outputs: Sequence[str], regressors: Sequence[Sequence[str]],
                 parameters: Sequence[Sequence[str]], rate: float, capacity: int | None = None,
                 max_lag: int = SWEEP_MAX_LAGS) -> None:
        self.outputs, self.regressors = tuple(outputs), [tuple(r) for r in regressors]
        self.parameters = [tuple(p) for p in parameters]
        self.sizes = [len(r) for r in self.regressors]
        self.rate, self.capacity, self.max_lag = rate, capacity, max_lag
        # The real parameters among a SampleOutput's (M, n_max) rows.
        n_max = max(self.sizes)
        self._real = np.arange(n_max) < np.array(self.sizes)[:, None]
        self.finals: list[ModelFinal] = []
        # Per model: the corrected standard errors of its last ready sample.
        self.last_se: list[np.ndarray | None] = [None] * len(self.sizes)
        self._bank: object = None
        self.reset()

    def reset(self) -> None:
        """Forget everything collected (the estimator restarted)."""
        # Per model: measured, modelled, then each regressor (History's estimate column).
        names = [[f"{m}:measured", f"{m}:model", *(f"{m}:{r}" for r in regs)]
                 for m, regs in zip(self.outputs, self.regressors, strict=True)]
        self.history = History(names, self.capacity)
        self._width = sum(len(n) for n in names)
        self.spectra = [WelchSpectrum(self.rate) for _ in self.outputs]
        self.fits = [FitStatistics() for _ in self.outputs]
        self.products = [LaggedProducts(n, self.max_lag) for n in self.sizes]
        count = int(self._real.sum())
        self.converged_since = np.full(count, -1, dtype=np.int64)  # stamp, -1: not converged now
        self.last_se = [None] * len(self.sizes)
        self._nan = np.full(self._width, np.nan)
        self._false = np.zeros(self._width, dtype=bool)

    def add(self, pipe: Pipeline, outs: Sequence[SampleOutput],
            rows: Sequence[tuple[int, np.ndarray, np.ndarray]]) -> None:
        """The samples ``outs`` one message produced and the regression rows recorded for them:
        the last samples and the last rows pair up (earlier samples went before a restart;
        earlier rows, with ``estimator.algorithm iv``, waited for their instruments and have
        no output of their own)."""
        if pipe.bank is not self._bank:
            if self._bank is not None:
                self.reset()
            self._bank = pipe.bank
        k = min(len(outs), len(rows))
        for out, (t, X, z) in zip(outs[len(outs) - k:], rows[len(rows) - k:], strict=True):
            if out.stamp_ns == t:
                self._sample(out, X, z)

    def _sample(self, out: SampleOutput, X: np.ndarray, z: np.ndarray) -> None:
        values = np.empty(self._width)
        k = 0
        for j, n in enumerate(self.sizes):
            x = X[j, :n]
            model = float(x @ out.theta[j, :n])  # NaN while the model is not ready
            values[k], values[k + 1] = z[j], model
            values[k + 2 : k + 2 + n] = x
            k += 2 + n
            self.products[j].add(x, float(z[j]))
            if out.ready[j]:
                self.spectra[j].add(float(z[j]) - model)
                self.fits[j].add(float(z[j]), float(z[j]) - model)
                self.last_se[j] = out.se[j, :n]
        self.history.append(out.stamp_ns, values, self._nan, self._nan, self._false, out.ready)
        flags = out.converged[self._real]
        since = self.converged_since
        since[~flags] = -1
        since[flags & (since < 0)] = out.stamp_ns

    def finish(self, pipe: Pipeline) -> None:
        """Each model's end-of-run state (:class:`ModelFinal`)."""
        bank, options = pipe.bank, pipe.config.estimator
        lags = bank.lags_used
        self.finals = [ModelFinal(bank.autocorrelation(j) if bank.ready[j] else None, bank.n_samples,
                                  int(lags[j]), options.lags, options.window) for j in range(len(self.sizes))]

    def coefficient(self, j: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Model ``j``'s kept samples: stamps (ns), measured and modelled coefficient."""
        k = sum(2 + n for n in self.sizes[:j])
        return self.history.stamps_ns, self.history.column(k)[0], self.history.column(k + 1)[0]

    def regressor_history(self, j: int) -> np.ndarray:
        """Model ``j``'s regressors at the kept samples, ``(samples, n)``."""
        k = sum(2 + n for n in self.sizes[:j]) + 2
        return np.column_stack([self.history.column(k + i)[0] for i in range(self.sizes[j])])
