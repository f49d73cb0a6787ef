"""Parameter covariances of every model of a bank, from one computation (Eqs. 13, 16, 20, 22).

**The two-sided lag sum, in one place.** The bank stores the one-sided lag products
``Lambda+_k(i) = sum_j x_j x_(j-i)'`` (newer sample on the left, weighted as Eq. 21), so that
``Lambda_k(i) = Lambda+_k(i) + Lambda+_k(i)'`` for ``i > 0`` (Eq. 19) and
``Lambda_k(0) = Lambda+_k(0) = (Lambda+_k(0) + Lambda+_k(0)') / 2``. Hence every covariance
of Eqs. 20 and 22 is

    cov = D [sum_i c_i R_k(i) Lambda_k(i)] D = P + P',    P = D N D,
    N = sum_i h_i R_k(i) Lambda+_k(i),    h_0 = c_0 / 2, h_i = c_i   (half_window).

The conventional covariance is Eq. 22 with ``n_tau = 0``: ``N = R_k(0) Lambda_k(0) / 2``;
with ``f = 1``, ``D Lambda_k(0) D = D`` and Eq. 13 reads ``P = R_k(0) D / 2``. Nothing else
in the package deals with the factor 2 of the two-sided sum.

:class:`CovarianceEvaluator` computes the full matrices of both kinds for all models in one
vectorised pass; the published standard errors are the square roots of their diagonals, so
``standard_errors_all``, ``standard_errors(j)`` and ``covariance(j)`` of the bank are the
same numbers. A corrected covariance with a negative diagonal entry is replaced by
:func:`nearest_psd` (a repair), or by zero when the model fits exactly (:data:`EXACT_FIT`).
"""

from __future__ import annotations

import numpy as np

__all__ = ["EXACT_FIT", "nearest_psd", "half_window", "CovarianceEvaluator", "Covariances"]

# An exact fit: R_k(0) at most this fraction of the mean square of the model output
# x_j' theta_k (weighted as Lambda_k(0)). Its corrected variances are rounding of either
# sign and are published as zero, not repaired.
EXACT_FIT = 1e-12


def nearest_psd(cov: np.ndarray) -> np.ndarray:
    """Nearest (Frobenius) symmetric positive semi-definite matrix: eigenvalues clipped at 0."""
    sym = 0.5 * (cov + cov.T)
    vals, vecs = np.linalg.eigh(sym)
    return (vecs * np.clip(vals, 0.0, None)) @ vecs.T


def half_window(c: np.ndarray) -> np.ndarray:
    """``h`` with ``h_0 = c_0 / 2`` and ``h_i = c_i``: the weights of the one-sided products in
    ``N`` (module docstring)."""
    h = np.array(c, dtype=float)
    h[0] *= 0.5
    return h


class Covariances:
    """Both covariances of every model at one sample, as ``P`` (module docstring).

    ``matrices()`` are the corrected (``[0]``, Eq. 20/22) and conventional (``[1]``, Eq. 13)
    covariances ``(P + P') * scale``, ``(2, M, n_max, n_max)`` in the regressors' units,
    unrepaired, NaN outside the ready models' blocks; they are formed on first use.
    ``standard_errors`` ``(2, M, n_max)`` are the published ones: the square roots of those
    diagonals, computed as ``2 diag(P) * diag(scale)``, which is the same floating-point
    number (doubling is exact). The published corrected covariance differs where a diagonal
    entry is negative: ``repaired`` maps such a model to its nearest positive semi-definite
    matrix. When any is negative, ``exact`` marks the models that fit exactly: theirs are
    rounding of either sign and are published as zero.
    """

    __slots__ = ("P", "scale", "standard_errors", "repaired", "exact", "_matrices")

    def __init__(self, P: np.ndarray, scale: np.ndarray, diagonal_scale: np.ndarray) -> None:
        self.P, self.scale = P, scale
        self.repaired: dict[int, np.ndarray] = {}
        self.exact = None
        self._matrices = None
        se = P.diagonal(0, 2, 3) * diagonal_scale  # diag(P + P') * scale = diag(P) * 2 diag(scale)
        np.maximum(se, 0.0, out=se)
        self.standard_errors = np.sqrt(se, out=se)

    def matrices(self) -> np.ndarray:
        if self._matrices is None:
            self._matrices = (self.P + self.P.swapaxes(2, 3)) * self.scale  # cov = P + P'
        return self._matrices

    def matrix(self, kind_index: int, j: int, size: int, *, repair: bool = True) -> np.ndarray:
        """Model ``j``'s covariance (a copy), published (``repair``) or unrepaired."""
        if repair and kind_index == 0:
            if j in self.repaired:
                return self.repaired[j].copy()
            if self.exact is not None and self.exact[j]:
                return np.zeros((size, size))
        return self.matrices()[kind_index, j, :size, :size].copy()


