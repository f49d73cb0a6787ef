"""Eqs. 6-22 of Grauer & Morelli (2016), written as the paper writes them.

This module is the executable specification of the estimator and the oracle of its tests,
not the hot path: one statement per equation, in the paper's symbols (``D``, ``K``,
``theta``, ``v``, ``R(i)``, ``Lambda(i)``), plain loops over samples and lags, no column
scaling, no buffers. :class:`~.bank.EstimatorBank` must give the same numbers (to rounding)
for every option; ``test/test_estimator_reference.py`` checks that, and checks this module
against closed forms.

What the paper leaves open is defined here, and the fast bank follows it:

* **Instrumental variables** (:func:`batch_iv`): the estimate ``(Z'X)^-1 Z'z`` and Eq. 8 with
  the instruments ``Z`` in place of the regressors beside ``R``; the bank's recursive form is
  :mod:`.iv_fit`.
* **Forgetting** ``0 < f <= 1`` (``f = 1`` is the paper). At sample ``k`` sample ``j`` has
  weight ``w_j = f^(k-j)`` and the sample count is ``n_k = sum_j w_j = f n_(k-1) + 1``.
  Least squares is weighted by ``W = diag(w)``: ``D_k = (X'WX)^-1``. Eq. 15 then reads
  ``K_k = D_(k-1) x_k / (f + x_k' D_(k-1) x_k)``, ``D_k = (I - K_k x_k') D_(k-1) / f``.
  Eq. 17 becomes ``R_k(i) = (f n_(k-1)/n_k) R_(k-1)(i) + v_k v_(k-i) / n_k``, i.e.
  ``R_k(i) = sum_j w_j v_j v_(j-i) / n_k``. The covariance is the sandwich
  ``D X'W E[vv'] W X D`` of Eq. 8, so the lag products carry both weights:
  ``Lambda_k(i) = f^2 Lambda_(k-1)(i) + f^i (x_k x_(k-i)' + x_(k-i) x_k')`` (Eq. 21), and
  the conventional covariance is ``R_k(0) D_k Lambda_k(0) D_k``, which is Eq. 13 when
  ``f = 1``.
* **Noise model** (``noise_forgetting`` ``f_R``, ``f <= f_R <= 1``; default
  ``max(f, 1 - 1/(40 (n_tau + 1)))``, ``f`` when ``f = 1`` or all lags are kept). When
  ``f_R != f``, ``R_k(i)`` of Eqs. 17-22 is not that of the estimator's residuals: a second
  least-squares fit of the same model, weighted ``f_R^(k-j)`` (Eq. 15 with ``f_R``:
  ``d^N_k = f_R + x_k' D^N_(k-1) x_k``, ``e^N_k = z_k - x_k' theta^N_(k-1)``), gives the
  residuals ``u_k`` (of the chosen kind, with ``f_R``), and
  ``R_k(i) = sum_j f_R^(k-j) u_j u_(j-i) / n^N_k``, ``n^N_k = sum_j f_R^(k-j)``. ``D_k`` and
  ``Lambda_k(i)`` stay the estimator's. It initializes with the estimator, at ``k0``, from its
  own weighted normal equations ``A^N_k0 = X'W_R X``, ``b^N_k0 = X'W_R z`` (Eq. 6), its
  residuals of samples ``1..k0`` by Eq. 7 and their ``R_k0(i)`` by Eq. 10 weighted ``f_R``; with
  a prior, ``D^N_0 = D_0``, ``theta^N_0 = 0``.
* **Residual** of Eqs. 16-17, from the a priori innovation ``e_k = z_k - x_k' theta_(k-1)``
  and ``d_k = f + x_k' D_(k-1) x_k``: ``"a_priori"`` is ``e_k``; ``"a_posteriori"`` is
  ``z_k - x_k' theta_k`` (Eq. 7 at sample ``k``, equal to ``e_k f / d_k``);
  ``"standardized"`` (the default) is ``e_k sqrt(f / d_k)``, whose square is the product of
  the other two. With it Eq. 16 is exact: ``n_k R_k(0)`` is the weighted residual sum of
  squares of the batch fit of samples ``1..k`` (Brown, Durbin & Evans 1975), so ``R_k(0)``
  is Eq. 14 at every sample.
* **Exact initialization** (``p0=None``). A model accumulates the normal equations
  ``A_k = X'WX``, ``b_k = X'Wz`` until ``A_k`` is well conditioned after column scaling:
  ``k >= n``, a positive diagonal, and ``cond(S^-1 A_k S^-1) < init_condition`` with
  ``S = diag(sqrt(diag(A_k)))``. At that sample ``k0`` it takes the batch solution (Eq. 6),
  defines the residuals of samples ``1..k0`` with it (Eq. 7) and their autocorrelation with
  Eq. 10 (weighted as above), and continues with Eqs. 15-17. ``Lambda_k(i)`` does not depend
  on the estimate and is accumulated from sample 1. With a prior ``p0`` instead, ``D_0 =
  diag(p0)``, ``theta_0 = 0`` and Eqs. 15-17 run from sample 1.
* **Lag window** ``c_i`` (:func:`.lag_window.lag_weights`): Eq. 20 keeps all lags
  ``i < k``, Eq. 22 lags ``i <= n_tau``; ``bartlett`` weights them by ``1 - i/(n_tau+1)``
  (``n_tau = k - 1`` with all lags).
* **Automatic lags** (``lags="auto"``, truncated window only): ``R_k(i)`` is kept for
  ``i <= max_lags`` and, when a covariance is evaluated, ``n_tau = L`` is chosen by Politis'
  flat-top rule (:func:`flat_top_lag`): with ``rho(i) = R_k(i)/R_k(0)``, the threshold
  ``tau = 2 sqrt(log10 n / n)`` and ``K = max(5, ceil(sqrt(log10 n)))``, ``m`` is the smallest
  ``m >= 0`` with ``|rho(m+j)| < tau`` for ``j = 1..K`` and ``L = 2 m``, or ``max_lags`` when
  no such run fits in the lags held; ``L`` is limited to ``[min_lags, min(max_lags, lags
  held, n - 1)]`` and is ``min_lags`` before initialization, when ``R_k(0) <= 0``, and when
  the model fits exactly (``R_k(0)`` at most ``1e-12`` of the mean square of its output, as
  for the published covariance below): its residuals are then rounding, whose pattern
  depends on the machine's floating-point kernels, so ``R_k(i)`` counts as zero. ``n`` is
  ``k``, or under forgetting Kish's effective size ``(sum w)^2 / sum w^2`` of the weights
  ``w_j = f_R^(k-j)`` of ``R_k(i)``.
* **Residual burn-in** (``residual_burn_in`` ``B >= 0``; default ``50`` with
  ``lags="auto"``, else 0). Right after a model's initialization at ``k0`` (``k0 = 0`` with a
  prior) its estimate is still poor and its residuals are large and correlated; Eq. 17 keeps
  them in ``R_k(i)`` for ever. With ``B > 0`` they are left out: for ``k <= k0 + B``,
  ``R_k(i)`` is the paper's (above); from ``k = k0 + B + 1`` on it is Eq. 17 started afresh on
  the residuals after the burn-in,
  ``R_k(i) = sum_{j > k0+B, j-i > k0+B} w_j v_j v_(j-i) / n^B_k``,
  ``n^B_k = sum_{j > k0+B} w_j`` (``k - k0 - B`` when ``f = 1``), recursively
  ``n^B_k R_k(i) = f n^B_(k-1) R_(k-1)(i) + v_k v_(k-i)`` with the product left out while
  ``k - i <= k0 + B``. Both ``v_k`` and its partner ``v_(k-i)`` must lie after the burn-in; the
  initialization's own residuals (Eq. 7 of samples ``1..k0``) are left out too. Under
  forgetting ``w_j = f_R^(k-j)`` and ``v`` are the noise model's (which initializes with the
  estimator at ``k0``). ``D_k``, ``Lambda_k(i)`` and the lag window (``n_tau = k - 1`` with
  all lags) are unchanged; the conventional covariance uses the same ``R_k(0)``. The lag
  rule's ``n`` is the count ``k - k0 - B`` (Kish's size of those weights under forgetting).
  ``B = 0`` is the paper. At ``k = k0 + B + 1``, ``R_k`` rests on one sample: the covariance
  is as unsettled as right after initialization.
* **Published covariance.** A corrected covariance with a negative diagonal entry is
  replaced by the nearest positive semi-definite matrix (:func:`.covariance.nearest_psd`),
  unless the model fits exactly (``R_k(0) <= 1e-12`` times the mean square of the model
  output ``x_j' theta_k``, weighted as ``Lambda_k(0)``), when it is zero. Standard errors
  are the square roots of the published diagonal. (In a bank, the exact fits are looked for
  when any of its models has a negative corrected variance.)
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Literal

import numpy as np
import numpy.typing as npt

from ..errors import EstimatorNotReady
from .covariance import EXACT_FIT, nearest_psd
from .lag_window import lag_weights
from .options import EstimatorOptions, check_kind, check_window

__all__ = ["batch_reference", "RecursiveReference", "flat_top_lag"]


def flat_top_lag(R: Sequence[float], n: float, max_lags: int, min_lags: int = 0) -> int:
    """Politis' flat-top rule on ``R(0..W-1)`` (the module docstring), one model, literally."""
    W = len(R)
    hi = max(min(W - 1, max_lags, math.floor(n) - 1), 0)
    lo = min(min_lags, hi)
    if n < 2 or W < 2 or not R[0] > 0 or not all(math.isfinite(r) for r in R):
        return lo
    tau = 2.0 * math.sqrt(math.log10(n) / n)
    K = max(5, math.ceil(math.sqrt(math.log10(n))))
    for m in range(W - K):  # a run of K lags m+1..m+K inside the W lags held
        if all(abs(R[m + j]) < tau * R[0] for j in range(1, K + 1)):
            return max(min(2 * m, hi), lo)
    return hi


