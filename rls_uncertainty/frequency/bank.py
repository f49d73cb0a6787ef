"""The real-time frequency-domain estimator: ``M`` equation-error models on one recursive
Fourier transform (docs/frequency.md; Morelli, JGCD 23(5), 2000).

Per sample (:meth:`FrequencyBank.update`): the first sample is subtracted from every signal
(the trim, the mean of the first ``trim_samples``, is applied to the transforms when they are
used, exactly: it is a constant), the transforms are advanced (Eq. F2, ``K (p + 1)`` complex
multiply-adds per model) and so are the lag-product sums (Eq. F9, ``(L + 1) (p + 1)^2``).
Every ``every`` samples, when asked (:meth:`FrequencyBank.theta_all` and the others): the
complex least-squares solution (F4), the conventional covariance (F5), the residual
autocovariance of the record's least-squares residuals (F9) corrected for the fit's degrees of
freedom (F10) and the corrected covariance in closed form (F7-F8). Its numbers are those of
:func:`.reference.frequency_reference` at every sample (the tests hold them together).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
import numpy.typing as npt

from ..errors import ConfigError, EstimatorNotReady, NonFiniteInput
from ..estimator import COVARIANCE_KINDS
from .covariance import PairGeometry, middle
from .instrumental import instrumental_system
from .lags import LagSums, residual_autocovariance
from .options import FrequencyOptions
from .transform import RecursiveFourierTransform

__all__ = ["FrequencyBank", "EXACT_FIT", "LARGEST_INPUT"]

FloatArray = npt.NDArray[np.float64]
BoolArray = npt.NDArray[np.bool_]

# An exact fit: R(0) at most this fraction of the variance of the model output x' theta. Its
# corrected covariance is rounding of either sign: the model is not ready at that evaluation.
EXACT_FIT = 1e-12
# Inputs beyond this magnitude are refused: their products in the lag sums would overflow.
LARGEST_INPUT = 1e100
_KIND_INDEX: dict[str, int] = {kind: i for i, kind in enumerate(COVARIANCE_KINDS)}  # corrected 0, conventional 1


class FrequencyBank:
    """``M`` models ``z = x' theta`` (no bias term: the trim is subtracted and the grid leaves out
    0 Hz) estimated in the frequency domain (docs/frequency.md).

    Parameters
    ----------
    sizes:
        Number of regressors of each model, without the bias (``"1"``) column of Eq. 2:
        e.g. ``(2, 3)`` for the T-2's ``C_Z`` (``alpha, delta_e``) and ``C_m`` (``alpha,
        q_hat, delta_e``).
    options:
        :class:`~.options.FrequencyOptions` (grid, lags, evaluation interval).
    instruments:
        Estimate with instrumental variables (Eqs. F11-F12): :meth:`update` then takes one
        instrument per regressor, laid out like ``X``, transformed like the regressors.

    :meth:`update` takes ``X`` ``(M, max(sizes))`` (model ``j``'s regressors in its first
    ``sizes[j]`` columns) and ``z`` ``(M,)``, one row per sample at ``options.rate_hz``.
    """

    def __init__(self, sizes: Sequence[int], options: FrequencyOptions, instruments: bool = False) -> None:
        self.sizes = tuple(int(s) for s in sizes)
        if not self.sizes or min(self.sizes) < 1:
            raise ValueError(f"every model needs at least one regressor, got sizes={self.sizes}")
        self.options = options
        self.frequencies = options.frequencies()
        K, p_max = self.frequencies.size, max(self.sizes)
        if K <= p_max:
            raise ConfigError(
                f"frequency grid has {K} frequencies, a model has {p_max} regressors: the conventional "
                "covariance needs more frequencies than parameters (lower f_step or widen f_min..f_max)"
            )
        M, q = len(self.sizes), p_max + 1
        self._geometry = PairGeometry(2.0 * np.pi * self.frequencies / float(options.rate_hz))
        self._columns: BoolArray = np.arange(q)[None, :] <= np.array(self.sizes)[:, None]  # z and real x
        # The transformed signals: z, x and (with instruments) w; lag sums of (z, x) only.
        self._padding: BoolArray = ~np.concatenate([self._columns] + [self._columns[:, 1:]] * instruments, axis=1)
        width = self._padding.shape[1]
        self._cross: FloatArray | None = np.zeros((M, p_max, q + 1)) if instruments else None  # sum w (u, 1)'
        self._transform = RecursiveFourierTransform(self.frequencies, options.rate_hz, (M, width))
        self._lags = LagSums(M, q, options.n_lags)
        self._first: FloatArray | None = None
        self._trim_sum: FloatArray = np.zeros((M, width))  # sum of the first trim_samples samples (first subtracted)
        self._due = False
        self.repairs = 0
        self._theta: FloatArray = np.full((M, p_max), np.nan)
        self._cov: FloatArray = np.full((2, M, p_max, p_max), np.nan)
        self._se: FloatArray = np.full((2, M, p_max), np.nan)  # both kinds, published or not
        self._published_se: FloatArray = np.full((2, M, p_max), np.nan)
        self._R: FloatArray = np.full((M, 1), np.nan)
        self._output_variance: FloatArray = np.full(M, np.nan)
        self._ready: BoolArray = np.zeros(M, dtype=bool)
        self._solved: BoolArray = np.zeros(M, dtype=bool)
        self._evaluated_at = 0
        # Fixed masks of the evaluation: the parameters, the padding's diagonal and blocks.
        real = self._columns[:, 1:]
        self._real: BoolArray = real
        self._pad_diagonal: BoolArray = ~real[:, :, None] & np.eye(p_max, dtype=bool)
        self._pad_square: BoolArray = ~(real[:, :, None] & real[:, None, :])
        self._pad_unit: FloatArray = self._pad_diagonal.astype(np.float64)  # added to Re(X^H X)[x, x]
        self._real_square: FloatArray = (~self._pad_square).astype(np.float64)  # multiplies A^-1
        self._none: BoolArray = np.zeros(M, dtype=bool)
        self._all: BoolArray = np.ones(M, dtype=bool)
        self._residual_dof: FloatArray = K - np.array(self.sizes, dtype=np.float64)
        # The publication rule: samples each model needs (its regressors and the bias, plus the windows).
        self.publish_at = np.array([options.publish_samples(s + 1) for s in self.sizes], dtype=np.int64)
        self._withheld: BoolArray = np.zeros(M, dtype=bool)

    # ------------------------------------------------------------------ per sample
    @property
    def n_samples(self) -> int:
        """Samples taken since the start or the last :meth:`reset`."""
        return self._lags.n

    def update(self, X: npt.ArrayLike, z: npt.ArrayLike, instruments: npt.ArrayLike | None = None) -> None:
        """Add one sample of every model (Eqs. F2, F9). A non-finite or too large value of a
        model's regressors, instruments or output raises :class:`NonFiniteInput` and leaves the
        state as it was (the sample is not counted: the transform's time runs on accepted samples)."""
        self.add(self.check(X, z, instruments))

    def check(self, X: npt.ArrayLike, z: npt.ArrayLike, instruments: npt.ArrayLike | None = None) -> FloatArray:
        """The sample as :meth:`add` takes it, ``(M, 1 + max(sizes))`` (``(M, 1 + 2 max(sizes))``
        with instruments): each model's output, its regressors, its instruments, zero padding;
        :class:`NonFiniteInput` for a value :meth:`update` refuses. Nothing changes: a caller
        that feeds another estimator too checks here first."""
        M, q = self._columns.shape
        if (instruments is None) != (self._cross is None):
            raise ValueError("instruments are given exactly when the bank was made with instruments=True")
        u = np.empty(self._padding.shape)
        u[:, 0] = np.asarray(z, dtype=np.float64).reshape(M)
        u[:, 1:q] = np.asarray(X, dtype=np.float64).reshape(M, q - 1)
        if instruments is not None:
            u[:, q:] = np.asarray(instruments, dtype=np.float64).reshape(M, q - 1)
        np.copyto(u, 0.0, where=self._padding)
        if np.abs(u).max() <= LARGEST_INPUT:  # NaN: False
            return u
        bad = ~(np.abs(u) <= LARGEST_INPUT).all(axis=1)
        if bad.any():
            raise NonFiniteInput(
                f"frequency estimator: models {np.flatnonzero(bad).tolist()} have a non-finite regressor or "
                f"output, or one beyond {LARGEST_INPUT:g}; sample refused"
            )
        return u

    def add(self, u: FloatArray) -> None:
        """Add a sample :meth:`check` returned (Eqs. F2, F9); ``u`` is consumed."""
        if self._first is None:
            self._first = u.copy()
        u -= self._first
        if self._lags.n < self.options.trim_samples:
            self._trim_sum += u
        self._transform.update(u)
        q = self._columns.shape[1]
        self._lags.update(u[:, :q])
        if self._cross is not None:  # sum_n w_n (u_n, 1)', the newest (u_n, 1) of the lag window
            self._cross += u[:, q:, None] * self._lags.window()[:, 0, None, :]
        if self._lags.n % self.options.every == 0:
            self._due = True

    def reset(self) -> None:
        """Start a new record: transforms, lag sums and results cleared."""
        self._transform.reset()
        self._lags.reset()
        self._first = None
        self._trim_sum[...] = 0.0
        if self._cross is not None:
            self._cross[...] = 0.0
        self._due = False
        self._theta[...] = np.nan
        self._cov[...] = np.nan
        self._se[...] = np.nan
        self._published_se[...] = np.nan
        self._R = np.full((len(self.sizes), 1), np.nan)
        self._output_variance[...] = np.nan
        self._ready[...] = False
        self._solved = np.zeros(len(self.sizes), dtype=bool)  # not in place: it may be a shared constant
        self._withheld[...] = False
        self._evaluated_at = 0

    # ------------------------------------------------------------------ evaluation
    def _evaluate(self) -> None:
        """Estimates and both covariances at the current sample (Eqs. F4-F12), if due."""
        if not self._due:
            return
        self._due = False
        N = self._lags.n
        self._evaluated_at = N
        S = self._trimmed()  # (M, q or q + p, K): transforms of z, x (and w), frequency-last
        q = self._columns.shape[1]
        X, W = S[:, 1:q].swapaxes(1, 2), S[:, q:].swapaxes(1, 2)  # (M, K, .) views
        # conj(U), U (M, K, q or q + p) the transforms by frequency, C-contiguous: the left factor
        # of X^H X (W^H X) and the rows of the residuals (conjugated: theta is real, |conj e| = |e|).
        Uc = np.conjugate(S.swapaxes(1, 2), order="C")
        if self._cross is None:
            G: FloatArray = (Uc.swapaxes(1, 2) @ S.swapaxes(1, 2)).real
            A, b = G[:, 1:, 1:] + self._pad_unit, G[:, 1:, 0]  # padded parameters (0 in G): theta = 0
            A_inv = _all_well_conditioned(A, self.options.init_condition) if N >= 2 else None
            if A_inv is not None:
                solved = self._all
            else:
                solved = _well_conditioned(A, self.options.init_condition) if N >= 2 else self._none
        else:  # Eq. F11
            A, b, WW, solved = instrumental_system(S, Uc, q, self._pad_diagonal, self.options.init_condition, N)
            A_inv = None
        all_solved = bool(solved.all())
        if A_inv is None:
            if not all_solved:
                A[~solved] = np.eye(A.shape[1])
            A_inv = np.linalg.inv(A).astype(np.float64, copy=False)
        A_inv *= self._real_square  # padding: 0
        theta = (A_inv @ b[:, :, None])[:, :, 0]
        # Eq. F5: s^2 = sum_k |Z_k - X_k theta|^2 / (K - p), of the conjugates (theta is real).
        E = (Uc[..., 0] - (Uc[..., 1:q] @ theta[:, :, None])[:, :, 0]).view(np.float64)
        s2 = (E[:, None, :] @ E[:, :, None])[:, 0, 0] / self._residual_dof
        cov = self._cov
        if self._cross is None:
            np.multiply(s2[:, None, None], A_inv, out=cov[1])
            unusable = self._corrected(X, A_inv, A_inv, theta, N, cov[0])
        else:  # Eq. F12: A^-1 [.] A^-T with the instruments in the middle
            A_invT = A_inv.swapaxes(1, 2)
            np.multiply(s2[:, None, None], A_inv @ WW @ A_invT, out=cov[1])
            unusable = self._corrected(W, A_inv, A_invT, theta, N, cov[0])
        self._theta = np.where(self._real if all_solved else solved[:, None] & self._real, theta, np.nan)
        if not all_solved:
            cov[:, ~solved] = np.nan
        rule = solved & (N >= self.publish_at)
        self._withheld = rule & unusable
        self._solved, self._ready = solved, rule & ~unusable
        # Both kinds' standard errors, and as published, once per evaluation.
        variances = np.maximum(np.diagonal(cov, axis1=2, axis2=3), 0.0)  # NaN stays NaN
        self._se = np.where(self._real, np.sqrt(variances), np.nan)
        self._published_se = np.where(self._ready[:, None], self._se, np.nan)

    def _trim_count(self) -> int:
        return min(self._lags.n, self.options.trim_samples)

    def _trimmed(self) -> npt.NDArray[np.complex128]:
        """The transforms with the trim subtracted (F1), frequency-last ``(M, signals, K)``: those
        of ``u - u_0`` (kept recursively) less ``dt (m - u_0) Gamma_k``, ``m`` the mean of the
        first samples, ``Gamma_k`` the sum of the phasors over the record (the transform of a
        constant). Without a trim (one sample) the transform's own sums, not to be written."""
        S = self._transform.frequency_last
        if self.options.trim_samples == 1:
            return S
        shift = self._trim_sum / max(self._trim_count(), 1)
        gamma = self._geometry.at(self._lags.n).gamma
        out: npt.NDArray[np.complex128] = S - self.options.dt * shift[:, :, None] * gamma[None, None, :]
        return out

    def _corrected(
        self, X: npt.NDArray[np.complex128], A_inv: FloatArray, right: FloatArray, theta: FloatArray, N: int,
        out: FloatArray,
    ) -> BoolArray:
        """Eqs. F7-F10 (F12): the residual autocovariance over the record (least-squares or
        instrumental-variable residuals, corrected for the fit's degrees of freedom), the
        closed-form sandwich ``A_inv [.] right`` of the transforms ``X`` (the instruments'), written
        to ``out``; returned: the models
        whose covariance means nothing at this evaluation: an exact fit (rounding of either
        sign), or a sandwich with a negative variance (its nearest positive semi-definite
        repair is zero or nearly so; counted in :attr:`repairs`)."""
        augmented = self._lags.augmented(reuse=True)  # nothing keeps it past this evaluation
        R, C0 = residual_autocovariance(augmented, self._columns, N, self.options.dof_correction, self._cross)
        self._R = R
        self._output_variance = C0[:, 0, 0] / N
        mid = middle(R, X, self._geometry.at(N), self._trim_count())
        mid *= self.options.dt**2
        np.matmul(A_inv @ mid, right, out=out)
        output_variance = (theta[:, None, :] @ C0[:, 1:, 1:] @ theta[:, :, None])[:, 0, 0] / N
        exact = R[:, 0] <= EXACT_FIT * output_variance
        variances = np.diagonal(out, axis1=1, axis2=2)  # padding: 0
        if not (variances < 0.0).any():
            return exact
        negative = (variances < 0.0).any(axis=1) & ~exact
        if negative.any():
            self.repairs += 1
        unusable: BoolArray = exact | negative
        return unusable

    # ------------------------------------------------------------------ results
    @property
    def evaluated_at(self) -> int:
        """The sample count of the results returned now (the last multiple of ``every``)."""
        self._evaluate()
        return self._evaluated_at

    @property
    def ready(self) -> BoolArray:
        """Models that publish at the last evaluation: well conditioned, past the publication
        rule (:attr:`publish_at` samples) and with a positive semi-definite corrected
        covariance that is not an exact fit's (:attr:`withheld` otherwise)."""
        self._evaluate()
        return self._ready.copy()

    @property
    def withheld(self) -> BoolArray:
        """Models withheld at the last evaluation although past the rule: an exact fit or a
        corrected covariance with a negative variance."""
        self._evaluate()
        return self._withheld.copy()

    @property
    def solved(self) -> BoolArray:
        """Models with a solution at the last evaluation (well conditioned), published or not:
        :meth:`theta`, :meth:`covariance` and the others answer for them."""
        self._evaluate()
        return self._solved.copy()

    def _require(self, j: int) -> None:
        if not self.solved[j]:
            raise EstimatorNotReady(f"frequency model {j} is not ready ({self.n_samples} samples)")

    def theta_all(self) -> FloatArray:
        """Published estimates ``(M, max(sizes))``; NaN for padding and models not :attr:`ready`."""
        self._evaluate()
        out: FloatArray = np.where(self._ready[:, None], self._theta, np.nan)
        return out

    def theta(self, j: int) -> FloatArray:
        self._require(j)
        return self._theta[j, : self.sizes[j]].copy()

    def standard_errors_all(self, kind: str = "corrected") -> FloatArray:
        """Published standard errors ``(M, max(sizes))``, the square roots of the covariance
        diagonals: ``"corrected"`` (Eq. F7) or ``"conventional"`` (Eq. F5); NaN for padding and
        models not :attr:`ready`."""
        index = self._kind(kind)
        self._evaluate()
        out: FloatArray = self._published_se[index].copy()
        return out

    def _standard_errors(self, kind: str) -> FloatArray:
        index = self._kind(kind)
        self._evaluate()
        se: FloatArray = self._se[index]
        return se

    def standard_errors(self, j: int, kind: str = "corrected") -> FloatArray:
        """Model ``j``'s standard errors, published or not (a negative variance as 0)."""
        self._require(j)
        return self._standard_errors(kind)[j, : self.sizes[j]].copy()

    def covariance(self, j: int, kind: str = "corrected") -> FloatArray:
        """Parameter covariance of model ``j`` (``sizes[j]`` square), published or not, as
        Eqs. F5 and F7-F8 give it (not repaired)."""
        index = self._kind(kind)
        self._require(j)
        p = self.sizes[j]
        return self._cov[index, j, :p, :p].copy()

    def autocorrelation(self, j: int) -> FloatArray:
        """``R(0..L)`` behind the corrected covariance of model ``j`` (Eqs. F9-F10)."""
        self._require(j)
        out: FloatArray = self._R[j].copy()
        return out

    def fit(self) -> tuple[FloatArray, FloatArray]:
        """``(R^2, rho_1)`` of every model ``(M,)`` at the last evaluation: ``1 - R(0) / var(z)``
        from the record's residual autocovariance (F9-F10) and output variance, and the
        residuals' lag-1 correlation ``R(1) / R(0)``; NaN where undefined."""
        self._evaluate()
        R, var = self._R, self._output_variance
        with np.errstate(divide="ignore", invalid="ignore"):
            r2: FloatArray = np.where(var > 0, 1.0 - R[:, 0] / var, np.nan)
            rho1: FloatArray = R[:, 1] / R[:, 0] if R.shape[1] > 1 else np.full(R.shape[0], np.nan)
        return r2, rho1

    def transforms(self) -> tuple[npt.NDArray[np.complex128], npt.NDArray[np.complex128]]:
        """``(Z, X)``: the transforms ``(M, K)`` and ``(M, K, max(sizes))`` of the outputs and
        regressors with the trim subtracted (Eq. F1), copies."""
        S = self._trimmed()
        return S[:, 0].copy(), S[:, 1:].swapaxes(1, 2).copy()

    @staticmethod
    def _kind(kind: str) -> int:
        index = _KIND_INDEX.get(kind)
        if index is None:
            raise ValueError(f"kind must be one of {COVARIANCE_KINDS}, got {kind!r}")
        return index

    def describe(self) -> dict[str, Any]:
        """The configuration, for logs and reports."""
        o = self.options
        return {
            "sizes": self.sizes, "rate_hz": o.rate_hz, "frequencies": self.frequencies.size,
            "f_min": float(self.frequencies[0]), "f_max": float(self.frequencies[-1]), "f_step": o.f_step,
            "trim_samples": o.trim_samples, "n_lags": o.n_lags, "every": o.every, "dof_correction": o.dof_correction,
            "instruments": self._cross is not None,
        }


def _all_well_conditioned(A: FloatArray, init_condition: float) -> FloatArray | None:
    """``A^-1`` when every model passes :func:`_well_conditioned` without its eigenvalues, else
    None. For ``S = D^-1/2 A D^-1/2`` (``D`` the diagonal; positive definite, unit diagonal,
    ``p`` rows) ``1 <= lambda_max <= p`` and ``1 / lambda_min <= tr(S^-1) = sum_i D_ii (A^-1)_ii``,
    so ``0 < p tr(S^-1) < init_condition`` bounds the condition number below the limit."""
    d = np.diagonal(A, axis1=1, axis2=2)
    if not ((d > 0).all() and np.isfinite(A).all()):
        return None
    try:
        A_inv: FloatArray = np.linalg.inv(A).astype(np.float64, copy=False)
    except np.linalg.LinAlgError:
        return None
    bound = A.shape[1] * np.einsum("mi,mii->m", d, A_inv)
    return A_inv if bound.min() > 0 and bound.max() < init_condition else None  # NaN: None


def _well_conditioned(A: FloatArray, init_condition: float) -> BoolArray:
    """Column-scaled ``Re(X^H X)`` of each model (padding: a unit diagonal, which leaves the
    extreme eigenvalues of a unit-diagonal matrix unchanged) below ``init_condition``."""
    d = np.diagonal(A, axis1=1, axis2=2)
    if (d > 0).all() and np.isfinite(A).all():  # the usual case, without per-model reductions
        s = 1.0 / np.sqrt(d)
        eig = np.linalg.eigvalsh(A * s[:, :, None] * s[:, None, :])
        ok: BoolArray = eig[:, 0] * init_condition > eig[:, -1]
        return ok
    positive: BoolArray = np.all(d > 0, axis=1) & np.all(np.isfinite(A), axis=(1, 2))
    s = 1.0 / np.sqrt(np.where(positive[:, None], d, 1.0))
    scaled = A * s[:, :, None] * s[:, None, :]
    scaled[~positive] = np.eye(A.shape[1])
    eig = np.linalg.eigvalsh(scaled)
    ok = positive & (eig[:, 0] * init_condition > eig[:, -1])
    return ok