class CovarianceEvaluator:
    """Evaluates :class:`Covariances` for a bank whose conventional covariance is Eq. 13
    (``eq13``, ``f = 1``) or ``R_k(0) D Lambda_k(0) D`` (``f < 1``)."""

    def __init__(self, m: int, n: int, eq13: bool) -> None:
        self.eq13 = eq13
        # P of the latest evaluation; the bank asks for one evaluation per sample and drops it
        # at the next update, so the workspace is reused (what callers get is always fresh).
        self._P = np.empty((2, m, n, n))

    def __call__(
        self,
        D: np.ndarray,
        lag_sums: np.ndarray,
        h_over_n: np.ndarray,
        lag_products: np.ndarray,
        scale: np.ndarray,
        diagonal_scale: np.ndarray,
        exact_fit,
        sizes: tuple,
    ) -> tuple[Covariances, list]:
        """Both covariances of every model, and the models whose corrected one was repaired.

        ``D`` ``(M, n, n)`` and ``lag_products`` ``(M, n, w, n)`` (``Lambda+_k(i)``) are in
        column-scaled units; ``lag_sums`` ``(M, w)`` is ``n_k R_k(i)`` and ``h_over_n`` the
        half window divided by ``n_k``, for the ``w`` lags held; ``scale`` ``(M, n, n)``
        takes scaled units back to the regressors' (NaN outside the ready models' blocks) and
        ``diagonal_scale`` is ``2 diag(scale)`` ``(M, n)``; ``exact_fit()`` returns the models that fit exactly.
        """
        P = self._P
        hR = lag_sums * h_over_n  # h_i R_k(i)
        N = np.matmul(hR[:, None, None, :], lag_products)[:, :, 0, :]  # sum_i h_i R(i) Lambda+(i)
        np.matmul(np.matmul(D, N), D, out=P[0])  # Eq. 20 / 22: corrected
        if self.eq13:
            np.multiply(D, hR[:, :1, None], out=P[1])  # Eq. 13 with sigma^2 = R_k(0) (Eq. 16)
        else:
            N0 = np.matmul(hR[:, None, None, :1], lag_products[:, :, :1])[:, :, 0, :]
            np.matmul(np.matmul(D, N0), D, out=P[1])  # Eq. 22 with n_tau = 0
        cov = Covariances(P, scale, diagonal_scale)
        counted: list[int] = []
        corrected_diag = P[0].diagonal(0, 1, 2)  # models not ready are 0 here, not NaN
        if np.minimum.reduce(corrected_diag, axis=None) < 0.0:
            exact = exact_fit()
            if exact.any():  # rounding of exact fits, not indefiniteness: zero
                cov.exact = exact
                cov.standard_errors[0][exact] *= 0.0  # (NaN padding stays NaN)
                corrected_diag = np.where(exact[:, None], 0.0, corrected_diag)
            if np.minimum.reduce(corrected_diag, axis=None) < 0.0:
                for j in np.flatnonzero((corrected_diag < 0.0).any(axis=1)):
                    j = int(j)
                    s = sizes[j]
                    fixed = cov.repaired[j] = nearest_psd(cov.matrices()[0, j, :s, :s])
                    counted.append(j)
                    cov.standard_errors[0, j, :s] = np.sqrt(np.maximum(np.diag(fixed), 0.0))
        return cov, counted
