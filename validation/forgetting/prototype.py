"""Prototype of the forgetting fix (issue 12 item 7), outside the package.

The corrected covariance under forgetting ``f < 1`` keeps the estimator's ``D_k`` and
``Lambda_k(i)`` (both exact for the weighted fit) and replaces the residual autocorrelation
``R_k(i)`` by an estimate of the *noise* autocovariance that

1. is computed from the standardized residuals of a companion RLS of the same model with a
   slower forgetting factor ``f_R`` (the *noise model*), so that the residuals are not
   high-passed by the fast fit (the fast residual has a notch of width ``1 - f`` at every
   regressor frequency, which the lag sum of Eq. 22 sees as a missing long-run variance), and
2. is averaged with the weight ``f_R^(k-j)`` (its own memory of ``1/(1 - f_R)`` samples)
   instead of ``f^(k-j)``, so that ``n_lags`` lags are estimated from many more samples than
   lags (with ``f = 0.98`` and 50 lags, the fast memory holds about 100 effective samples for
   101 two-sided lags: the estimate is unbiased at best but has a relative spread near 100 %).

``R^N_k(i) = S^N_k(i) / n^N_k``, ``S^N_k(i) = f_R S^N_(k-1)(i) + u_k u_(k-i)``,
``n^N_k = f_R n^N_(k-1) + 1``, where ``u_k = (z_k - x_k' theta^N_(k-1)) sqrt(f_R / d^N_k)``,
``d^N_k = f_R + x_k' D^N_(k-1) x_k``, and ``(theta^N, D^N)`` is RLS with forgetting ``f_R``
(Eq. 15 with ``f_R``). The corrected covariance is
``cov_k = D_k [sum_{i=0}^{L} c_i R^N_k(i) Lambda_k(i)] D_k`` and the conventional one
``R^N_k(0) D_k Lambda_k(0) D_k``. With ``f_R = f`` the noise model *is* the estimator and
``R^N = R`` (the current formulas); with ``f = 1`` the default ``f_R`` is 1, so the paper is
unchanged (the prototype then uses the bank's own ``R`` and gives bit-identical numbers).

Default noise memory: ``f_R = max(f, 1 - 1/(NOISE_MEMORY_LAGS * (n_lags + 1)))``, i.e. the
noise autocovariance is averaged over at least ``NOISE_MEMORY_LAGS`` times as many samples as
lags (see REPORT.md for the choice).

Option (``NoiseModel(level_forgetting=f)``, ``autocovariance(level=True)``): the level-adaptive
variant ``R^N_k(i) * q_k / R^N_k(0)`` with ``q_k = sum f^(k-j) u_j^2 / sum f^(k-j)``, the shape of
the autocovariance from the noise memory and its level from the estimator's memory. It follows
a change of the noise level within about ``1/(1-f)`` samples instead of ``1/(1-f_R)``, at the
price of a larger spread of the standard errors (see REPORT.md, transients).

This module reads the bank's private arrays (``_aug``, ``_Q``, ``_inv_s``, ``_S``) read-only;
the proposed patch (proposed_fix.md) moves the computation into ``EstimatorBank`` itself.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from rls_uncertainty.estimator import EstimatorBank, lag_weights

__all__ = [
    "NOISE_MEMORY_LAGS",
    "HonestForgettingBank",
    "LagSums",
    "NoiseModel",
    "covariance_from_bank",
    "default_noise_forgetting",
]

NOISE_MEMORY_LAGS = 40.0


def default_noise_forgetting(forgetting: float, n_lags: int | None) -> float:
    """``f_R = max(f, 1 - 1/(40 (n_lags + 1)))``; ``f`` itself when ``f = 1`` or all lags."""
    f = float(forgetting)
    if f == 1.0 or n_lags is None:
        return f
    return max(f, 1.0 - 1.0 / (NOISE_MEMORY_LAGS * (int(n_lags) + 1)))


class LagSums:
    """Exponentially weighted lag sums of a scalar stream per model:
    ``S_k(i) = g S_(k-1)(i) + u_k u_(k-i)``, ``n_k = g n_(k-1) + 1`` (``i = 0..n_lags``).

    ``push(u, active)`` adds one sample for the models in ``active`` (others untouched)."""

    def __init__(self, n_models: int, n_lags: int, weight: float) -> None:
        self.g = float(weight)
        self.L = int(n_lags)
        self.S = np.zeros((n_models, self.L + 1))
        self.n = np.zeros(n_models)
        self.count = np.zeros(n_models, dtype=np.int64)
        self.hist = np.zeros((n_models, self.L + 1))  # newest first

    def push(self, u: np.ndarray, active: np.ndarray | None = None) -> None:
        if active is None:
            active = np.ones(u.shape[0], dtype=bool)
        a = active
        h = self.hist[a]
        h[:, 1:] = h[:, :-1].copy()
        h[:, 0] = u[a]
        # lags beyond the samples seen contribute zero (history initialised with zeros)
        self.S[a] = self.g * self.S[a] + h * h[:, :1]
        self.n[a] = self.g * self.n[a] + 1.0
        self.count[a] += 1
        self.hist[a] = h

    def autocovariance(self) -> np.ndarray:
        with np.errstate(invalid="ignore", divide="ignore"):
            return self.S / self.n[:, None]


class NoiseModel:
    """Companion RLS (forgetting ``f_R``) of every model of a bank: standardized residuals
    ``u_k = e_k sqrt(f_R / d_k)`` and their lag sums with weight ``f_R``.

    Exact initialization as in :class:`EstimatorBank`: accumulate the ``f_R``-weighted normal
    equations until the column-scaled ``X'X`` has condition number below ``init_condition``,
    take the batch solution, then continue recursively. The lag sums start with the first
    sample after initialization (the prototype does not reconstruct the residuals of the
    initialization samples; far from initialization this makes no difference).
    """

    def __init__(
        self,
        sizes: Sequence[int],
        n_lags: int,
        forgetting: float,
        init_condition: float = 1e8,
        level_forgetting: float | None = None,
    ) -> None:
        self.sizes = tuple(int(s) for s in sizes)
        self.M = m = len(self.sizes)
        self.n = n = max(self.sizes)
        self.f = float(forgetting)
        self.mask = np.zeros((m, n), dtype=bool)
        for j, s in enumerate(self.sizes):
            self.mask[j, :s] = True
        self.init_condition = float(init_condition)
        self.A = np.zeros((m, n, n))  # f_R-weighted X'X until initialization
        self.b = np.zeros((m, n))
        self.D = np.zeros((m, n, n))  # scaled dispersion S D S
        self.theta = np.zeros((m, n))  # scaled estimate S^-1 theta
        self.inv_s = np.ones((m, n))
        self.ready = np.zeros(m, dtype=bool)
        self.sums = LagSums(m, n_lags, self.f)
        # optional: the mean square of the same residuals with the estimator's memory, for the
        # level-adaptive variant R^N(i) * msq_f(u) / R^N(0) (see autocovariance)
        self.level = None if level_forgetting is None else LagSums(m, 0, level_forgetting)

    def update(self, X: np.ndarray, z: np.ndarray) -> None:
        X = np.where(self.mask, X, 0.0)
        f = self.f
        r = self.ready
        if r.any():
            xs = X[r] * self.inv_s[r]
            D = self.D[r]
            Dx = np.einsum("mab,mb->ma", D, xs)
            d = f + np.einsum("ma,ma->m", xs, Dx)
            e = z[r] - np.einsum("ma,ma->m", xs, self.theta[r])
            u = np.zeros(self.M)
            u[r] = e * np.sqrt(f / d)
            self.theta[r] += Dx * (e / d)[:, None]
            self.D[r] = (D - Dx[:, :, None] * Dx[:, None, :] / d[:, None, None]) / f
            self.sums.push(u, r)
            if self.level is not None:
                self.level.push(u, r)
        w = ~r
        if w.any():
            self.A[w] = f * self.A[w] + X[w, :, None] * X[w, None, :]
            self.b[w] = f * self.b[w] + X[w] * z[w, None]
            for j in np.flatnonzero(w):
                self._try_init(j)

    def _try_init(self, j: int) -> None:
        s_n = self.sizes[j]
        A = self.A[j, :s_n, :s_n]
        s = np.sqrt(np.diag(A))
        if not np.all(s > 0):
            return
        C = A / np.outer(s, s)
        if not np.linalg.cond(C) < self.init_condition:
            return
        Cinv = np.linalg.inv(C)
        self.D[j, :s_n, :s_n] = 0.5 * (Cinv + Cinv.T)
        self.theta[j, :s_n] = self.D[j, :s_n, :s_n] @ (self.b[j, :s_n] / s)
        self.inv_s[j, :s_n] = 1.0 / s
        self.ready[j] = True

    def autocovariance(self, level: bool = False) -> np.ndarray:
        """``R^N_k(i)``, ``(M, n_lags + 1)``; NaN before initialization.

        ``level=True`` (needs ``level_forgetting``): the shape from the noise memory, the level
        from the short one, ``R^N_k(i) * [sum g^(k-j) u_j^2 / sum g^(k-j)] / R^N_k(0)``."""
        R = self.sums.autocovariance()
        if level:
            with np.errstate(invalid="ignore", divide="ignore"):
                R = R * (self.level.autocovariance()[:, :1] / R[:, :1])
        R[~self.ready] = np.nan
        return R


def covariance_from_bank(bank: EstimatorBank, R: np.ndarray, kind: str = "corrected") -> np.ndarray:
    """``D_k [sum_i c_i R(i) Lambda_k(i)] D_k`` (``kind="corrected"``) or
    ``R(0) D_k Lambda_k(0) D_k`` (``"conventional"``) with the bank's ``D_k`` and
    ``Lambda_k(i)`` and a given autocovariance ``R`` of shape ``(M, >= n_window)``.

    Returns ``(M, n_max, n_max)`` in the units of the parameters. With ``R`` equal to the
    bank's own ``S / n_eff`` this reproduces the bank's unrepaired covariances.
    """
    n = bank.n_max
    D = bank._aug[:, :n]
    w = bank.n_window
    U = bank._Q[:, :n, :w, :n]  # U[m, b, i, a] = sum_j f^(2(k-j)) f^i x_(j-i)[a] x_j[b]
    if kind == "corrected":
        largest = bank.k - 1 if bank.n_lags is None else bank.n_lags
        c = lag_weights(largest, bank.window, w)
        c[0] *= 0.5
        cR = np.asarray(R)[:, :w] * c
    else:
        cR = np.zeros((bank.n_models, w))
        cR[:, 0] = 0.5 * np.asarray(R)[:, 0]
    N = np.einsum("mi,mbia->mba", cR, U)
    cov = D @ (N + N.swapaxes(1, 2)) @ D
    inv_s = bank._inv_s
    return cov * inv_s[:, :, None] * inv_s[:, None, :]


class HonestForgettingBank:
    """An :class:`EstimatorBank` whose covariances use the noise model's autocovariance.

    ``noise_forgetting=None`` takes :func:`default_noise_forgetting`; ``noise_forgetting=f``
    (or ``f = 1``) gives the bank's own numbers.
    """

    def __init__(
        self,
        sizes: Sequence[int],
        n_lags: int,
        window: str = "truncated",
        forgetting: float = 1.0,
        *,
        noise_forgetting: float | None = None,
        **options,
    ) -> None:
        self.bank = EstimatorBank(sizes, n_lags, window, forgetting, **options)
        f_R = default_noise_forgetting(forgetting, n_lags) if noise_forgetting is None else float(noise_forgetting)
        if not (forgetting <= f_R <= 1.0):
            raise ValueError(f"noise_forgetting must be in [forgetting, 1], got {f_R!r}")
        self.noise_forgetting = f_R
        self.noise = None if f_R == forgetting else NoiseModel(sizes, n_lags, f_R)

    def update(self, X: np.ndarray, z: np.ndarray) -> None:
        self.bank.update(X, z)
        if self.noise is not None:
            self.noise.update(np.asarray(X, dtype=float), np.asarray(z, dtype=float))

    def theta_all(self) -> np.ndarray:
        return self.bank.theta_all()

    def autocovariance(self) -> np.ndarray:
        if self.noise is None:
            b = self.bank
            out = np.full((b.n_models, b._cap), np.nan)
            out[:, : b.n_window] = b._S[:, : b.n_window] / b.n_eff
            return out
        return self.noise.autocovariance()

    def standard_errors_all(self, kind: str = "corrected") -> np.ndarray:
        if self.noise is None:
            return self.bank.standard_errors_all(kind)
        cov = covariance_from_bank(self.bank, self.autocovariance(), kind)
        var = np.diagonal(cov, axis1=1, axis2=2).copy()
        var = np.where(self.bank._invalid(), np.nan, var)
        return np.sqrt(np.maximum(var, 0.0))
