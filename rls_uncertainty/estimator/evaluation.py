"""What a bank publishes at a sample: the lag choice and both covariances (Eqs. 13, 20, 22).

:class:`Evaluation` reads the bank's fit (``D``, ``theta``), lag storage (``R_k(i)`` as lag
sums, ``Lambda_k(i)``) and sample counts, and computes, at most once per sample and only when
asked:

* the largest lag ``L`` of Eq. 22 of every model: ``min(lags, k - 1)``, or with
  ``lags="auto"`` Politis' flat-top rule (:func:`.lag_selection.flat_top_lags`) on
  ``R_k(0..max_lags)`` with the rule's sample count (:mod:`.counts`). A model that is not
  ready, and a model that fits exactly (:func:`exact_fits`: its residuals are rounding,
  whose pattern depends on the machine's floating-point kernels and means nothing), is
  given ``R_k(0) = 0`` and so ``min_lags`` (as far as the lags held allow);
* the corrected and conventional covariances of every model from one computation
  (:class:`.CovarianceEvaluator`), the window's half weights cached while the lags held stay
  the same; a corrected covariance with a negative variance is repaired and counted in
  :attr:`Evaluation.repairs`.

The results of a sample are kept until the sample count moves on: a refused sample (the
bank rolls its state back to the same sample) leaves them valid, so a repair is counted once.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np
import numpy.typing as npt

from .counts import SampleCounts
from .covariance import EXACT_FIT, CovarianceEvaluator, Covariances, half_window
from .iv_fit import IvFit
from .lag_selection import flat_top_lags
from .lag_storage import FloatArray, LagStorage, assign_checked
from .lag_window import lag_weights
from .numpy_compat import vecdot
from .options import EstimatorOptions, check_kind
from .rls_fit import RlsFit

__all__ = ["Evaluation", "kind_index", "exact_fits"]

IntArray = npt.NDArray[np.int64]
BoolArray = npt.NDArray[np.bool_]

_KIND_INDEX = {"corrected": 0, "conventional": 1}  # COVARIANCE_KINDS


def kind_index(kind: str) -> int:
    """The index of a covariance kind in :class:`.Covariances`; refuses another."""
    index = _KIND_INDEX.get(kind)
    if index is None:
        check_kind(kind)
    return _KIND_INDEX[kind]


def exact_fits(
    lag_sums: FloatArray, theta: FloatArray, theta_row: FloatArray, lag0: FloatArray, weight_totals: float | FloatArray,
    forgetting: float, k: int,
) -> BoolArray:
    """Models that fit exactly: ``R_k(0)`` at most :data:`.EXACT_FIT` (1e-12) of the
    mean square of their output ``x_j' theta_k``, ``theta' Lambda_k(0) theta / sum_j
    f^(2(k-j))`` (``lag_sums[:, 0] = n R_k(0)``, ``lag0`` = ``Lambda_k(0)``)."""
    output_square = vecdot(np.matmul(theta_row, lag0)[:, 0], theta)
    n_square = k if forgetting == 1.0 else (1.0 - forgetting ** (2 * k)) / (1.0 - forgetting * forgetting)
    exact: BoolArray = lag_sums[:, 0] <= (EXACT_FIT * weight_totals / n_square) * output_square
    return exact


class Evaluation:
    """The lag choice and the covariances of a bank at its current sample (module docstring),
    read from its ``fit``, ``lags`` and ``counts``; the repairs counted per model."""

    def __init__(
        self, options: EstimatorOptions, sizes: Sequence[int], fit: RlsFit | IvFit, lags: LagStorage,
        counts: SampleCounts,
    ) -> None:
        self.options, self.sizes = options, tuple(sizes)
        self._fit, self._lags, self._counts = fit, lags, counts
        self._auto, self._all_lags, self._window = options.auto, options.lags == "all", options.window
        self._D_diagonal = fit.D.diagonal(0, 1, 2)
        iv = options.algorithm == "iv"
        self._evaluator = CovarianceEvaluator(eq13=options.forgetting == 1.0 and not iv, sandwich=iv)
        self._small_sample = options.small_sample if iv else 0.0
        self._sizes = np.array(self.sizes, dtype=float)
        self.repairs = np.zeros(len(self.sizes), dtype=np.int64)  # corrected covariances repaired, per model
        self._mask = np.arange(fit.D.shape[1]) < np.array(self.sizes)[:, None]  # parameters, not padding
        self._ready = np.zeros(len(self.sizes), dtype=bool)
        self._at = -1  # the sample the results below are of
        self._covariances: Covariances | None = None
        self._chosen: IntArray | None = None  # the lags (chosen on first use)
        self._exact_fits: BoolArray | None = None  # exact_fits(), asked by the lag choice and the repair
        self._window_key: tuple[int, int] | tuple[int, bytes] | None = None
        self._window_h = np.zeros(0)

    def readiness_changed(self, ready: BoolArray, inv_s: FloatArray) -> None:
        """The models ``ready`` and their column scales ``inv_s`` (``1/s``) after a change: at
        a new sample (whose results are computed afresh) or a state restored."""
        self._ready = ready.copy()
        self._all_ready = bool(ready.all())
        invalid = ~(self._mask & ready[:, None])  # padding and models not ready: NaN
        self._theta_scale = np.where(invalid, np.nan, inv_s)
        self._cov_scale = self._theta_scale[:, :, None] * self._theta_scale[:, None, :]
        self._se_scale = 2.0 * self._cov_scale.diagonal(0, 1, 2)  # see Covariances

    def _sample(self) -> int:
        """The current sample count; the results of an earlier one are dropped."""
        k = self._counts.k
        if k != self._at:
            self._covariances = self._chosen = self._exact_fits = None
            self._at = k
        return k

    def theta_all(self) -> FloatArray:
        """Estimates of every model, NaN on padding and models not ready."""
        theta: FloatArray = self._fit.theta * self._theta_scale
        return theta

    def lags_chosen(self) -> IntArray:
        """``L`` of Eq. 22 of every model at this sample (module docstring)."""
        k = self._sample()
        chosen = self._chosen
        if chosen is None:
            if not self._auto:
                held = self._lags.cap - 1
                largest = max(k - 1, 0) if self._all_lags else min(held, max(k - 1, 0))
                chosen = np.full(len(self.sizes), largest, dtype=np.int64)
            else:  # models not ready, and exact fits, get R(0) = 0: min_lags (the rule's edge case)
                sums = self._lags.lag_sums[:, : min(k, self._lags.cap)]
                if self._all_ready:
                    exact = self._exact(k)
                    if exact.any():
                        sums = np.where(exact[:, None], 0.0, sums)
                elif k:
                    usable = self._ready & ~self._exact(k)
                    sums = np.where(usable[:, None], sums, 0.0)
                o = self.options
                chosen = flat_top_lags(sums, self._counts.rule_samples(), cap=o.max_lags, min_lags=o.min_lags)
            self._chosen = chosen
        return chosen

    def evaluate(self) -> Covariances:
        """Both covariances of every model at this sample, computed once (Eqs. 13, 20, 22)."""
        k = self._sample()
        cov = self._covariances
        if cov is None:
            lags = self._lags
            if k < lags.cap:
                w = max(k, 1)  # (before the first sample: lag 0 only, all zero; no model is ready)
                sums, products = lags.lag_sums[:, :w], lags.lag_products[:, :, :w]
            else:
                w = lags.cap
                sums, products = lags.lag_sums, lags.lag_products
            if self._auto:  # Eq. 22 with each model's L: weight 1 on lags 0..L (lag 0 halved)
                L = self.lags_chosen()
                w = min(w, int(L[self._ready].max(initial=0)) + 1)  # no lag beyond the largest L
                sums, products = lags.lag_sums[:, :w], lags.lag_products[:, :, :w]
                h = self._truncated_window(L, w)
            else:
                largest = max(k - 1, 0) if self._all_lags else lags.cap - 1
                h = self._window_h if self._window_key == (largest, w) else self._half_window(largest, w)
            totals = self._counts.weight_totals()
            factor = self._small_sample_factor(totals, w) if self._small_sample and k else None
            cov = self._evaluator(
                self._fit.D, self._D_diagonal, sums, h, products, 1.0 / totals if k else 1.0,  # (k = 0: all NaN)
                self._cov_scale, self._se_scale, factor,
            )
            if cov.indefinite:  # exact fits published as zero, the others repaired and counted
                self.repairs[cov.repair(self._exact(k), self.sizes)] += 1
            self._covariances = cov
        return cov

    def _small_sample_factor(self, totals: float | FloatArray, w: int) -> FloatArray:
        """``n_R / (n_R - n - s L)`` of every model, ``(M,)``, on the corrected covariance of
        instrumental variables (``L`` each model's largest lag used of the ``w`` held; the
        denominator at least ``n_R / 4``; 1 where ``n_R = 0``, a model not yet counting)."""
        L = np.minimum(self.lags_chosen(), w - 1) if self._auto else w - 1
        n_R = np.asarray(totals, dtype=float)
        with np.errstate(divide="ignore", invalid="ignore"):
            factor = n_R / np.maximum(n_R - self._sizes - self._small_sample * L, 0.25 * n_R)
        out: FloatArray = np.where(n_R > 0.0, factor, 1.0)
        return out

    def _truncated_window(self, L: IntArray, w: int) -> FloatArray:
        """Half windows ``(M, w)`` of Eq. 22 with each model's ``L``: weight 1 on lags
        ``0..L`` (lag 0 halved); kept while the lags stay the same."""
        key = (w, L.tobytes())
        if key != self._window_key:
            h = (np.arange(w) <= L[:, None]).astype(float)
            h[:, 0] = 0.5
            self._window_h, self._window_key = h, key
        return self._window_h

    def _half_window(self, largest: int, w: int) -> FloatArray:
        """Half window ``h`` of the ``w`` lags held, ``largest`` the largest lag of the window
        (:func:`.half_window`); kept while they stay the same."""
        self._window_h = half_window(lag_weights(largest, self._window, w))
        self._window_key = (largest, w)
        return self._window_h

    def _exact(self, k: int) -> BoolArray:
        """:func:`exact_fits` at this sample, computed once."""
        exact = self._exact_fits
        if exact is None:
            fit, lags = self._fit, self._lags
            exact = self._exact_fits = exact_fits(
                lags.lag_sums, fit.theta, fit.theta_row, lags.lag0, self._counts.weight_totals(),
                self.options.forgetting, k)
        return exact

    def standard_errors(self, kind: str) -> FloatArray:
        """The published standard errors of every model, ``(M, n_max)``."""
        index = kind_index(kind)
        se: FloatArray = self.evaluate().standard_errors[index]
        return se

    # ------------------------------------------------------------------ state
    def arrays(self) -> dict[str, np.ndarray]:
        """A copy of :attr:`repairs`."""
        return {"repairs": self.repairs.copy()}

    def load(self, arrays: Mapping[str, npt.ArrayLike]) -> None:
        """Inverse of :meth:`arrays`; another shape is refused by name."""
        assign_checked(self.repairs, arrays["repairs"], "repairs")
