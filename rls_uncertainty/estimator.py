"""Recursive least squares with a colored-residual parameter covariance.

Grauer & Morelli, "Parameter Uncertainty for Aircraft Aerodynamic Modeling using Recursive
Least Squares" (AIAA SciTech 2016), Eqs. 6-22. This module imports numpy only.

Notation (paper): regressor row ``x_k`` (n), measured output ``z_k``, estimate ``theta_k``,
dispersion ``D_k = (X'X)^-1``, residual ``v_k``, residual autocorrelation ``R_k(i)`` and lag
products ``Lambda_k(i)``.

Design notes
------------
* **One implementation.** :class:`EstimatorBank` runs ``M`` independent models (the six
  coefficient models of Eq. 2 have 3-6 parameters) with one set of vectorised numpy
  operations per sample; :class:`RecursiveEstimator` is a bank of one.
* **Residual for Eqs. 16-17.** The default is the *standardized* residual
  ``w_k = e_k sqrt(f / d_k)``, where ``e_k = z_k - x_k' theta_{k-1}`` is the a priori
  innovation and ``d_k = f + x_k' D_{k-1} x_k``; ``w_k^2 = e_k v_k`` is the product of the a
  priori and the a posteriori residual ``v_k = z_k - x_k' theta_k = e_k f / d_k``. With it,
  Eq. 16 is exact: the residual sum of squares of the batch fit over samples ``1..k`` obeys
  ``RSS_k = f RSS_{k-1} + e_k^2 f / d_k`` (Brown, Durbin & Evans 1975), so ``R_k(0)`` equals
  the batch fit-error variance of Eq. 14 at every sample, and the conventional recursive
  standard errors equal the batch ones. The a posteriori residual (``residual=
  "a_posteriori"``) shrinks early residuals by the leverage ``x_k' D_k x_k``: ``R_k(0)``
  falls short of Eq. 14 by about ``n ln(k) / k``, and the corrected standard errors of the
  Table 3 simulation by 2-3 %. The a priori innovation (``"a_priori"``) inflates them.
* **Exact initialization** (default). Until the weighted ``X'X`` of the first samples is
  well conditioned (after column scaling, condition number below ``init_condition``), a model
  only accumulates normal equations and lagged moments. At that sample ``k0`` it takes the
  batch solution (Eq. 6), defines the residuals of samples ``1..k0`` with it, and continues
  with Eq. 15; recursive and batch estimates then agree for every ``k >= k0`` whatever the
  regressor scales. ``p0`` selects the customary prior ``D_0 = p0 I`` instead (SIDPAC uses
  ``1e6``); that prior biases parameters whose regressors are small, such as ``q cbar/2V``.
* **Column scaling.** Internally each model works on regressors divided by the column norms
  found at initialization, which keeps ``D`` well conditioned when the regressors span six
  orders of magnitude; results are scaled back on output.
* **Lag products.** ``U_k(i) = sum_j w x_{j-i} x_j'`` is stored one-sided, so that
  ``Lambda_k(i) = U_k(i) + U_k(i)'`` (Eq. 21); the symmetrisation happens once per covariance
  evaluation on an ``n x n`` matrix instead of once per lag and sample. The products are kept
  for ``y = (x, z)``: the ``x`` block is Eq. 21 and the ``z`` row and column are the lagged
  moments exact initialization needs, so one outer product per sample updates both.
* **Per-sample cost.** Eq. 17 is kept as lag sums ``S_k(i) = f S_(k-1)(i) + v_k v_(k-i)``
  (``R_k(i) = S_k(i) / n_k``, the division done when a covariance is evaluated), the sample
  histories are written once into a newest-first buffer whose window is contiguous, and Eqs.
  15b-c are one rank-one update of ``(D, theta)``: about 20 numpy calls per sample for any
  number of models, the lag-product update (Eq. 21) being the only one whose cost grows with
  the lags.
* **Windows.** ``window="truncated"`` is Eq. 22 (uniform weights up to ``n_lags``).
  ``window="bartlett"`` uses ``1 - i/(n_lags+1)``: its Toeplitz kernel is positive
  semi-definite, and by the Schur product theorem so is the covariance; the uniform truncation
  can make the covariance indefinite. A covariance with a negative diagonal is replaced by the
  nearest positive semi-definite matrix (eigenvalues clipped at zero) and counted in
  :attr:`EstimatorBank.repairs`.
* **Forgetting** ``f < 1``: exponentially weighted RLS. ``D_k = (sum f^(k-j) x_j x_j')^-1``;
  ``Lambda_k(i) = f^2 Lambda_{k-1}(i) + f^i (x_k x_{k-i}' + x_{k-i} x_k')``, the weighting
  of the sandwich ``D X'W E[vv'] W X D``; ``R_k(i) = sum_j f^(k-j) v_j v_{j-i} / sum_j f^(k-j)``
  and the conventional covariance is ``R_k(0) D Lambda_k(0) D``. ``f = 1`` is exactly the paper.
"""

from __future__ import annotations

import math
from typing import Literal, Sequence, get_args

import numpy as np

from .errors import EstimatorNotReady, NonFiniteInput

__all__ = [
    "EstimatorBank",
    "RecursiveEstimator",
    "EstimatorNotReady",
    "NonFiniteInput",
    "batch_estimate",
    "lag_weights",
    "WINDOWS",
    "Window",
    "Residual",
    "CovarianceKind",
    "RESIDUALS",
    "COVARIANCE_KINDS",
]

