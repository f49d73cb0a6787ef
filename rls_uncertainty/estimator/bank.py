"""The fast estimator: ``M`` recursive least-squares models updated together (Eqs. 15-22).

:class:`EstimatorBank` runs the six coefficient models of Eq. 2 (3-6 parameters each), or
the hundreds of a Monte Carlo study, with one set of vectorised numpy operations per sample.
Its numbers are those of :class:`.reference.RecursiveReference`, which defines every option
(forgetting, residual kinds, exact initialization, the lag window); the tests hold the two
together. This module is the per-sample path; the rest lives beside it:
:mod:`.lag_storage` (history and lag-indexed sums), :mod:`.initialization`,
:mod:`.covariance` and :mod:`.state`.

How the hot path differs from the reference, and why (each measured in
``benchmarks/estimator_benchmark.py``):

* Each model works on column-scaled regressors once initialized (``x / s``); results are
  scaled back on output.
* ``D`` and ``theta`` are the rows of one array ``[D; theta']``, so that one matmul gives
  ``(D x, theta' x)`` and Eqs. 15b-c are one rank-one update with ``u = (D x, -e)``:
  ``[D; theta'] -= u (D x)' / d``. ``D - (Dx)(Dx)'/d`` is exactly symmetric in floating
  point; the algebraically equal ``(I - K x') D`` is not, and under forgetting its
  antisymmetric rounding error grows like ``f^-k`` until the estimator diverges.
* Eq. 17 is kept as the lag sums ``n_k R_k(i)`` and Eq. 21 one-sided (see
  :mod:`.lag_storage`); the sample histories are written once into a newest-first buffer.
* The residual burn-in (``residual_burn_in`` ``B > 0``, :mod:`.reference`) is not stored:
  each model's last left-out sample is ``k0 + B`` from ``ready_at``, the weight total of its
  ``R_k(i)`` and the lag rule's sample count are closed forms of ``k - k0 - B``, and the
  products reaching back into the burn-in are zeroed (``_burn_in``) only while some model's
  lag window still reaches into it (``max_lags + 1`` samples after it; always with all lags).
* An update whose every quantity (scaled regressors, output, ``D x``, innovation) is at most
  ``1e100`` in magnitude cannot make a finite state non-finite (its products with anything
  already in the state stay below ``1e254``, which rounding absorbs even next to the largest
  double), so it is applied directly. Any other sample is applied after a copy of the state
  is taken, and rolled back and refused with :class:`NonFiniteInput` if the state is not
  finite after it. (What the guard does not cover: ``D`` growing without bound under
  forgetting when a regressor stays zero for a very long time.)
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
import numpy.typing as npt

from ..errors import EstimatorNotReady, NonFiniteInput
from . import covariance, state
from .initialization import ExactInitialization
from .lag_selection import flat_top_lags
from .lag_storage import GROWTH_START, FloatArray, LagStorage
from .lag_window import lag_weights
from .numpy_compat import vecdot
from .options import AUTO, check_burn_in, check_kind, check_noise_forgetting, check_options, prior_diagonal

__all__ = ["EstimatorBank"]

_F64 = np.dtype(np.float64)

IntArray = npt.NDArray[np.int64]
BoolArray = npt.NDArray[np.bool_]

# A sample whose quantities are all at most this in magnitude is applied without checks.
_SAFE = 1e100
_SAFE_SQUARED = _SAFE * _SAFE
_KIND_INDEX = {"corrected": 0, "conventional": 1}  # COVARIANCE_KINDS
_NEVER = 2**62  # the burn-in end of a model that is not initialized (no sample reaches it)


class EstimatorBank:
    """``M`` independent recursive least-squares models updated together (Eqs. 15-22).

    Parameters
    ----------
    sizes:
        Number of parameters of each model, e.g. ``(3, 4, 3, 6, 4, 4)`` for Eq. 2a-f.
    n_lags:
        Largest residual-autocorrelation lag kept (Eq. 22); ``None`` keeps all lags (Eq. 20,
        memory and time grow with the number of samples). ``0`` gives the conventional
        covariance. ``"auto"``: each model's ``L`` is chosen from the data at every evaluated
        sample (Politis' flat-top rule on ``R_k(0..max_lags)``,
        :func:`.lag_selection.flat_top_lags`; truncated window only), with the memory of
        ``n_lags=max_lags``; :attr:`lags_used` tells the choice.
    window:
        ``"truncated"`` (Eq. 22, uniform) or ``"bartlett"`` (positive semi-definite).
    forgetting:
        Exponential forgetting factor ``0 < f <= 1``; ``1`` is the paper.
    residual:
        ``"standardized"`` (default, ``e_k sqrt(f/d_k)``, which makes Eq. 16 equal Eq. 14),
        ``"a_posteriori"`` (``z_k - x_k' theta_k``) or ``"a_priori"`` (``z_k - x_k' theta_{k-1}``).
    p0:
        ``None`` for exact initialization; a positive scalar or per-parameter sequence for the
        prior ``D_0 = diag(p0)``, ``theta_0 = 0`` (applied to every model).
    init_condition:
        Exact initialization waits until the column-scaled ``X'X`` has a condition number
        below this value.
    noise_forgetting:
        Forgetting ``f_R`` of the noise model whose residuals give ``R_k(i)`` under forgetting
        (``forgetting <= f_R <= 1``). ``None`` (default) takes
        ``max(f, 1 - 1/(40 (n_lags + 1)))`` (:func:`.options.default_noise_forgetting`; ``f``
        itself when ``f = 1`` or all lags are kept). ``f_R = f`` uses the estimator's own
        residuals (the formulas before issue 12, which under-report under forgetting).
    max_lags, min_lags:
        With ``n_lags="auto"``: the most lags the rule may choose (the memory bound) and the
        fewest it uses (default 50 and 0); ignored otherwise.
    residual_burn_in:
        ``B``: once a model has had ``B`` samples after its initialization at ``k0``, its
        ``R_k(i)`` is formed from the residuals of samples ``k0 + B + 1 .. k`` only (both
        ``v_k`` and ``v_(k-i)``; the initialization's own residuals are left out too),
        normalised by their weight total; until then it is the paper's. ``0`` is the paper's
        Eq. 17; ``None`` (default) takes 50 with ``n_lags="auto"`` and 0 otherwise
        (:func:`.options.check_burn_in`). Defined in :mod:`.reference`.

    The options are defined in :mod:`.reference`; the noise model in the package docstring.
    """

    STATE_FORMAT = state.STATE_FORMAT

    def __init__(
        self,
        sizes: Sequence[int],
        n_lags: int | str | None = None,
        window: str = "truncated",
        forgetting: float = 1.0,
        *,
        residual: str = "standardized",
        p0: float | Sequence[float] | None = None,
        init_condition: float = 1e8,
        noise_forgetting: float | None = None,
        max_lags: int = 50,
        min_lags: int = 0,
        residual_burn_in: int | None = None,
    ) -> None:
        sizes = tuple(int(s) for s in sizes)
        if not sizes or min(sizes) < 1:
            raise ValueError(f"every model needs at least one parameter, got sizes={sizes}")
        check_options(n_lags, window, forgetting, residual, init_condition, max_lags=max_lags, min_lags=min_lags)
        self.auto = n_lags == AUTO
        self.max_lags, self.min_lags = int(max_lags), int(min_lags)
        # The largest lag held: n_lags, max_lags with auto, None (growing) for all lags.
        held = None if n_lags is None else (self.max_lags if self.auto else int(n_lags))
        g = check_noise_forgetting(noise_forgetting, forgetting, held)
        self.residual_burn_in = check_burn_in(residual_burn_in, n_lags)  # B
        self.sizes = sizes
        self.n_models = m = len(sizes)
        self.n_max = n = max(sizes)
        self.n_lags = AUTO if self.auto else (None if n_lags is None else int(n_lags))
        self.window = window
        self.forgetting = float(forgetting)
        self.residual = residual
        self.init_condition = float(init_condition)
        self.noise_forgetting = g  # f_R
        self._noise = g != self.forgetting  # a noise model gives R_k(i) (f < 1)

        self._x_shape, self._z_shape = (m, n), (m,)
        self._mask = np.zeros((m, n), dtype=bool)
        for j, s in enumerate(sizes):
            self._mask[j, :s] = True

        self.k = 0
        self.n_eff = 0.0  # n_k = sum_j f^(k-j); equals k when f = 1
        self.n_noise = 0.0  # n^N_k = sum_j f_R^(k-j): R_k(i) = lag_sums / n_R (n_eff without noise model)
        # [D; theta'] in column-scaled units: _aug[:, :n] = S D S, _aug[:, n] = S theta.
        self._aug = np.zeros((m, n + 1, n))
        self._D = self._aug[:, :n]
        self._D_diagonal = self._D.diagonal(0, 1, 2)
        self._theta, self._theta_row = self._aug[:, n], self._aug[:, n, None, :]
        self._inv_s = self._mask.astype(float)  # 1/s on real parameters, 0 on padding
        self._ready = np.zeros(m, dtype=bool)
        self._ready_at = np.zeros(m, dtype=np.int64)
        self.repairs = np.zeros(m, dtype=np.int64)
        # Residual burn-in: each model's last left-out sample k0 + B (_NEVER until initialized),
        # and whether some model's lag window still reaches into its burn-in (see _apply).
        self._burn = self.residual_burn_in > 0
        self._burn_end = np.full(m, _NEVER, dtype=np.int64)
        self._burn_masking = self._burn
        self._burned_at: int | None = None  # the sample _burned_counts is of
        self._burned_counts: FloatArray | None = None
        cap = GROWTH_START if held is None else held + 1
        self._lags = LagStorage(
            m, n, cap, all_lags=held is None, forgetting=self.forgetting, waiting=p0 is None,
            noise_forgetting=g,
        )
        self._init = ExactInitialization(self)
        # Per-sample scratch, each contiguous: y = (x / s, z) and u = (D x, theta' x - z). Their
        # magnitudes decide whether the sample can be applied unchecked (_prepare).
        self._y = np.zeros((m, n + 1))
        self._y_xs = self._xs = self._y[:, :n]
        self._z_slot = self._y[:, n]
        self._y_flat = self._y.reshape(-1)
        self._g = np.zeros((m, n + 1, 1))  # u as a column: the matmul's output
        self._Dx = self._g[:, :n, 0]
        self._Dx_row = self._g[:, None, :n, 0]
        self._neg_e = self._g[:, n, 0]
        self._y_abs = np.zeros_like(self._y)
        self._y_abs_flat = self._y_abs.reshape(-1)
        self._g_flat = self._g.reshape(-1)
        self._y_xs_col = self._xs_col = self._xs[:, :, None]
        self._d = np.zeros(m)  # d_k = f + x' D x
        self._d_col = self._d[:, None, None]
        self._root = np.zeros(m)  # sqrt(d_k / f)
        self._outer = np.zeros((m, n + 1, n))
        if self._noise:  # the noise model: [D^N; theta^N'] and its scratch, as the estimator's
            self._naug = np.zeros((m, n + 1, n))
            self._nD = self._naug[:, :n]
            self._ng = np.zeros((m, n + 1, 1))
            self._nDx = self._ng[:, :n, 0]
            self._nDx_row = self._ng[:, None, :n, 0]
            self._n_neg_e = self._ng[:, n, 0]
            self._ng_flat = self._ng.reshape(-1)
            self._nd = np.zeros(m)
            self._nd_col = self._nd[:, None, None]
            self._nroot = np.zeros(m)
            self._nouter = np.zeros((m, n + 1, n))
        self._evaluator = covariance.CovarianceEvaluator(eq13=self.forgetting == 1.0)
        self._covariances: covariance.Covariances | None = None  # of the current sample
        self._chosen: IntArray | None = None  # lags_used at the current sample (chosen on first use)
        self._window_key: tuple[int, int] | None = None

        if p0 is not None:
            p = prior_diagonal(p0, n)
            self._aug[:, :n] = np.eye(n) * p * self._mask[:, :, None] * self._mask[:, None, :]
            if self._noise:
                self._naug[:, :n] = self._aug[:, :n]
            self._ready[:] = True
        self._readiness_changed()

    def _readiness_changed(self) -> None:
        """Recompute what depends on which models are ready (after an initialization or a
        restored state)."""
        self._all_ready = bool(self._ready.all())
        if self._all_ready:
            self._lags.all_initialized()
            self._xs, self._xs_col = self._y_xs, self._y_xs_col  # the scratch from now on
        invalid = ~(self._mask & self._ready[:, None])  # padding and models not ready: NaN
        self._theta_scale = np.where(invalid, np.nan, self._inv_s)
        self._cov_scale = self._theta_scale[:, :, None] * self._theta_scale[:, None, :]
        self._se_scale = 2.0 * self._cov_scale.diagonal(0, 1, 2)  # see covariance.Covariances
        if self._burn:
            self._burn_end = np.where(self._ready, self._ready_at + self.residual_burn_in, _NEVER)
            self._burn_masking = int((self.k - self._burn_end).min()) < max(1, self._lags.cap - 1)
            self._burned_at = None
        self._init.reset()
        self._covariances = self._chosen = None

    @property
    def n_window(self) -> int:
        """Number of lags currently held: ``min(k, n_lags + 1)``, or ``k`` for all lags."""
        return min(self.k, self._lags.cap)

    # ------------------------------------------------------------------ update
    def update(self, X: npt.NDArray[Any] | Sequence[npt.ArrayLike], z: npt.ArrayLike) -> None:
        """Process one sample for every model (Eqs. 15-17, 21).

        ``X`` is ``(M, n_max)`` (row ``j`` holds model ``j``'s regressors first; the padding
        is ignored) or a sequence of ``M`` regressor vectors; ``z`` holds the ``M`` measured
        outputs. A NaN or infinite input, or one that would make the state non-finite,
        raises :class:`NonFiniteInput` and leaves the state unchanged.
        """
        if type(X) is np.ndarray and X.shape == self._x_shape and X.dtype == _F64:
            x = X
        else:
            x = self._as_regressors(X)
        if not (type(z) is np.ndarray and z.shape == self._z_shape and z.dtype == _F64):
            z = np.asarray(z, dtype=float).reshape(-1)
            if z.shape != (self.n_models,):
                raise ValueError(f"expected {self.n_models} measured outputs, got shape {z.shape}")
        if self._prepare(x, z):
            self._apply(z)
        else:
            self._apply_checked(x, z)

    def _prepare(self, x: FloatArray, z: FloatArray, check: bool = True) -> bool:
        """Write the sample's ``y = (x / s, z)`` (to its history slot in front of the window
        while a model waits, else to scratch), ``u = (D x, theta' x - z)`` and ``d`` to
        scratch: the state is not touched. True when every entry of ``y`` and ``u`` is at
        most 1e100 in magnitude (then the update keeps a finite state finite); with ``check``,
        NaN, infinity or a larger number in ``y`` stops it early and returns False."""
        if self._lags.waiting:
            y = self._lags.y[:, self._lags.ptr - 1]
            self._y_k, self._xs, self._xs_col = y, y[:, : self.n_max], y[:, : self.n_max, None]
            np.multiply(x, self._inv_s, out=self._xs)
            y[:, self.n_max] = z
            small: bool = np.maximum.reduce(np.absolute(y, out=self._y_abs), axis=None) <= _SAFE
        else:  # scratch (self._xs is its x part once every model is initialized)
            np.multiply(x, self._inv_s, out=self._xs)
            self._z_slot[...] = z
            small = np.maximum.reduce(np.absolute(self._y_flat, out=self._y_abs_flat)) <= _SAFE
        if check and not small:
            return False
        np.matmul(self._aug, self._xs_col, out=self._g)  # (D x, theta' x)
        d = vecdot(self._xs, self._Dx, out=self._d)
        d += self.forgetting  # d_k = f + x' D x: the denominator of Eq. 15a
        np.subtract(self._neg_e, z, out=self._neg_e)  # -e_k = x' theta_(k-1) - z_k
        small = small and np.dot(self._g_flat, self._g_flat) <= _SAFE_SQUARED
        if self._noise:  # the same for the noise model (forgetting f_R)
            np.matmul(self._naug, self._xs_col, out=self._ng)
            vecdot(self._xs, self._nDx, out=self._nd)
            self._nd += self.noise_forgetting
            np.subtract(self._n_neg_e, z, out=self._n_neg_e)
            small = small and np.dot(self._ng_flat, self._ng_flat) <= _SAFE_SQUARED
        return small

    def _apply(self, z: FloatArray) -> None:
        """Add the prepared sample to the state (Eqs. 15-17, 21)."""
        f, lags = self.forgetting, self._lags
        k = self.k + 1
        w = k if k < lags.cap else lags.cap  # lags held after this sample
        p = lags.ptr - 1  # the free slot in front of the window (see the end)
        waiting, merged = lags.waiting, lags.merged
        if not merged:
            lags.x[:, p] = self._xs  # (while a model waits, _prepare wrote y to its slot)
        self.k = k
        lags.ptr = p
        self.n_eff = f * self.n_eff + 1.0  # n_k

        # Eqs. 15a-c: [D; theta'] -= u (D x)' / d with u = (D x, -e).
        outer = np.multiply(self._g, self._Dx_row, out=self._outer)
        outer /= self._d_col
        self._aug -= outer  # Eq. 15b (D rows), Eq. 15c (theta row)
        if f != 1.0:
            self._D /= f  # Eq. 15b with forgetting
        self._residual(lags.v[:, p], self._neg_e, self._d, self._root, f)
        series, g = lags.v, f
        if self._noise:
            # The noise model: Eq. 15 with f_R, and its residual u_k of the same kind.
            g = self.noise_forgetting
            outer = np.multiply(self._ng, self._nDx_row, out=self._nouter)
            outer /= self._nd_col
            self._naug -= outer
            if g != 1.0:
                self._nD /= g
            self._residual(lags.u[:, p], self._n_neg_e, self._nd, self._nroot, g)
            self.n_noise = g * self.n_noise + 1.0  # n^N_k
            series = lags.u

        sums, sums_tmp, products, products_tmp = lags.full if w == lags.cap else lags.by_lag(w)
        # Eq. 17 as sums: n_k R_k(i) = f n_(k-1) R_(k-1)(i) + v_k v_(k-i) (with a noise model
        # f_R and its residuals u_k).
        if g != 1.0:
            sums *= g
        v_window = series[:, p : p + w]  # v_k, v_(k-1), ...
        lagged = np.multiply(v_window, v_window[:, :1], out=sums_tmp)  # v_k v_(k-i)
        if self._burn_masking:  # some model's window reaches into its burn-in
            self._burn_in(sums, lagged, k, w)
        sums += lagged

        # Eq. 21, one-sided: Lambda+_k(i) = f^2 Lambda+_(k-1)(i) + f^i x_k x_(k-i)'.
        m, n = self.n_models, self.n_max
        if merged:  # of y = (x, z): Lambda+ and the lagged moments at once (see .lag_storage)
            y_window = lags.y[:, p : p + w].reshape(m, 1, w * (n + 1))  # y_k, y_(k-1), ...
            products += np.multiply(self._y_k[:, :, None], y_window, out=products_tmp)
        else:
            x_window = lags.x[:, p : p + w].reshape(m, 1, w * n)  # x_k, x_(k-1), ... (a view)
            if f == 1.0:
                products += np.multiply(self._xs_col, x_window, out=products_tmp)
            else:
                weighted = (x_window.reshape(m, w, n) * lags.lag_powers[None, :w, None]).reshape(m, 1, w * n)
                lags.lag_products *= f * f
                products += np.multiply(self._xs_col, weighted, out=products_tmp)
            if waiting:  # the lagged moments, weighted f^(k-j) (f_R^(k-j) with a noise model)
                moments, moments_tmp = lags.products_y_by_lag(w)
                if lags.moment0 is not None:  # the lag-0 moments weighted f^(k-j)
                    lags.moment0 *= f
                    lags.moment0 += self._y_k[:, :, None] * self._y_k[:, None, :]
                lags.products_y *= lags.moment_forgetting
                y_window = lags.y[:, p : p + w].reshape(m, 1, w * (n + 1))
                moments += np.multiply(self._y_k[:, :, None], y_window, out=moments_tmp)
        if waiting:
            self._init.check(w)
        if p == 0:  # keep a free slot in front of the window for the next sample
            if self.n_lags is None:
                lags.grow(w)
                self._init.reset()  # its indices point into the old arrays
            else:
                lags.relocate(w)
        self._covariances = self._chosen = None

    def _burn_in(self, sums: FloatArray, lagged: FloatArray, k: int, w: int) -> None:
        """The residual burn-in at sample ``k`` (``w`` lags held): a model whose burn-in ended
        at the previous sample starts its lag sums afresh, and the products with a partner
        ``v_(k-i)`` of the burn-in (``k - i <= k0 + B``) are left out. Stops being called
        once no model's window can reach into its burn-in (never with all lags)."""
        after = k - self._burn_end  # samples since the burn-in ended (<= 0: in it, the paper's Eq. 17)
        sums[after == 1] = 0.0
        lagged[(np.arange(w) >= after[:, None]) & (after[:, None] > 0)] = 0.0
        if int(after.min()) >= max(1, self._lags.cap - 1):  # every start done, no window reaches back
            self._burn_masking = False

    def _residual(self, out: FloatArray, neg_e: FloatArray, d: FloatArray, root: FloatArray, f: float) -> None:
        """The residual of Eqs. 16-17 of the chosen kind, from ``-e_k`` and ``d_k`` (forgetting
        ``f``), written to ``out``."""
        if self.residual == "standardized":  # v_k = e_k sqrt(f/d_k)
            root = np.sqrt(d if f == 1.0 else np.divide(d, f, out=root), out=root)
            np.divide(neg_e, np.negative(root, out=root), out=out)
        elif self.residual == "a_posteriori":
            np.multiply(neg_e / d, -f, out=out)  # v_k = e_k f/d_k = z_k - x_k' theta_k (Eq. 7)
        else:
            np.negative(neg_e, out=out)  # v_k = e_k

    def _apply_checked(self, x: FloatArray, z: FloatArray) -> None:
        """Apply a sample on which :meth:`_prepare` found NaN, infinity or a large number:
        refuse a non-finite input, or one that would make the state non-finite."""
        bad = [
            j for j in range(self.n_models)
            if not (np.isfinite(x[j, : self.sizes[j]]).all() and np.isfinite(z[j]))
        ]
        if bad:
            raise NonFiniteInput(f"non-finite regressor or output for model(s) {bad}; sample ignored")
        x = np.where(self._mask, x, 0.0)  # the padding is ignored
        before, outputs = self.state(), self._covariances
        with np.errstate(all="ignore"):  # overflow is what is being checked
            self._prepare(x, z, check=False)
            self._apply(z)
        finite = all(np.isfinite(a).all() for a in self.state()["arrays"].values())
        if not finite:
            state.restore(self, before)
            self._covariances = outputs  # evaluated (and repairs counted) before this sample
            raise NonFiniteInput(
                "sample ignored: its magnitude would make the estimator state non-finite "
                f"(largest |regressor| {np.max(np.abs(x)):.3g}, largest |output| {np.max(np.abs(z)):.3g})"
            )

    def _as_regressors(self, X: npt.NDArray[Any] | Sequence[npt.ArrayLike]) -> FloatArray:
        if isinstance(X, np.ndarray) and X.shape == (self.n_models, self.n_max):
            return X if X.dtype == float else X.astype(float)
        rows = [X] if isinstance(X, np.ndarray) and X.ndim == 1 else list(X)
        if len(rows) != self.n_models:
            raise ValueError(f"expected regressors for {self.n_models} models, got {len(rows)}")
        x = np.zeros((self.n_models, self.n_max))
        for j, (row, s) in enumerate(zip(rows, self.sizes, strict=True)):  # (lengths checked above)
            values = np.asarray(row, dtype=float).reshape(-1)
            if values.shape != (s,):
                raise ValueError(f"model {j} has {s} parameters, got {values.shape[0]} regressors")
            x[j, :s] = values
        return x

    # ------------------------------------------------------------------ results
    @property
    def ready(self) -> np.ndarray:
        """Boolean per model: initialized, so estimates and covariances exist."""
        return self._ready.copy()

    @property
    def ready_at(self) -> np.ndarray:
        """Sample count at which each model was initialized (0 while not ready)."""
        return np.where(self._ready, self._ready_at, 0)

    @property
    def n_samples(self) -> int:
        return self.k

    def _require(self, j: int) -> None:
        if not self._ready[j]:
            raise EstimatorNotReady(
                f"model {j} is not initialized after {self.k} samples: its regressors "
                "have not yet made X'X well conditioned"
            )

    def theta(self, j: int) -> np.ndarray:
        """Parameter estimate ``theta_k`` of model ``j`` (Eq. 15c)."""
        self._require(j)
        s_n = self.sizes[j]
        theta: FloatArray = self._aug[j, self.n_max, :s_n] * self._inv_s[j, :s_n]
        return theta

    def theta_all(self) -> np.ndarray:
        """Estimates of every model as an ``(M, n_max)`` array; padding and models that are
        not :attr:`ready` are NaN."""
        return self._theta * self._theta_scale

    @property
    def n_R(self) -> np.ndarray:
        """The weight total of each model's ``R_k(i)``, ``(M,)``: ``n^N_k = sum_j f_R^(k-j)``
        with a noise model, otherwise ``n_k = sum_j f^(k-j)``; after a model's residual
        burn-in the sum runs over ``j > k0 + B`` only."""
        return np.broadcast_to(self._weight_totals(), (self.n_models,)).copy()

    def _burned(self) -> FloatArray | None:
        """Each model's samples after its burn-in (0 during it) as floats, or None while no
        model is past it (always with ``B = 0``); computed once per sample."""
        if not self._burn:
            return None
        if self._burned_at != self.k:
            after = self.k - self._burn_end
            self._burned_counts = np.maximum(after, 0).astype(float) if int(after.max()) > 0 else None
            self._burned_at = self.k
        return self._burned_counts

    def _weight_totals(self) -> float | FloatArray:
        """:attr:`n_R`: one float while no model is past its burn-in (always with ``B = 0``),
        else one per model."""
        n = self.n_noise if self._noise else self.n_eff
        c = self._burned()
        if c is None:
            return n
        g = self.noise_forgetting
        burned = c if g == 1.0 else -np.expm1(c * math.log(g)) / (1.0 - g)  # sum_(j > k0+B) g^(k-j)
        totals: FloatArray = np.where(c > 0.0, burned, n)
        return totals

    def residual_variance(self, j: int) -> float:
        """Fit-error variance (Eq. 16), i.e. ``R_k(0)`` (the noise model's under forgetting)."""
        self._require(j)
        return float(self._lags.lag_sums[j, 0] / self._weight_total(j))

    def autocorrelation(self, j: int) -> np.ndarray:
        """Residual autocorrelation ``R_k(i)``, ``i = 0..n_window-1`` (Eq. 17; under
        forgetting that of the noise model's residuals, weighted ``f_R^(k-j)``; after the
        residual burn-in from the samples after it)."""
        self._require(j)
        R: FloatArray = self._lags.lag_sums[j, : self.n_window] / self._weight_total(j)
        return R

    def _weight_total(self, j: int) -> float:
        totals = self._weight_totals()
        return totals if isinstance(totals, float) else float(totals[j])

    def residuals(self, j: int) -> np.ndarray:
        """Stored residuals of the estimator, oldest first: the whole history with
        ``n_lags=None``, otherwise the last ``n_lags + 1``."""
        self._require(j)
        return self._lags.window(self._lags.v, self.n_window)[j, ::-1].copy()

    def noise_residuals(self, j: int) -> np.ndarray:
        """The residuals behind ``R_k(i)``, stored as :meth:`residuals`: the noise model's
        ``u_k`` under forgetting, otherwise the estimator's own residuals."""
        self._require(j)
        buf = self._lags.u if self._noise else self._lags.v
        return self._lags.window(buf, self.n_window)[j, ::-1].copy()

    def _half_window(self, largest: int, w: int) -> np.ndarray:
        """Half window ``h`` of the ``w`` lags held, ``largest`` the largest lag of the window
        (:func:`.covariance.half_window`); kept while they stay the same."""
        self._window_h = covariance.half_window(lag_weights(largest, self.window, w))
        self._window_key = (largest, w)
        return self._window_h

    def _evaluate(self) -> covariance.Covariances:
        """Both covariances of every model at this sample, computed once."""
        cov = self._covariances
        if cov is None:
            lags = self._lags
            if self.k < lags.cap:
                w = self.k
                sums, products = lags.lag_sums[:, :w], lags.lag_products[:, :, :w]
            else:
                w = lags.cap
                sums, products = lags.lag_sums, lags.lag_products
            if self.auto:  # Eq. 22 with each model's L: weight 1 on lags 0..L (lag 0 halved)
                L = self._lags_chosen()
                w = min(w, int(L[self._ready].max(initial=0)) + 1)  # no lag beyond the largest L
                sums, products = lags.lag_sums[:, :w], lags.lag_products[:, :, :w]
                h = (np.arange(w) <= L[:, None]).astype(float)
                h[:, 0] = 0.5
            else:
                # (not auto, so n_lags is an int or None, which mypy cannot see through self.auto)
                largest: int = self.k - 1 if self.n_lags is None else self.n_lags  # type: ignore[assignment]
                h = self._window_h if self._window_key == (largest, w) else self._half_window(largest, w)
            cov, repaired = self._evaluator(
                self._D, self._D_diagonal, sums, h, products, 1.0 / self._weight_totals(),
                self._cov_scale, self._se_scale, self._exact_fit, self.sizes,
            )
            if repaired:
                self.repairs[repaired] += 1
            self._covariances = cov
        return cov

    @property
    def lags_used(self) -> np.ndarray:
        """The largest lag ``L`` of Eq. 22 each model uses at this sample, ``(M,)`` ints: with
        ``n_lags="auto"`` chosen by the flat-top rule (``min_lags``, as far as the lags held
        allow, for a model that is not ready), otherwise ``min(n_lags, k - 1)`` (``k - 1`` with
        all lags)."""
        return self._lags_chosen().copy()

    def _lags_chosen(self) -> np.ndarray:
        chosen = self._chosen
        if chosen is None:
            k, m = self.k, self.n_models
            if not self.auto:
                largest = max(k - 1, 0) if self.n_lags is None else min(self.n_lags, max(k - 1, 0))
                chosen = np.full(m, largest, dtype=np.int64)
            else:  # models not ready get R(0) = 0: min_lags (the rule's edge case)
                sums = self._lags.lag_sums[:, : self.n_window]
                if not self._all_ready:
                    sums = np.where(self._ready[:, None], sums, 0.0)
                chosen = flat_top_lags(sums, self._rule_samples(), cap=self.max_lags, min_lags=self.min_lags)
            self._chosen = chosen
        return chosen

    @property
    def rule_samples(self) -> np.ndarray:
        """The sample count the lag rule uses for each model, ``(M,)``: ``k``, or under
        forgetting Kish's effective size ``(sum w)^2 / sum w^2`` of the weights ``w_j = g^(k-j)``
        of ``R_k(i)`` (``g = f_R``), ``(1 - g^k)(1 + g) / ((1 - g)(1 + g^k))``; after a model's
        residual burn-in the same with ``k - k0 - B`` samples."""
        return np.broadcast_to(self._rule_samples(), (self.n_models,)).copy()

    def _rule_samples(self) -> float | FloatArray:
        """:attr:`rule_samples`: one float while no model is past its burn-in, else one per model."""
        g, k = self.noise_forgetting, self.k
        if g == 1.0:
            n = float(k)
        else:
            gk = g**k
            n = (1.0 - gk) * (1.0 + g) / ((1.0 - g) * (1.0 + gk))
        c = self._burned()
        if c is None:
            return n
        if g == 1.0:
            burned = c
        else:
            gc = np.power(g, c)
            burned = (1.0 - gc) * (1.0 + g) / ((1.0 - g) * (1.0 + gc))
        counts: FloatArray = np.where(c > 0.0, burned, n)
        return counts

    def _exact_fit(self) -> BoolArray:
        """Models whose residual variance ``R_k(0)`` is at most 1e-12 of the mean square of
        their output ``x_j' theta_k`` (``theta' Lambda_k(0) theta / sum_j f^(2(k-j))``)."""
        f, k = self.forgetting, self.k
        output_square = vecdot(np.matmul(self._theta_row, self._lags.lag0)[:, 0], self._theta)
        n_square = k if f == 1.0 else (1.0 - f ** (2 * k)) / (1.0 - f * f)
        return self._lags.lag_sums[:, 0] <= (covariance.EXACT_FIT * self._weight_totals() / n_square) * output_square

    def standard_errors_all(self, kind: str = "corrected") -> np.ndarray:
        """Standard errors of every model as an ``(M, n_max)`` array: the square roots of the
        diagonals of :meth:`covariance`. Padding and models that are not :attr:`ready` are NaN.
        """
        index = _KIND_INDEX.get(kind)
        if index is None:
            check_kind(kind)
        return self._evaluate().standard_errors[index]

    def covariance(self, j: int, kind: str = "corrected", *, repair: bool = True) -> np.ndarray:
        """Parameter covariance of model ``j``.

        ``kind="corrected"``: Eq. 20 (all lags) or Eq. 22 (``n_lags``) with the chosen window.
        ``kind="conventional"``: Eq. 13 with the fit-error variance of Eq. 16.
        With ``repair`` (default) a corrected covariance with a negative diagonal is replaced
        by the nearest positive semi-definite matrix and counted in :attr:`repairs` (once per
        sample), or by zero where the model fits exactly.
        """
        check_kind(kind)
        self._require(j)
        return self._evaluate().matrix(_KIND_INDEX[kind], j, self.sizes[j], repair=repair)

    def covariance_all(self) -> np.ndarray:
        """:meth:`covariance` (repaired) of every model and both kinds at once, a new
        ``(2, M, n_max, n_max)`` array: ``[0]`` corrected, ``[1]`` conventional; NaN outside
        the :attr:`ready` models' blocks."""
        return self._evaluate().published(self.sizes, self._ready)

    def standard_errors(self, j: int, kind: str = "corrected") -> np.ndarray:
        """Square roots of the covariance diagonal (never NaN: see :meth:`covariance`)."""
        check_kind(kind)
        self._require(j)
        return self.standard_errors_all(kind)[j, : self.sizes[j]].copy()

    # ------------------------------------------------------------------ snapshot
    def state(self) -> dict[str, Any]:
        """A deep copy of the complete state; :meth:`from_state` continues bit-identically."""
        return state.capture(self)

    @classmethod
    def from_state(cls, saved: Mapping[str, Any]) -> EstimatorBank:
        """Rebuild an estimator bank from :meth:`state` (also after a save to disk)."""
        state.check_format(saved)
        cfg = dict(saved["config"])
        bank = cls(cfg.pop("sizes"), cfg.pop("n_lags"), cfg.pop("window"), cfg.pop("forgetting"), **cfg)
        state.restore(bank, saved)
        return bank
