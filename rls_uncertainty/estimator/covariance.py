"""Parameter covariances of every model of a bank, from one computation (Eqs. 13, 16, 20, 22).

The two-sided lag sum, in one place. The bank stores the one-sided lag products
``Lambda+_k(i) = sum_j x_j x_(j-i)'`` (newer sample on the left, weighted as in Eq. 21), so
that ``Lambda_k(i) = Lambda+_k(i) + Lambda+_k(i)'`` for ``i > 0`` (Eq. 19) and
``Lambda_k(0) = Lambda+_k(0)``. The bracket of Eqs. 20 and 22 is therefore

    sum_i c_i R_k(i) Lambda_k(i) = N + N',   N = sum_i h_i R_k(i) Lambda+_k(i),

with the half window ``h_0 = c_0 / 2``, ``h_i = c_i`` (:func:`half_window`, :func:`bracket`).
Nothing else in the package deals with the factor 2 of the two-sided sum.

:func:`evaluate` gives the full covariance matrices of both kinds for all models, in the
units of the regressors; the published standard errors are the square roots of their
diagonals, so ``standard_errors_all``, ``standard_errors(j)`` and ``covariance(j)`` of the
bank are the same numbers. A corrected covariance with a negative diagonal is replaced by
:func:`nearest_psd` (counted as a repair), or by zero when the model fits exactly.
"""

from __future__ import annotations

import numpy as np

__all__ = ["EXACT_FIT", "nearest_psd", "half_window", "bracket", "Covariances", "evaluate"]

# An exact fit: R_k(0) at most this fraction of the weighted mean square of z. Its corrected
# variances are rounding of either sign and are published as zero, not repaired.
EXACT_FIT = 1e-12


def nearest_psd(cov: np.ndarray) -> np.ndarray:
    """Nearest (Frobenius) symmetric positive semi-definite matrix: eigenvalues clipped at 0."""
    sym = 0.5 * (cov + cov.T)
    vals, vecs = np.linalg.eigh(sym)
    return (vecs * np.clip(vals, 0.0, None)) @ vecs.T


def half_window(c: np.ndarray) -> np.ndarray:
    """``h`` with ``h_0 = c_0 / 2`` and ``h_i = c_i``: the weights of the one-sided products
    whose sum ``N`` gives the bracket of Eqs. 20/22 as ``N + N'``."""
    h = np.array(c, dtype=float)
    h[0] *= 0.5
    return h


def bracket(hR: np.ndarray, lag_products: np.ndarray) -> np.ndarray:
    """``sum_i c_i R_k(i) Lambda_k(i)`` (Eqs. 20, 22) for every model, ``(M, n, n)``.

    ``hR[m, i] = h_i R_k(i)`` (:func:`half_window`); ``lag_products[m, a, i, b] =
    Lambda+_k(i)[a, b]`` for the same lags.
    """
    N = np.matmul(hR[:, None, None, :], lag_products)[:, :, 0, :]  # sum_i h_i R(i) Lambda+(i)
    return N + N.swapaxes(1, 2)  # Eq. 19: Lambda(i) = Lambda+(i) + Lambda+(i)'


class Covariances:
    """Both covariances of every model at one sample.

    ``matrices[0]`` is the corrected (Eq. 20/22), ``matrices[1]`` the conventional (Eq. 13)
    covariance, ``(2, M, n_max, n_max)``, unrepaired, NaN outside the ready models' blocks.
    ``standard_errors`` ``(2, M, n_max)`` are the published ones; ``repaired`` maps a model to
    its published corrected covariance where that differs from the unrepaired one.
    """

    __slots__ = ("matrices", "standard_errors", "repaired")

    def __init__(self, matrices: np.ndarray, standard_errors: np.ndarray, repaired: dict) -> None:
        self.matrices = matrices
        self.standard_errors = standard_errors
        self.repaired = repaired

    def published(self, kind_index: int, j: int, size: int) -> np.ndarray:
        if kind_index == 0 and j in self.repaired:
            return self.repaired[j].copy()
        return self.matrices[kind_index, j, :size, :size].copy()


def evaluate(
    D: np.ndarray,
    R: np.ndarray,
    h: np.ndarray,
    lag_products: np.ndarray,
    eq13: bool,
    scale: np.ndarray,
    exact_fit,
    sizes: tuple,
) -> tuple[Covariances, list]:
    """Both covariances of every model, and the models whose corrected one was repaired.

    ``D`` ``(M, n, n)`` and ``lag_products`` ``(M, n, w, n)`` are in the bank's column-scaled
    units; ``R`` ``(M, w)`` is ``R_k(i)`` (Eq. 17) for the ``w`` lags held and ``h`` their
    half window; ``eq13`` selects ``R_k(0) D`` (Eq. 13, ``f = 1``) for the conventional
    covariance instead of ``R_k(0) D Lambda_k(0) D``; ``scale`` ``(M, n, n)`` takes scaled
    units back to the regressors' (NaN outside the ready models' blocks); ``exact_fit()``
    returns the models that fit exactly.
    """
    cov = np.empty((2,) + D.shape)
    middle = bracket(R * h, lag_products)
    np.matmul(np.matmul(D, middle), D, out=cov[0])  # Eq. 20 / 22
    if eq13:
        np.multiply(D, R[:, 0, None, None], out=cov[1])  # Eq. 13 with sigma^2 = R_k(0) (Eq. 16)
    else:
        # Eq. 22 with n_tau = 0: R_k(0) D Lambda_k(0) D
        np.matmul(np.matmul(D, bracket(R[:, :1] * 0.5, lag_products[:, :, :1])), D, out=cov[1])
    corrected_diag = np.diagonal(cov[0], axis1=1, axis2=2)
    negative = None  # before scaling, where models that are not ready are 0, not NaN
    if corrected_diag.min() < 0.0:
        negative = np.flatnonzero((corrected_diag < 0.0).any(axis=1))
    cov *= scale
    se = np.maximum(np.diagonal(cov, axis1=2, axis2=3), 0.0)
    np.sqrt(se, out=se)
    repaired: dict[int, np.ndarray] = {}
    counted: list[int] = []
    if negative is not None:
        exact = exact_fit()
        for j in negative:
            j = int(j)
            s = sizes[j]
            if exact[j]:
                fixed = np.zeros((s, s))  # rounding of an exact fit, not indefiniteness
            else:
                fixed = nearest_psd(cov[0, j, :s, :s])
                counted.append(j)
            repaired[j] = fixed
            se[0, j, :s] = np.sqrt(np.maximum(np.diag(fixed), 0.0))
    return Covariances(cov, se, repaired), counted