# The estimator's choices, defined once: configuration, parameters and the command line read
# them from here.
Window = Literal["truncated", "bartlett"]
Residual = Literal["standardized", "a_posteriori", "a_priori"]
CovarianceKind = Literal["corrected", "conventional"]
WINDOWS: tuple[Window, ...] = get_args(Window)
RESIDUALS: tuple[Residual, ...] = get_args(Residual)
COVARIANCE_KINDS: tuple[CovarianceKind, ...] = get_args(CovarianceKind)

_GROWTH_START = 64  # initial lag capacity when all lags are kept (n_lags=None)

_F64 = np.dtype(np.float64)


def _einsum_vecdot(a: np.ndarray, b: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
    """``np.vecdot`` (numpy >= 2.0) for numpy 1.26: dot products over the last axis."""
    return np.einsum("...i,...i->...", a, b, out=out)


_vecdot = getattr(np, "vecdot", _einsum_vecdot)


def lag_weights(n_lags: int, window: str, count: int | None = None) -> np.ndarray:
    """Weights of lags ``0..count-1`` for Eq. 22 (``truncated``) or the Bartlett window.

    ``n_lags`` is the largest retained lag. For ``bartlett`` the weight of lag ``i`` is
    ``1 - i/(n_lags+1)``.
    """
    _check_window(window)
    count = n_lags + 1 if count is None else count
    i = np.arange(count, dtype=float)
    if window == "truncated":
        w = np.ones(count)
    else:
        w = 1.0 - i / (n_lags + 1.0)
    w[i > n_lags] = 0.0
    return w


def _check_window(window: str) -> None:
    if window not in WINDOWS:
        raise ValueError(f"window must be one of {WINDOWS}, got {window!r}")


def _check_kind(kind: str) -> None:
    if kind not in COVARIANCE_KINDS:
        raise ValueError(f"kind must be one of {COVARIANCE_KINDS}, got {kind!r}")


def nearest_psd(cov: np.ndarray) -> np.ndarray:
    """Nearest (Frobenius) symmetric positive semi-definite matrix: eigenvalues clipped at 0."""
    sym = 0.5 * (cov + cov.T)
    vals, vecs = np.linalg.eigh(sym)
    return (vecs * np.clip(vals, 0.0, None)) @ vecs.T


class EstimatorBank:
    """``M`` independent recursive least-squares models updated together (Eqs. 15-22).

    Parameters
    ----------
    sizes:
        Number of parameters of each model, e.g. ``(3, 4, 3, 6, 4, 4)`` for Eq. 2a-f.
    n_lags:
        Largest residual-autocorrelation lag kept (Eq. 22); ``None`` keeps all lags (Eq. 20,
        memory and time grow with the number of samples). ``0`` gives the conventional
        covariance.
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
    """

    def __init__(
        self,
        sizes: Sequence[int],
        n_lags: int | None = None,
        window: str = "truncated",
        forgetting: float = 1.0,
        *,
        residual: str = "standardized",
        p0: float | Sequence[float] | None = None,
        init_condition: float = 1e8,
    ) -> None:
        sizes = tuple(int(s) for s in sizes)
        if not sizes or min(sizes) < 1:
            raise ValueError(f"every model needs at least one parameter, got sizes={sizes}")
        if n_lags is not None and (isinstance(n_lags, bool) or int(n_lags) != n_lags or n_lags < 0):
            raise ValueError(f"n_lags must be None or an integer >= 0, got {n_lags!r}")
        _check_window(window)
        if not (0.0 < float(forgetting) <= 1.0):
            raise ValueError(f"forgetting must be in (0, 1], got {forgetting!r}")
        if residual not in RESIDUALS:
            raise ValueError(f"residual must be one of {RESIDUALS}, got {residual!r}")
        if not float(init_condition) > 1.0:
            raise ValueError(f"init_condition must be > 1, got {init_condition!r}")

        self.sizes = sizes
        self.n_models = m = len(sizes)
        self.n_max = n = max(sizes)
        self.n_lags = None if n_lags is None else int(n_lags)
        self.window = window
        self.forgetting = float(forgetting)
        self.residual = residual
        self.init_condition = float(init_condition)

        self._x_shape, self._z_shape = (m, n), (m,)
        self._mask = np.zeros((m, n), dtype=bool)
        for j, s in enumerate(sizes):
            self._mask[j, :s] = True

        self.k = 0
        self.n_eff = 0.0  # sum_j f^(k-j); equals k when f = 1
        # _aug[:, :n] is the scaled dispersion S D S, _aug[:, n] the scaled estimate S theta:
        # one matmul gives both D x and theta' x.
        self._aug = np.zeros((m, n + 1, n))
        self._inv_s = self._mask.astype(float)  # 1/s on real parameters, 0 on padding
        self._ready = np.zeros(m, dtype=bool)
        self._ready_at = np.zeros(m, dtype=np.int64)
        self.repairs = np.zeros(m, dtype=np.int64)
        self._zz = np.zeros(m)  # sum f^(k-j) z_j^2, the scale of an exact fit
        # Lag capacity: W = n_lags + 1 lags; all lags (n_lags=None) grow on demand.
        self._cap = _GROWTH_START if self.n_lags is None else self.n_lags + 1
        self._alloc_lag_arrays(self._cap)
        self._cache: dict = {}
        self._weights_key = None
        self._all_ready = False
        self._weights_cached = None

        if p0 is not None:
            p = np.asarray(p0, dtype=float)
            p = np.full(n, float(p)) if p.ndim == 0 else p.reshape(-1)
            if p.shape != (n,):
                raise ValueError(f"p0 must be a scalar or have {n} entries, got {p.shape}")
            if not np.all(np.isfinite(p)) or np.any(p <= 0):
                raise ValueError(f"p0 must be positive and finite, got {p0!r}")
            self._aug[:, :n] = np.eye(n) * p * self._mask[:, :, None] * self._mask[:, None, :]
            self._ready[:] = True
            self._all_ready = True
        self._set_scale()

    # ------------------------------------------------------------------ storage
    def _alloc_lag_arrays(self, cap: int) -> None:
        m, n = self.n_models, self.n_max
        n1 = n + 1
        # History of y_k = (scaled regressors, output) and of the residuals, newest first:
        # the last min(k, cap) samples are the contiguous slice [_ptr, _ptr + w). Each sample
        # is written once, at _ptr - 1; when it lands on slot 0 the window is copied back to
        # the end (once every 3 cap samples). With all lags the buffer is exactly the capacity
        # and fills up when the capacity is reached, just before it grows (_grow). The outputs
        # are needed until initialization.
        length = 4 * cap if self.n_lags is not None else cap
        self._ybuf = np.zeros((m, length, n1))
        # The residuals are stored with the opposite sign, -v_k = x_k' theta - z_k: the
        # products v_k v_(k-i) of Eq. 17 do not see it, and the update saves a negation.
        self._vbuf = np.zeros((m, length))
        self._ptr = length
        # Eq. 17 as sums: _S[:, i] = sum_j f^(k-j) v_j v_(j-i), so that R_k(i) = _S[:, i] / n_eff.
        self._S = np.zeros((m, cap))
        # Lag products of y = (x, z), one-sided Eq. 21 on the x block:
        # _Q[m, a, i, b] = sum_j f^(2(k-j)) f^i y_j[a] y_(j-i)[b], so that the x block
        # _Q[m, :n, i, :n] is U_k(i)' with Lambda_k(i) = U_k(i) + U_k(i)'. The z row and column
        # are the lagged moments X'z, z'z that exact initialization needs (with f = 1; under
        # forgetting those are kept in _P with weight f per sample). The layout keeps each
        # (m, a) block contiguous, so one outer product per sample updates every lag.
        self._Q = np.zeros((m, n1, cap, n1))
        self._tmp = np.zeros((m, n1, cap, n1))
        self._P = np.zeros((m, n1, cap, n1)) if self.forgetting != 1.0 else None
        self._lag_pow = self.forgetting ** np.arange(cap, dtype=float)
        self._bind_views()

    def _bind_views(self) -> None:
        """Views and scratch arrays the per-sample update reuses (rebuilt with the arrays)."""
        m, n, cap = self.n_models, self.n_max, self._cap
        n1 = n + 1
        self._Q_flat = self._Q.reshape(m, n1, cap * n1)
        self._U_full = self._Q[:, :n, :, :n]
        self._zz_view = self._Q[:, n, 0, n]  # sum of z^2 (f = 1)
        self._D_view = self._aug[:, :n]
        self._D_diag = np.diagonal(self._D_view, axis1=1, axis2=2)
        self._tmp_flat = self._tmp.reshape(m, n1, cap * n1)
        self._g = np.zeros((m, n1, 1))  # (D x, theta' x) as a column
        self._g2 = self._g[:, :, 0]
        self._Dx = self._g2[:, :n]
        self._Dx_row = self._g[:, None, :n, 0]
        self._gz = self._g2[:, n]
        self._outer = np.zeros((m, n1, n))
        self._waiting = None  # see _check_initialization
        self._invalid_mask = None  # see _invalid

    _LAG_ARRAYS = ("_ybuf", "_vbuf", "_S", "_Q", "_P")

    @property
    def _U(self) -> np.ndarray:
        """One-sided Eq. 21, transposed: ``_U[m, b, i, a] = sum x_(j-i)[a] x_j[b]``."""
        return self._Q[:, : self.n_max, :, : self.n_max]

    def _grow(self) -> None:
        """Double the lag capacity (all-lags mode only)."""
        old, w, p = self._cap, self.n_window, self._ptr
        keep = {name: getattr(self, name) for name in self._LAG_ARRAYS}
        self._cap = 2 * old
        self._alloc_lag_arrays(self._cap)
        for name, arr in keep.items():
            if arr is None:
                continue
            if name in ("_Q", "_P"):
                getattr(self, name)[:, :, :old] = arr
            elif name == "_S":
                self._S[:, :old] = arr
            else:
                getattr(self, name)[:, self._ptr - w :] = arr[:, p : p + w]
        self._ptr -= w

    def _relocate(self) -> None:
        """Move the history window from the buffer's front back to its end, making room for
        the next samples (called when the newest sample was written at slot 0)."""
        w = self.n_window
        length = self._vbuf.shape[1]
        self._ybuf[:, length - w :] = self._ybuf[:, :w]
        self._vbuf[:, length - w :] = self._vbuf[:, :w]
        self._ptr = length - w

    def _recent(self, buf: np.ndarray) -> np.ndarray:
        """View of the last ``min(k, W)`` entries of a history buffer, newest first."""
        return buf[:, self._ptr : self._ptr + self.n_window]

    @property
    def n_window(self) -> int:
        """Number of lags currently held: ``min(k, n_lags + 1)``, or ``k`` for all lags."""
        return min(self.k, self._cap)

    # ------------------------------------------------------------------ update
    def update(self, X, z) -> None:
        """Process one sample for every model.

        ``X`` is ``(M, n_max)`` (row ``j`` holds model ``j``'s regressors first; the padding
        is ignored) or a sequence of ``M`` regressor vectors; ``z`` holds the ``M`` measured
        outputs. Non-finite input raises :class:`NonFiniteInput` and leaves the state unchanged.
        """
        if type(X) is np.ndarray and X.shape == self._x_shape and X.dtype == _F64:
            x = X
        else:
            x = self._as_regressors(X)
        if not (type(z) is np.ndarray and z.shape == self._z_shape and z.dtype == _F64):
            z = np.asarray(z, dtype=float).reshape(-1)
            if z.shape != (self.n_models,):
                raise ValueError(f"expected {self.n_models} measured outputs, got shape {z.shape}")
        n, f, m = self.n_max, self.forgetting, self.n_models
        k = self.k + 1
        if k > self._cap and self.n_lags is None:
            self._grow()
        # y_k = (scaled regressors, output), written straight into its history slot (outside
        # the current window, so a rejected sample leaves the state unchanged).
        p = self._ptr - 1  # >= 0: see _relocate
        y = self._ybuf[:, p]
        xs = y[:, :n]
        np.multiply(x, self._inv_s, out=xs)
        y[:, n] = z
        if not math.isfinite(float(y.sum())):
            # NaN or Inf somewhere, or only an overflow of the sum: check exactly.
            bad = [
                j for j in range(m)
                if not (np.isfinite(x[j, : self.sizes[j]]).all() and np.isfinite(z[j]))
            ]
            if bad:
                raise NonFiniteInput(
                    f"non-finite regressor or output for model(s) {bad}; sample ignored"
                )
            xs[...] = np.where(self._mask, xs, 0.0)  # non-finite padding is ignored
        self.k = k
        self._ptr = p
        self.n_eff = f * self.n_eff + 1.0

        # Eq. 15 in covariance form (with forgetting, D is divided by f). One matmul gives
        # g = (D x, theta' x); with u = (D x, theta' x - z) = (D x, -e), the rank-one update
        # _aug -= u (D x)' / d is Eq. 15b on the D rows and Eq. 15c (theta += D x e / d) on
        # the theta row. D - (Dx)(Dx)'/d is exactly symmetric in floating point; the
        # algebraically equal (I - K x') D is not, and under forgetting its antisymmetric
        # rounding error grows like f^-k until the estimator diverges.
        np.matmul(self._aug, xs[:, :, None], out=self._g)
        d = _vecdot(xs, self._Dx)
        d += f
        neg_e = np.subtract(self._gz, z, out=self._gz)  # -(z_k - x_k' theta_{k-1}), a priori
        outer = np.multiply(self._g, self._Dx_row, out=self._outer)
        outer /= d[:, None, None]
        self._aug -= outer
        if f != 1.0:
            self._aug[:, :n] /= f
        v = self._vbuf[:, p]  # -v_k (see _alloc_lag_arrays)
        if self.residual == "standardized":
            np.divide(neg_e, np.sqrt(d) if f == 1.0 else np.sqrt(d / f), out=v)
        elif self.residual == "a_posteriori":
            np.multiply(neg_e / d, f, out=v)  # e f/d = z_k - x_k' theta_k
        else:
            v[...] = neg_e

        w = k if k < self._cap else self._cap  # lags held
        # Eq. 17 as sums: S_k(i) = f S_(k-1)(i) + v_k v_(k-i).
        S = self._S[:, :w]
        if f != 1.0:
            S *= f
            self._zz *= f  # with f = 1 the sum of z^2 is the lag-0 z z entry of _Q
            self._zz += z * z
        S += self._vbuf[:, p : p + w] * v[:, None]
        # Eq. 21 (one-sided): U_k(i) = f^2 U_{k-1}(i) + f^i x_{k-i} x_k', for y = (x, z).
        # Views as (M, n+1, w (n+1)) make the inner loops contiguous.
        n1 = n + 1
        yl = self._ybuf[:, p : p + w].reshape(m, 1, w * n1)  # y_k, y_(k-1), ... (a view)
        if w == self._cap:
            Q, tmp = self._Q_flat, self._tmp_flat
        else:
            Q = self._Q[:, :, :w].reshape(m, n1, w * n1)
            tmp = self._tmp[:, :, :w].reshape(m, n1, w * n1)
        if f == 1.0:
            np.multiply(y[:, :, None], yl, out=tmp)
            Q += tmp
        else:
            lagged = yl.reshape(m, w, n1) * self._lag_pow[None, :w, None]
            np.multiply(y[:, :, None], lagged.reshape(m, 1, w * n1), out=tmp)
            self._Q *= f * f
            Q += tmp
            if not self._all_ready:  # the moments for exact initialization: weight f per sample
                P = self._P[:, :, :w].reshape(m, n1, w * n1)
                np.multiply(y[:, :, None], yl, out=tmp)
                self._P *= f
                P += tmp
        if not self._all_ready:
            self._check_initialization(w)
        if p == 0 and self.n_lags is not None:
            self._relocate()
        self._cache.clear()

    def _as_regressors(self, X) -> np.ndarray:
        if isinstance(X, np.ndarray) and X.shape == (self.n_models, self.n_max):
            return X if X.dtype == float else X.astype(float)
        rows = [X] if isinstance(X, np.ndarray) and X.ndim == 1 else list(X)
        if len(rows) != self.n_models:
            raise ValueError(f"expected regressors for {self.n_models} models, got {len(rows)}")
        x = np.zeros((self.n_models, self.n_max))
        for j, (row, s) in enumerate(zip(rows, self.sizes)):
            row = np.asarray(row, dtype=float).reshape(-1)
            if row.shape != (s,):
                raise ValueError(f"model {j} has {s} parameters, got {row.shape[0]} regressors")
            x[j, :s] = row
        return x

    def _check_initialization(self, w: int) -> None:
        """Exact initialization of the models still waiting, where their X'X allows it.

        Only a model whose ``X'X`` has a positive diagonal can be well conditioned. A zero
        diagonal entry (a regressor that has been exactly zero so far, such as a surface
        that never moved) is remembered as the model's blocker, and only that one number is
        looked at until it becomes positive.
        """
        waiting = self._waiting
        if waiting is None:
            # Flat indices of each waiting model's lag-0 X'X diagonal (rebuilt whenever a
            # model initializes or the arrays are reallocated), and its blocker.
            n1, cap = self.n_max + 1, self._cap
            waiting = self._waiting = [
                [j, np.array([((j * n1 + a) * cap) * n1 + a for a in range(self.sizes[j])], dtype=np.intp), None]
                for j in range(self.n_models) if not self._ready[j]
            ]
        flat = (self._Q if self._P is None else self._P).reshape(-1)
        for entry in waiting:
            blocker = entry[2]
            if blocker is not None and not flat[blocker] > 0.0:
                continue
            diag = flat.take(entry[1])
            zero = np.flatnonzero(~(diag > 0.0))
            if zero.size:
                entry[2] = int(entry[1][zero[0]])
                continue
            entry[2] = None
            self._try_initialize(entry[0], w)  # rebuilds the waiting list on success

    def _try_initialize(self, j: int, w: int) -> bool:
        """Exact initialization of model ``j`` at the current sample, if X'X allows it."""
        s_n = self.sizes[j]
        if self.k < s_n:
            return False
        # Before initialization inv_s is 1 on real parameters, so the moments are unscaled.
        Pj = self._Q[j] if self._P is None else self._P[j]  # (n+1, cap, n+1)
        P0 = Pj[:, 0, :]
        A = P0[:s_n, :s_n]
        s = np.sqrt(np.diag(A))
        if not np.all(s > 0):
            return False
        C = A / np.outer(s, s)
        if not np.linalg.cond(C) < self.init_condition:
            return False
        Cinv = np.linalg.inv(C)
        Cinv = 0.5 * (Cinv + Cinv.T)  # scaled D = S (X'X)^-1 S
        theta_scaled = Cinv @ (P0[:s_n, self.n_max] / s)  # Eq. 6
        n = self.n_max
        self._aug[j, :s_n, :s_n] = Cinv
        self._aug[j, n, :s_n] = theta_scaled
        self._inv_s[j, :s_n] = 1.0 / s
        # Residuals of samples 1..k0 with the batch solution; R(i) from the lagged moments:
        # v_j = ta' y_j with ta = (-theta, 1), so sum v_j v_{j-i} = ta' P(i) ta.
        ta = np.zeros(n + 1)
        ta[:s_n] = -theta_scaled / s
        ta[n] = 1.0
        nR = np.einsum("a,aib,b->i", ta, Pj[:, :w, :], ta)
        self._S[j, :w] = nR
        inv = self._inv_s[j]
        self._Q[j, :n] *= inv[:, None, None]  # x rows and columns to scaled units
        self._Q[j, :, :, :n] *= inv[None, None, :]
        xb = self._ybuf[j, :, :n]
        xb *= inv[None, :]
        self._vbuf[j] = xb @ self._aug[j, n] - self._ybuf[j, :, n]  # -v_j
        self._ready[j] = True
        self._ready_at[j] = self.k
        self._waiting = None
        self._invalid_mask = None
        self._set_scale()
        self._all_ready = bool(self._ready.all())
        return True

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
        return self._aug[j, self.n_max, :s_n] * self._inv_s[j, :s_n]

    def residual_variance(self, j: int) -> float:
        """Fit-error variance (Eq. 16), i.e. ``R_k(0)``."""
        self._require(j)
        return float(self._S[j, 0] / self.n_eff)

    def autocorrelation(self, j: int) -> np.ndarray:
        """Residual autocorrelation ``R_k(i)``, ``i = 0..n_window-1`` (Eq. 17)."""
        self._require(j)
        return self._S[j, : self.n_window] / self.n_eff

    def residuals(self, j: int) -> np.ndarray:
        """Stored residuals, oldest first: the whole history with ``n_lags=None``, otherwise
        the last ``n_lags + 1``."""
        self._require(j)
        return -self._recent(self._vbuf)[j, ::-1]

    def _weights(self, w: int) -> np.ndarray:
        """Lag weights of Eq. 22 / Bartlett for ``w`` lags, halved at lag 0 (U(0) + U(0)')."""
        largest = self.k - 1 if self.n_lags is None else self.n_lags
        if self._weights_key != (largest, w):
            weights = lag_weights(largest, self.window, w)
            weights[0] *= 0.5
            self._weights_cached, self._weights_key = weights, (largest, w)
        return self._weights_cached

    def _middle_one_sided(self) -> np.ndarray:
        """``N`` with ``N + N' = n_eff sum_i c_i R_k(i) Lambda_k(i)`` (Eqs. 20, 22), i.e. with
        the lag sums of :attr:`_S` in place of ``R_k(i)``; ``(M, n, n)``."""
        N = self._cache.get("N")
        if N is None:
            w = self.n_window
            cS = self._S[:, :w] * self._weights(w)
            # N'[b, a] = sum_i cS_i U[b, i, a]
            U = self._U_full if w == self._cap else self._U[:, :, :w]
            N = self._cache["N"] = np.matmul(cS[:, None, None, :], U)[:, :, 0, :]
        return N

    def _variance_pair(self) -> np.ndarray:
        """Diagonals of the corrected (``[0]``, Eq. 20/22) and conventional (``[1]``, Eq. 13)
        covariances of all models, ``(2, M, n_max)``, in one pass; negative corrected ones
        are repaired (see :meth:`_covariances`). Padding and models that are not ready are
        NaN."""
        D = self._D_view
        var = np.empty((2,) + D.shape[:2])
        # diag(D (N + N') D) = 2 diag(D N D) = 2 sum_c (D N)_ac D_ac because D is symmetric
        # (the 2 is in _var_scale).
        _vecdot(np.matmul(D, self._middle_one_sided()), D, out=var[0])
        if self.forgetting == 1.0:
            np.multiply(self._S[:, :1], self._D_diag, out=var[1])  # Eq. 13 with Eq. 16
        else:
            Nc = (0.5 * self._S[:, 0, None, None]) * self._U[:, :, 0, :]
            _vecdot(np.matmul(D, Nc), D, out=var[1])
        corrected = var[0]
        repair = corrected.min() < 0.0  # the scale below is positive (NaN where invalid)
        if repair:
            np.copyto(corrected, 0.0, where=self._exact_fit()[:, None])
            repair = corrected.min() < 0.0
        var *= self._var_scale * (1.0 / self.n_eff)  # lag sums to R_k(i), scaled units back
        if repair:
            for j in np.flatnonzero(self._ready & (corrected < 0.0).any(axis=1)):
                corrected[j, : self.sizes[j]] = np.diag(self._covariances("corrected")[j])
        return var

    def _exact_fit(self) -> np.ndarray:
        """Models whose residual variance is below 1e-12 of the output's mean square: an
        exact fit (no noise), whose covariances are zero. Their corrected variances come out
        as tiny numbers of either sign from rounding; they are set to zero, not repaired."""
        zz = self._zz_view if self.forgetting == 1.0 else self._zz
        return self._S[:, 0] <= 1e-12 * zz

    def standard_errors_all(self, kind: str = "corrected") -> np.ndarray:
        """Standard errors of every model as an ``(M, n_max)`` array (one vectorised pass
        computes both kinds).

        Padding and the rows of models that are not :attr:`ready` are NaN.
        """
        _check_kind(kind)
        se = self._cache.get("se")
        if se is None:
            se = self._variance_pair()
            np.maximum(se, 0.0, out=se)
            np.sqrt(se, out=se)
            self._cache["se"] = se
        return se[0] if kind == "corrected" else se[1]

    def _set_scale(self) -> None:
        """Column scaling of the variances: ``2/s^2`` for the one-sided products, ``1/s^2``
        for Eq. 13 (two-sided under forgetting); NaN on the padding and the models not ready,
        so that their standard errors come out NaN."""
        self._theta_scale = np.where(self._invalid(), np.nan, self._inv_s)
        inv_s2 = self._theta_scale * self._theta_scale
        self._var_scale = np.stack([2.0 * inv_s2, inv_s2 if self.forgetting == 1.0 else 2.0 * inv_s2])

    def theta_all(self) -> np.ndarray:
        """Estimates of every model as an ``(M, n_max)`` array; padding and models that are
        not :attr:`ready` are NaN."""
        return self._aug[:, self.n_max] * self._theta_scale

    def _invalid(self) -> np.ndarray:
        """``(M, n_max)`` mask of the padding and the models not ready (NaN in outputs)."""
        if self._invalid_mask is None:
            self._invalid_mask = ~(self._mask & self._ready[:, None])
        return self._invalid_mask

    def _covariances(self, kind: str) -> dict:
        """Full covariances of the ready models, repaired where a diagonal is negative."""
        key = ("cov", kind)
        if key in self._cache:
            return self._cache[key]
        out: dict[int, np.ndarray] = {}
        raw = self._raw_covariances(kind)
        exact = None
        for j, cov in raw.items():
            if kind == "corrected" and np.any(np.diag(cov) < 0.0):
                exact = self._exact_fit() if exact is None else exact
                if exact[j]:
                    cov = np.zeros_like(cov)  # rounding of an exact fit, not indefiniteness
                else:
                    cov = nearest_psd(cov)
                    self.repairs[j] += 1
            out[j] = cov
        self._cache[key] = out
        return out

    def _raw_covariances(self, kind: str) -> dict:
        key = ("raw", kind)
        if key in self._cache:
            return self._cache[key]
        n = self.n_max
        D = self._aug[:, :n]
        R0 = self._S[:, 0, None, None] / self.n_eff
        if kind == "conventional" and self.forgetting == 1.0:
            cov_s = R0 * D  # Eq. 13 with Eq. 16
        elif kind == "conventional":
            cov_s = R0 * (D @ self._U[:, :, 0, :] @ D)
        else:
            N = self._middle_one_sided()
            cov_s = D @ (N + N.swapaxes(1, 2)) @ D * (1.0 / self.n_eff)  # Eq. 20 / 22
        cov_all = cov_s * self._inv_s[:, :, None] * self._inv_s[:, None, :]
        out = {
            int(j): cov_all[j, : self.sizes[j], : self.sizes[j]] for j in np.flatnonzero(self._ready)
        }
        self._cache[key] = out
        return out

    def covariance(self, j: int, kind: str = "corrected", *, repair: bool = True) -> np.ndarray:
        """Parameter covariance of model ``j``.

        ``kind="corrected"``: Eq. 20 (all lags) or Eq. 22 (``n_lags``) with the chosen window.
        ``kind="conventional"``: Eq. 13 with the fit-error variance of Eq. 16.
        With ``repair`` (default) a corrected covariance with a negative diagonal is replaced
        by the nearest positive semi-definite matrix and counted in :attr:`repairs` (once per
        sample).
        """
        _check_kind(kind)
        self._require(j)
        src = self._covariances(kind) if repair else self._raw_covariances(kind)
        return src[j].copy()

    def standard_errors(self, j: int, kind: str = "corrected") -> np.ndarray:
        """Square roots of the covariance diagonal (never NaN: see :meth:`covariance`)."""
        _check_kind(kind)
        self._require(j)
        return self.standard_errors_all(kind)[j, : self.sizes[j]].copy()

    # ------------------------------------------------------------------ snapshot
    STATE_FORMAT = 3  # 2: lagged moments as one array of y = (x, z) products; 3: Eq. 17 as sums
    _STATE_ARRAYS = (
        "_aug", "_inv_s", "_ready", "_ready_at", "repairs", "_zz",
        "_ybuf", "_vbuf", "_S", "_Q", "_P",
    )

    def state(self) -> dict:
        """A deep copy of the complete state; :meth:`from_state` continues bit-identically."""
        config = {
            "sizes": list(self.sizes),
            "n_lags": self.n_lags,
            "window": self.window,
            "forgetting": self.forgetting,
            "residual": self.residual,
            "init_condition": self.init_condition,
        }
        counters = {"k": self.k, "n_eff": self.n_eff, "cap": self._cap}
        arrays = {
            name.lstrip("_"): getattr(self, name).copy()
            for name in self._STATE_ARRAYS
            if getattr(self, name) is not None
        }
        # The histories as their windows, newest first (where they sit in the buffer is not
        # part of the state).
        arrays["ybuf"] = self._recent(self._ybuf).copy()
        arrays["vbuf"] = -self._recent(self._vbuf)  # the residuals v_k
        return {"format": self.STATE_FORMAT, "config": config, "counters": counters, "arrays": arrays}

    @classmethod
    def from_state(cls, state: dict) -> "EstimatorBank":
        """Rebuild an estimator bank from :meth:`state` (also after a save to disk)."""
        if state.get("format") != cls.STATE_FORMAT:
            raise ValueError(
                f"unknown estimator state format {state.get('format')!r} "
                f"(this version reads format {cls.STATE_FORMAT})"
            )
        cfg = dict(state["config"])
        bank = cls(
            cfg.pop("sizes"), cfg.pop("n_lags"), cfg.pop("window"), cfg.pop("forgetting"), **cfg
        )
        c = state["counters"]
        bank.k, bank.n_eff = int(c["k"]), float(c["n_eff"])
        cap = int(c["cap"])
        if cap != bank._cap:
            bank._cap = cap
            bank._alloc_lag_arrays(cap)
        w = bank.n_window
        bank._ptr -= w
        for name in cls._STATE_ARRAYS:
            if getattr(bank, name) is None:
                continue
            arr = np.array(state["arrays"][name.lstrip("_")], copy=True)
            if name in ("_ybuf", "_vbuf"):
                target = bank._recent(getattr(bank, name))
                if arr.shape != target.shape:
                    raise ValueError(f"estimator state field {name!r} has shape {arr.shape}")
                target[...] = -arr if name == "_vbuf" else arr
                continue
            if arr.shape != getattr(bank, name).shape:
                raise ValueError(f"estimator state field {name!r} has shape {arr.shape}")
            setattr(bank, name, arr)
        bank._all_ready = bool(bank._ready.all())
        bank._bind_views()
        bank._set_scale()
        return bank


class RecursiveEstimator:
    """Recursive least squares for one model, with corrected and conventional covariances.

    ``RecursiveEstimator(n_params, n_lags=None, window="truncated", forgetting=1.0)``;
    keyword options as for :class:`EstimatorBank`. ``update(x, z)`` processes one sample.
    """

    def __init__(
        self,
        n_params: int,
        n_lags: int | None = None,
        window: str = "truncated",
        forgetting: float = 1.0,
        **options,
    ) -> None:
        self._bank = EstimatorBank((int(n_params),), n_lags, window, forgetting, **options)

    @classmethod
    def _wrap(cls, bank: EstimatorBank) -> "RecursiveEstimator":
        est = cls.__new__(cls)
        est._bank = bank
        return est

    def update(self, x, z) -> None:
        """Eq. 15-17, 21 for one sample; non-finite input raises :class:`NonFiniteInput`."""
        x = np.asarray(x, dtype=float).reshape(1, -1)
        if x.shape[1] != self._bank.n_max:
            raise ValueError(f"expected {self._bank.n_max} regressors, got {x.shape[1]}")
        self._bank.update(x, np.asarray([z], dtype=float).reshape(1))

    @property
    def n_params(self) -> int:
        return self._bank.n_max

    @property
    def n_lags(self):
        return self._bank.n_lags

    @property
    def n_samples(self) -> int:
        return self._bank.k

    @property
    def is_ready(self) -> bool:
        return bool(self._bank.ready[0])

    @property
    def theta(self) -> np.ndarray:
        return self._bank.theta(0)

    @property
    def repairs(self) -> int:
        """How many evaluated corrected covariances needed a positive semi-definite repair."""
        return int(self._bank.repairs[0])

    @property
    def residual_variance(self) -> float:
        return self._bank.residual_variance(0)

    def autocorrelation(self) -> np.ndarray:
        return self._bank.autocorrelation(0)

    def residuals(self) -> np.ndarray:
        return self._bank.residuals(0)

    def covariance(self, kind: str = "corrected", *, repair: bool = True) -> np.ndarray:
        return self._bank.covariance(0, kind, repair=repair)

    def standard_errors(self, kind: str = "corrected") -> np.ndarray:
        return self._bank.standard_errors(0, kind)

    def state(self) -> dict:
        return self._bank.state()

    @classmethod
    def from_state(cls, state: dict) -> "RecursiveEstimator":
        if len(state["config"]["sizes"]) != 1:
            raise ValueError("state holds several models: use EstimatorBank.from_state")
        return cls._wrap(EstimatorBank.from_state(state))


def batch_estimate(
    X: np.ndarray,
    z: np.ndarray,
    n_lags: int | None = None,
    window: str = "truncated",
    residuals: np.ndarray | None = None,
    *,
    forgetting: float = 1.0,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Batch least squares with conventional and colored-residual covariances.

    Returns ``(theta, cov_conventional, cov_corrected)``: Eq. 6 for ``theta``, Eq. 13-14 for
    the conventional covariance and Eq. 8-11 (the Toeplitz form of Eq. 9 with the sample
    autocorrelation of Eq. 10, lags beyond ``n_lags`` dropped or Bartlett-weighted) for the
    corrected one. ``residuals`` replaces ``z - X theta`` in Eq. 10 (for instance the residual
    history of a recursive estimator). ``forgetting < 1`` gives the exponentially weighted
    formulas that :class:`EstimatorBank` implements recursively.
    """
    X = np.asarray(X, dtype=float)
    z = np.asarray(z, dtype=float).reshape(-1)
    if X.ndim != 2 or X.shape[0] != z.shape[0]:
        raise ValueError(f"X must be (N, n) with N = len(z); got {X.shape} and {z.shape}")
    _check_window(window)
    N, n = X.shape
    wts = forgetting ** np.arange(N - 1, -1, -1, dtype=float)
    sw = np.sqrt(wts)
    theta = np.linalg.lstsq(X * sw[:, None], z * sw, rcond=None)[0]
    A = X.T @ (X * wts[:, None])
    D = np.linalg.inv(A)
    v = z - X @ theta if residuals is None else np.asarray(residuals, dtype=float).reshape(-1)
    if v.shape != (N,):
        raise ValueError(f"residuals must have {N} entries, got {v.shape}")
    L = N - 1 if n_lags is None else min(int(n_lags), N - 1)
    # Eq. 10 (weighted): R(i) = sum_{j>i} w_j v_j v_{j-i} / sum_j w_j
    R = np.array([np.dot(wts[i:] * v[i:], v[: N - i]) for i in range(L + 1)]) / wts.sum()
    kernel = R * lag_weights(L if n_lags is None else int(n_lags), window, L + 1)
    Xw = X * wts[:, None]
    if forgetting == 1.0:
        cov_conv = R[0] * D  # Eq. 13
    else:
        cov_conv = R[0] * D @ (Xw.T @ Xw) @ D
    # Eq. 11: D [sum_j sum_l x_j R(j-l) x_l'] D, in row blocks to bound memory.
    middle = np.zeros((n, n))
    cols = np.arange(N)
    block = max(1, min(N, 2_000_000 // max(N, 1)))
    for start in range(0, N, block):
        rows = np.arange(start, min(N, start + block))
        lag = np.abs(rows[:, None] - cols[None, :])
        T = np.where(lag <= L, kernel[np.minimum(lag, L)], 0.0)
        middle += Xw[rows].T @ (T @ Xw)
    cov_corr = D @ middle @ D
    return theta, cov_conv, cov_corr
