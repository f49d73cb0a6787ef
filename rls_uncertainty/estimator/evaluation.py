"""What a bank publishes at a sample: the lag choice and both covariances (Eqs. 13, 20, 22).

:class:`Evaluation` reads the bank's state (the estimator's ``D`` and ``theta``, the lag
storage, the burn-in's counts) and computes, at most once per sample and only when asked:

* the largest lag ``L`` of Eq. 22 of every model: ``min(lags, k - 1)``, or with
  ``lags="auto"`` Politis' flat-top rule (:func:`.lag_selection.flat_top_lags`) on
  ``R_k(0..max_lags)`` with the rule's sample count (:mod:`.burn_in`). A model that is not
  ready, and a model that fits exactly (:func:`exact_fits`: its residuals are rounding,
  whose pattern depends on the machine's floating-point kernels and means nothing), is
  given ``R_k(0) = 0`` and so ``min_lags`` (as far as the lags held allow);
* the corrected and conventional covariances of every model from one computation
  (:class:`.CovarianceEvaluator`), the window's half weights cached while the lags
  held stay the same.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np
import numpy.typing as npt

from .burn_in import BurnIn
from .covariance import EXACT_FIT, CovarianceEvaluator, Covariances, half_window
from .lag_selection import flat_top_lags
from .lag_storage import FloatArray, LagStorage
from .lag_window import lag_weights
from .numpy_compat import vecdot
from .options import EstimatorOptions, check_kind

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
    """The lag choice and the covariances of a bank at its current sample (module docstring).

    ``D``, ``theta`` and ``theta_row`` are views of the estimator's fit, ``ready`` and
    ``repairs`` the bank's arrays (read, and ``repairs`` counted, in place), ``counters()``
    returns the bank's sample count ``k`` and the weight total ``n`` of ``R_k(i)`` before
    any burn-in.
    """

    def __init__(
        self, options: EstimatorOptions, sizes: Sequence[int], lags: LagStorage, burn: BurnIn,
        fit: tuple[FloatArray, FloatArray, FloatArray], ready: BoolArray, repairs: IntArray,
        counters: Callable[[], tuple[int, float]],
    ) -> None:
        self.options, self.sizes = options, tuple(sizes)
        self._auto, self._all_lags, self._window = options.auto, options.lags == "all", options.window
        self._lags, self._burn, self._ready, self._repairs, self._counters = lags, burn, ready, repairs, counters
        self._D, self._theta, self._theta_row = fit
        self._D_diagonal = self._D.diagonal(0, 1, 2)
        self._evaluator = CovarianceEvaluator(eq13=options.forgetting == 1.0)
        self._covariances: Covariances | None = None  # of the current sample
        self._chosen: IntArray | None = None  # the lags of the current sample (chosen on first use)
        self._totals: float | FloatArray | None = None  # the weight totals of the current sample
        self._exact_fits: BoolArray | None = None  # exact_fits() of the current sample
        self._window_key: tuple[int, int] | None = None
        self._window_h = np.zeros(0)

    def readiness_changed(self, mask: BoolArray, inv_s: FloatArray) -> None:
        """The scales after the ready models or their column scales ``1/s`` changed."""
        self._all_ready = bool(self._ready.all())
        invalid = ~(mask & self._ready[:, None])  # padding and models not ready: NaN
        self._theta_scale = np.where(invalid, np.nan, inv_s)
        self._cov_scale = self._theta_scale[:, :, None] * self._theta_scale[:, None, :]
        self._se_scale = 2.0 * self._cov_scale.diagonal(0, 1, 2)  # see Covariances
        self.new_sample()

    def new_sample(self) -> None:
        self._covariances = self._chosen = self._totals = self._exact_fits = None

    def saved(self) -> Covariances | None:
        """The covariances evaluated at this sample (None if none were)."""
        return self._covariances

    def restore(self, saved: Covariances | None) -> None:
        """Back to :meth:`saved` (a refused sample: evaluated, and repairs counted, before it)."""
        self._covariances = saved

    def weight_totals(self) -> float | FloatArray:
        """The weight total of ``R_k(i)``: one float, or one per model after a burn-in
        (:mod:`.burn_in`); computed once per sample."""
        totals = self._totals
        if totals is None:
            totals = self._totals = self._burn.weight_totals(*self._counters())
        return totals

    def theta_all(self) -> FloatArray:
        """Estimates of every model, NaN on padding and models not ready."""
        theta: FloatArray = self._theta * self._theta_scale
        return theta

    def lags_chosen(self) -> IntArray:
        """``L`` of Eq. 22 of every model at this sample (module docstring)."""
        chosen = self._chosen
        if chosen is None:
            k, _ = self._counters()
            if not self._auto:
                held = self._lags.cap - 1
                largest = max(k - 1, 0) if self._all_lags else min(held, max(k - 1, 0))
                chosen = np.full(len(self.sizes), largest, dtype=np.int64)
            else:  # models not ready, and exact fits, get R(0) = 0: min_lags (the rule's edge case)
                sums = self._lags.lag_sums[:, : min(k, self._lags.cap)]
                if self._all_ready:
                    exact = self._exact(k, self.weight_totals())
                    if exact.any():
                        sums = np.where(exact[:, None], 0.0, sums)
                elif k:
                    usable = self._ready & ~self._exact(k, self.weight_totals())
                    sums = np.where(usable[:, None], sums, 0.0)
                o = self.options
                chosen = flat_top_lags(sums, self._burn.rule_samples(k), cap=o.max_lags, min_lags=o.min_lags)
            self._chosen = chosen
        return chosen

    def evaluate(self) -> Covariances:
        """Both covariances of every model at this sample, computed once."""
        cov = self._covariances
        if cov is None:
            lags = self._lags
            k, _ = self._counters()
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
                h = (np.arange(w) <= L[:, None]).astype(float)
                h[:, 0] = 0.5
            else:
                largest = max(k - 1, 0) if self._all_lags else lags.cap - 1
                h = self._window_h if self._window_key == (largest, w) else self._half_window(largest, w)
            totals = self.weight_totals()
            cov, repaired = self._evaluator(
                self._D, self._D_diagonal, sums, h, products, 1.0 / totals if k else 1.0,  # (k = 0: all NaN)
                self._cov_scale, self._se_scale, lambda: self._exact(k, totals), self.sizes,
            )
            if repaired:
                self._repairs[repaired] += 1
            self._covariances = cov
        return cov

    def _half_window(self, largest: int, w: int) -> FloatArray:
        """Half window ``h`` of the ``w`` lags held, ``largest`` the largest lag of the window
        (:func:`.half_window`); kept while they stay the same."""
        self._window_h = half_window(lag_weights(largest, self._window, w))
        self._window_key = (largest, w)
        return self._window_h

    def _exact(self, k: int, totals: float | FloatArray) -> BoolArray:
        """:func:`exact_fits` at this sample, computed once (the lag choice and the evaluator's
        repair both ask)."""
        exact = self._exact_fits
        if exact is None:
            lags = self._lags
            exact = self._exact_fits = exact_fits(
                lags.lag_sums, self._theta, self._theta_row, lags.lag0, totals, self.options.forgetting, k)
        return exact

    def standard_errors(self, kind: str) -> FloatArray:
        """The published standard errors of every model, ``(M, n_max)``."""
        index = kind_index(kind)
        se: FloatArray = self.evaluate().standard_errors[index]
        return se