def batch_reference(
    X: np.ndarray,
    z: np.ndarray,
    lags: int | Literal["all"] = "all",
    window: str = "truncated",
    *,
    forgetting: float = 1.0,
    residuals: np.ndarray | None = None,
    noise_forgetting: float | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Eqs. 6-14 with the paper's matrices: ``(theta, cov_conventional, cov_corrected)``.

    ``residuals`` replaces Eq. 7 (for instance the residual history of a recursive
    estimator). Weighted by ``W = diag(f^(N-j))`` when ``forgetting < 1``. ``noise_forgetting``
    ``f_R`` (default ``forgetting``) weights Eq. 10 by ``W_R = diag(f_R^(N-j))``; without given
    ``residuals`` they are then those of the ``W_R``-weighted fit (the noise model).
    """
    X = np.asarray(X, dtype=float)
    z = np.asarray(z, dtype=float)
    check_window(window)
    N = len(z)
    f = forgetting
    g = f if noise_forgetting is None else float(noise_forgetting)
    W = np.diag([f ** (N - j) for j in range(1, N + 1)])
    W_R = np.diag([g ** (N - j) for j in range(1, N + 1)])
    D = np.linalg.inv(X.T @ W @ X)  # Eq. 6: dispersion matrix
    theta = D @ X.T @ W @ z  # Eq. 6
    theta_R = theta if g == f else np.linalg.solve(X.T @ W_R @ X, X.T @ W_R @ z)  # Eq. 6, W_R (noise model)
    v = z - X @ theta_R if residuals is None else np.asarray(residuals, dtype=float)  # Eq. 7
    n_N = np.trace(W_R)  # N when f = 1
    R = np.zeros(N)
    for i in range(N):
        R[i] = sum(W_R[i + j, i + j] * v[i + j] * v[j] for j in range(N - i)) / n_N  # Eq. 10
    n_tau = N - 1 if lags == "all" else int(lags)
    c = lag_weights(n_tau, window, N)
    E = np.array([[c[abs(a - b)] * R[abs(a - b)] for b in range(N)] for a in range(N)])  # Eq. 9 (22)
    cov_corrected = D @ X.T @ W @ E @ W @ X @ D  # Eq. 8
    sigma2 = R[0]  # Eq. 14
    if f == 1.0:
        cov_conventional = sigma2 * D  # Eq. 13
    else:
        cov_conventional = D @ X.T @ W @ (sigma2 * np.eye(N)) @ W @ X @ D  # Eq. 8 with Eq. 12
    return theta, cov_conventional, cov_corrected


def batch_iv(
    X: np.ndarray,
    Zeta: np.ndarray,
    z: np.ndarray,
    lags: int | Literal["all"] = "all",
    window: str = "truncated",
    *,
    residuals: np.ndarray | None = None,
    first: int = 0,
    small_sample: float = 0.0,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Batch instrumental variables with the paper's matrices: ``(theta, cov_conventional,
    cov_corrected)``, the oracle of the bank's algorithm ``"iv"``.

    ``theta = P Z'z`` with ``P = (Z'X)^-1`` (Eq. 6 with the instruments ``Z`` on the left), and
    Eq. 8 with ``D X'`` replaced by ``P Z'``: ``cov = P Z' E Z P'``, ``E`` the Toeplitz matrix of
    Eq. 9 (22) of the residual autocorrelation (Eq. 10); the conventional covariance is
    ``R(0) P Z'Z P'``. With ``Z = X`` these are Eqs. 6-14. ``residuals`` replaces ``z - X theta``
    (Eq. 7; for instance a recursive history), of which Eq. 10 uses those from index ``first``
    on (a residual burn-in), divided by their number ``n_R``; ``small_sample`` ``s`` multiplies
    the corrected covariance by ``n_R / (n_R - n - s L)``.
    """
    X, Zeta, z = (np.asarray(a, dtype=float) for a in (X, Zeta, z))
    check_window(window)
    N, n = X.shape
    P = np.linalg.inv(Zeta.T @ X)
    theta = P @ Zeta.T @ z
    v = z - X @ theta if residuals is None else np.asarray(residuals, dtype=float)  # Eq. 7
    n_R = N - first
    R = np.zeros(N)
    for i in range(n_R):
        R[i] = sum(v[first + i + j] * v[first + j] for j in range(n_R - i)) / n_R  # Eq. 10
    n_tau = N - 1 if lags == "all" else int(lags)
    c = lag_weights(n_tau, window, N)
    E = np.array([[c[abs(a - b)] * R[abs(a - b)] for b in range(N)] for a in range(N)])  # Eq. 9 (22)
    cov_corrected = P @ Zeta.T @ E @ Zeta @ P.T
    if small_sample:
        cov_corrected = cov_corrected * n_R / max(n_R - n - small_sample * min(n_tau, N - 1), 0.25 * n_R)
    cov_conventional = R[0] * P @ Zeta.T @ Zeta @ P.T
    return theta, cov_conventional, cov_corrected


class RecursiveReference:
    """Eqs. 15-22 for one model of ``n`` parameters, literally (see the module docstring for
    the options): ``RecursiveReference(n, options)`` with the :class:`.options.EstimatorOptions`
    of :class:`~.bank.EstimatorBank`."""

    def __init__(self, n: int, options: EstimatorOptions | None = None) -> None:
        o = EstimatorOptions() if options is None else options
        self.n, self.options = n, o
        self.lags, self.window = o.lags, o.window
        self.f, self.residual, self.init_condition = o.forgetting, o.residual, o.init_condition
        self.auto = o.auto
        self.max_lags, self.min_lags = o.max_lags, o.min_lags
        self.held = o.held  # n_tau of the memory: lags, max_lags with auto, None for all
        self.g = o.noise_forgetting_used  # f_R
        self.noise = self.g != self.f  # R(i) from the noise model
        self.B = o.burn_in  # the residual burn-in
        self.n_B = 0.0  # sum_(j > k0+B) f_R^(k-j) after the burn-in
        self.k = 0
        self.n_k = 0.0  # sum_j f^(k-j)
        self.n_R = 0.0  # sum_j f_R^(k-j) (equal to n_k without a noise model)
        self.u: list[float] = []  # the noise model's residuals u_1..u_k once initialized
        self.x: list[np.ndarray] = []  # x_1, x_2, ... (x[j-1] is x_j)
        self.z: list[float] = []
        self.v: list[float] = []  # residuals v_1..v_k once initialized
        self.R: dict[int, float] = {}  # R_k(i)
        self.Lam: dict[int, np.ndarray] = {}  # Lambda_k(i)
        self.A = np.zeros((n, n))  # X'WX before initialization
        self.b = np.zeros(n)  # X'Wz before initialization
        self.A_R = np.zeros((n, n))  # X'W_R X and X'W_R z of the noise model before initialization
        self.b_R = np.zeros(n)
        prior = o.prior(n)
        self.ready = prior is not None
        self.ready_at = 0
        self.D = np.zeros((n, n)) if prior is None else np.diag(prior)
        self.theta = np.zeros(n)
        self.D_R, self.theta_R = self.D.copy(), self.theta.copy()  # the noise model

    def largest_lag(self) -> int:
        """The largest lag held at sample ``k``: ``k - 1`` (Eq. 20) or ``min(k - 1, n_tau)``."""
        return self.k - 1 if self.held is None else min(self.k - 1, self.held)

    def update(self, x: npt.ArrayLike, z: float) -> None:
        x = np.asarray(x, dtype=float)
        z = float(z)
        f = self.f
        self.k += 1
        k = self.k
        self.x.append(x)
        self.z.append(z)
        n_prev, self.n_k = self.n_k, f * self.n_k + 1.0
        g = self.g
        n_R_prev, self.n_R = self.n_R, g * self.n_R + 1.0
        for i in range(self.largest_lag() + 1):  # Eq. 21 (weighted)
            if i == 0:
                self.Lam[0] = f**2 * self.Lam.get(0, 0.0) + np.outer(x, x)
            else:
                x_lag = self.x[k - i - 1]  # x_(k-i)
                self.Lam[i] = f**2 * self.Lam.get(i, 0.0) + f**i * (np.outer(x, x_lag) + np.outer(x_lag, x))
        if not self.ready:
            self.A = f * self.A + np.outer(x, x)
            self.b = f * self.b + x * z
            self.A_R = g * self.A_R + np.outer(x, x)
            self.b_R = g * self.b_R + x * z
            self._try_initialize()
            return
        D, theta = self.D, self.theta
        d = f + x @ D @ x
        K = D @ x / d  # Eq. 15a
        e = z - x @ theta  # the a priori innovation of Eq. 15c
        self.D = (np.eye(self.n) - np.outer(K, x)) @ D / f  # Eq. 15b
        self.theta = theta + K * e  # Eq. 15c
        # (e and the a posteriori residual are scalars: 1-D @ 1-D, typed as arrays by numpy's stubs)
        self.v.append(self._residual(e, d, z - x @ self.theta, f))  # type: ignore[arg-type]
        series = self.v
        if self.noise:  # the noise model: Eq. 15 with f_R
            D, theta = self.D_R, self.theta_R
            d = g + x @ D @ x
            K = D @ x / d
            e = z - x @ theta
            self.D_R = (np.eye(self.n) - np.outer(K, x)) @ D / g
            self.theta_R = theta + K * e
            self.u.append(self._residual(e, d, z - x @ self.theta_R, g))  # type: ignore[arg-type]  # as self.v
            series = self.u
        else:
            n_R_prev = n_prev
        w = series[-1]
        end = self.ready_at + self.B  # the last sample of the burn-in (B > 0)
        if self.B > 0 and k > end:
            # Eq. 17 on the residuals after the burn-in: afresh at k0 + B + 1, partners v_(k-i)
            # of the burn-in left out, n^B_k = f_R n^B_(k-1) + 1
            if k == end + 1:
                self.R, self.n_B = {}, 0.0
            n_B_prev, self.n_B = self.n_B, g * self.n_B + 1.0
            for i in range(self.largest_lag() + 1):
                partner = series[k - i - 1] if k - i > end else 0.0
                self.R[i] = (g * n_B_prev / self.n_B) * self.R.get(i, 0.0) + w * partner / self.n_B
            return
        for i in range(self.largest_lag() + 1):
            # Eq. 17 (Eq. 16 at i = 0), weighted: n_k R_k(i) = f n_(k-1) R_(k-1)(i) + v_k v_(k-i)
            # (f_R and u with a noise model)
            self.R[i] = (g * n_R_prev / self.n_R) * self.R.get(i, 0.0) + w * series[k - i - 1] / self.n_R

    def _residual(self, e: float, d: float, post: float, f: float) -> float:
        """The residual of the chosen kind from ``e_k``, ``d_k`` and the a posteriori residual."""
        if self.residual == "a_priori":
            return e
        if self.residual == "a_posteriori":
            return post  # Eq. 7 at sample k
        standardized: float = e * np.sqrt(f / d)
        return standardized

    def _try_initialize(self) -> None:
        """Exact initialization at this sample if ``A_k`` is well conditioned (Eqs. 6, 7, 10)."""
        A = self.A
        s = np.sqrt(np.diag(A))
        if self.k < self.n or not np.all(s > 0):
            return
        if not np.linalg.cond(A / np.outer(s, s)) < self.init_condition:
            return
        self.D = np.linalg.inv(A)  # Eq. 6
        self.theta = self.D @ self.b  # Eq. 6
        k, g = self.k, self.g
        # (1-D @ 1-D is a scalar; numpy's stubs type it as an array)
        self.v = [self.z[j] - self.x[j] @ self.theta for j in range(k)]  # type: ignore[misc]  # Eq. 7, samples 1..k
        series = self.v
        if self.noise:  # the noise model's batch solution (Eq. 6 weighted W_R) and residuals
            self.D_R = np.linalg.inv(self.A_R)
            self.theta_R = self.D_R @ self.b_R
            self.u = [self.z[j] - self.x[j] @ self.theta_R for j in range(k)]  # type: ignore[misc]  # as self.v
            series = self.u
        for i in range(self.largest_lag() + 1):
            # Eq. 10, weighted: R_k(i) = sum_j w_j v_j v_(j-i) / n_k (f_R and u with a noise model)
            self.R[i] = sum(g ** (k - 1 - j) * series[j] * series[j - i] for j in range(i, k)) / self.n_R
        self.ready, self.ready_at = True, k

    # ------------------------------------------------------------------ results
    def _require(self) -> None:
        if not self.ready:
            raise EstimatorNotReady(f"not initialized after {self.k} samples")

    def lags_used(self) -> int:
        """``n_tau`` of Eq. 22 at this sample: chosen with ``lags="auto"``, else the lags held."""
        if not self.auto:
            return self.largest_lag()
        g, k = self.g, self.k
        if self.B > 0 and self.ready and k > self.ready_at + self.B:
            k -= self.ready_at + self.B  # the samples after the burn-in
        n = k if g == 1.0 else (sum(g**i for i in range(k)) ** 2 / sum(g ** (2 * i) for i in range(k)))
        usable = self.ready and not self.exact_fit()  # not ready, or rounding for residuals: as R(0) = 0
        R = [self.R[i] if usable else 0.0 for i in range(self.largest_lag() + 1)]
        return flat_top_lag(R, n, self.max_lags, self.min_lags)

    def exact_fit(self) -> bool:
        """The model fits exactly: ``R_k(0)`` is at most ``EXACT_FIT`` (1e-12) of the mean
        square of the model output ``x_j' theta_k``, weighted as ``Lambda_k(0)``."""
        output_square = self.theta @ self.Lam[0] @ self.theta  # sum_j f^(2(k-j)) (x_j' theta)^2
        n_square = sum(self.f ** (2 * (self.k - j)) for j in range(1, self.k + 1))
        exact: bool = self.R[0] <= EXACT_FIT * output_square / n_square
        return exact

    def weights(self) -> np.ndarray:
        """Lag window ``c_i`` for the lags held (Eqs. 20, 22)."""
        held = self.largest_lag() + 1
        if self.auto:
            return lag_weights(self.lags_used(), "truncated", held)
        return lag_weights(self.k - 1 if self.held is None else self.held, self.window, held)

    def covariance(self, kind: str = "corrected") -> np.ndarray:
        """Eq. 20 / 22 (``corrected``) or Eq. 13 with Eq. 16 (``conventional``), unrepaired."""
        check_kind(kind)
        self._require()
        D, R, Lam = self.D, self.R, self.Lam
        if kind == "conventional":
            if self.f == 1.0:
                return R[0] * D  # Eq. 13 with sigma^2 = R_k(0) (Eq. 16)
            conventional: npt.NDArray[np.float64] = R[0] * D @ Lam[0] @ D
            return conventional
        c = self.weights()
        middle = sum(c[i] * R[i] * Lam[i] for i in range(len(c)))  # Eq. 20 / 22
        corrected: npt.NDArray[np.float64] = D @ middle @ D  # Eq. 20 / 22
        return corrected

    def published_covariance(self, kind: str = "corrected") -> np.ndarray:
        """The covariance the estimator publishes: repaired where a diagonal is negative."""
        cov = self.covariance(kind)
        if kind == "corrected" and np.any(np.diag(cov) < 0.0):
            if self.exact_fit():
                return np.zeros_like(cov)  # an exact fit: rounding, not indefiniteness
            return nearest_psd(cov)
        return cov

    def standard_errors(self, kind: str = "corrected") -> np.ndarray:
        return np.sqrt(np.maximum(np.diag(self.published_covariance(kind)), 0.0))
