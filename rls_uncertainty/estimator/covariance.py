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

:class:`CovarianceEvaluator` computes both kinds for all models in one vectorised pass
from ``D N``: the variances ``diag(P + P') = 2 diag(P)`` every sample, the full matrices when
asked, with the same diagonals; the published standard errors are their square roots, so
``standard_errors_all``, ``standard_errors(j)`` and ``covariance(j)`` of the bank are the
same numbers. The ``1/n_k`` of ``R_k(i)`` and the column scaling are applied last (the
order the variances were always summed in). A corrected covariance with a negative diagonal
entry is replaced by :func:`nearest_psd` (a repair), or by zero when the model fits exactly
(:data:`EXACT_FIT`).
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from .numpy_compat import vecdot

__all__ = ["EXACT_FIT", "nearest_psd", "half_window", "CovarianceEvaluator", "Covariances"]

# An exact fit: R_k(0) at most this fraction of the mean square of the model output
# x_j' theta_k (weighted as Lambda_k(0)). Its corrected variances are rounding of either
# sign and are published as zero, not repaired.
EXACT_FIT = 1e-12

FloatArray = npt.NDArray[np.float64]
BoolArray = npt.NDArray[np.bool_]
# What Covariances.matrices() is formed from: D N, D N0 (None for Eq. 13), D, h_0 S_0, scale, 1/n_k,
# D' (D itself when symmetric) and the variances as computed (before any repair).
_Parts = tuple[FloatArray, FloatArray | None, FloatArray, FloatArray, FloatArray, float, FloatArray, FloatArray]


def nearest_psd(cov: FloatArray) -> FloatArray:
    """Nearest (Frobenius) symmetric positive semi-definite matrix: eigenvalues clipped at 0."""
    sym = 0.5 * (cov + cov.T)
    vals, vecs = np.linalg.eigh(sym)
    psd: FloatArray = (vecs * np.clip(vals, 0.0, None)) @ vecs.T
    return psd


def half_window(c: npt.ArrayLike) -> FloatArray:
    """``h`` with ``h_0 = c_0 / 2`` and ``h_i = c_i``: the weights of the one-sided products in
    ``N`` (module docstring)."""
    h = np.array(c, dtype=float)
    h[0] *= 0.5
    return h


class Covariances:
    """Both covariances of every model at one sample.

    ``variances`` ``(2, M, n_max)`` are the diagonals of the corrected (``[0]``, Eq. 20/22)
    and conventional (``[1]``, Eq. 13) covariances in the regressors' units, published
    (repaired: :meth:`repair`, when :attr:`indefinite`), and :attr:`standard_errors` their
    square roots (negative rounding clipped at 0). ``matrices()`` are the unrepaired
    covariances ``(2, M, n_max, n_max)``, formed on first use from the same ``D N`` products as
    ``(P + P') * scale / n_k`` with ``P = D N D``, their diagonals the variances as computed
    (before any repair), so that ``standard_errors`` are exactly ``sqrt(diag(matrices))``. NaN outside the
    ready models' blocks. Where a corrected variance is negative, ``repaired`` maps a model to
    its nearest positive semi-definite matrix, and ``exact`` marks the models that fit
    exactly, whose covariance is published as zero.
    """

    __slots__ = ("indefinite", "repaired", "exact", "_variances", "_standard_errors", "_parts", "_matrices", "_kinds")

    def __init__(self, variances: FloatArray, indefinite: bool, parts: _Parts) -> None:
        self.indefinite = indefinite  # a corrected variance is negative
        self.repaired: dict[int, FloatArray] = {}
        self.exact: BoolArray | None = None
        self._variances = variances
        self._standard_errors: FloatArray | None = None
        self._parts = parts
        self._matrices: FloatArray | None = None
        self._kinds: list[FloatArray | None] = [None, None]  # each kind, formed when first asked for

    def repair(self, exact: BoolArray, sizes: tuple[int, ...]) -> list[int]:
        """Publish the corrected covariance of the models that fit ``exact``-ly as zero (its
        variances are rounding, not indefiniteness), and replace each other one with a
        negative variance by its nearest positive semi-definite matrix; the models repaired."""
        self.exact = exact
        corrected = self._variances[0]
        corrected *= ~exact[:, None]  # (NaN stays)
        counted: list[int] = []
        if np.fmin.reduce(corrected, axis=None) < 0.0:
            for index in np.flatnonzero((corrected < 0.0).any(axis=1)):
                j = int(index)
                s = sizes[j]
                fixed = self.repaired[j] = nearest_psd(self.kind_matrices(0)[j, :s, :s])
                counted.append(j)
                corrected[j, :s] = np.diag(fixed)
        return counted

    @property
    def standard_errors(self) -> FloatArray:
        """The published standard errors ``(2, M, n_max)``, the square roots of the variances."""
        if self._standard_errors is None:
            se = self._variances
            np.maximum(se, 0.0, out=se)
            self._standard_errors = np.sqrt(se, out=se)
        return self._standard_errors

    def matrices(self) -> FloatArray:
        """Both kinds' covariance matrices ``(2, M, n_max, n_max)``: ``[0]`` corrected, ``[1]``
        conventional (:meth:`kind_matrices` of each)."""
        if self._matrices is None:
            self._matrices = np.stack([self.kind_matrices(0), self.kind_matrices(1)])
        return self._matrices

    def kind_matrices(self, kind_index: int) -> FloatArray:
        """``matrices()[kind_index]``, formed without the other kind."""
        cov = self._kinds[kind_index]
        if cov is None:
            DN, DN0, D, hS0, scale, inv_n, Dt, variances = self._parts
            P = np.empty(D.shape)
            if kind_index == 0:
                np.matmul(DN, Dt, out=P)
            elif DN0 is None:
                np.multiply(D, hS0[:, :, None], out=P)
            else:
                np.matmul(DN0, Dt, out=P)
            cov = np.add(P, P.swapaxes(1, 2), out=np.empty(P.shape))
            cov *= scale * inv_n
            n = D.shape[1]
            cov.reshape(D.shape[0], n * n)[:, :: n + 1] = variances[kind_index]
            self._kinds[kind_index] = cov
        return cov

    def matrix(self, kind_index: int, j: int, size: int, *, repair: bool = True) -> FloatArray:
        """Model ``j``'s covariance (a copy), published (``repair``) or unrepaired."""
        if repair and kind_index == 0:
            if j in self.repaired:
                return self.repaired[j].copy()
            if self.exact is not None and self.exact[j]:
                return np.zeros((size, size))
        return self.matrices()[kind_index, j, :size, :size].copy()

    def published(self, sizes: tuple[int, ...], ready: BoolArray) -> FloatArray:
        """:meth:`matrix` with ``repair`` of every model and both kinds in one new array
        ``(2, M, n_max, n_max)``, NaN outside the ``ready`` models' blocks (as
        :meth:`matrices`): the corrected covariance of an exact fit is zero, that of a
        repaired model its nearest positive semi-definite matrix."""
        cov = self.matrices().copy()
        self._published_corrected(cov[0], sizes, ready)
        return cov

    def published_kind(self, kind_index: int, sizes: tuple[int, ...], ready: BoolArray) -> FloatArray:
        """``published(sizes, ready)[kind_index]`` alone, a new ``(M, n_max, n_max)`` array."""
        cov = self.kind_matrices(kind_index).copy()
        if kind_index == 0:
            self._published_corrected(cov, sizes, ready)
        return cov

    def _published_corrected(self, cov: FloatArray, sizes: tuple[int, ...], ready: BoolArray) -> None:
        """The corrected covariances ``cov`` as published: zero for an exact fit, a repaired
        model's nearest positive semi-definite matrix (in place)."""
        if self.exact is not None:
            for index in np.flatnonzero(self.exact & ready):
                j = int(index)
                cov[j, : sizes[j], : sizes[j]] = 0.0
        for j, fixed in self.repaired.items():
            cov[j, : sizes[j], : sizes[j]] = fixed


class CovarianceEvaluator:
    """Evaluates :class:`Covariances` for a bank whose conventional covariance is Eq. 13
    (``eq13``, ``f = 1``) or ``R_k(0) D Lambda_k(0) D`` (``f < 1``). With ``sandwich``
    (instrumental variables) ``D`` is ``P = (Z'X)^-1``, not symmetric, and the lag products
    are the instruments': every covariance is ``P [sum_i c_i R_k(i) Lambda_k(i)] P'`` (the
    conventional one ``R_k(0) P Lambda_k(0) P'``)."""

    def __init__(self, eq13: bool, sandwich: bool = False) -> None:
        self.eq13 = eq13
        self.sandwich = sandwich

    def __call__(
        self, D: FloatArray, D_diagonal: FloatArray, lag_sums: FloatArray, h: FloatArray, lag_products: FloatArray,
        inv_n: float | FloatArray, scale: FloatArray, diagonal_scale: FloatArray, factor: FloatArray | None = None,
    ) -> Covariances:
        """Both covariances of every model, not yet repaired.

        ``D`` ``(M, n, n)`` (``D_diagonal`` its diagonal) and ``lag_products`` ``(M, n, w, n)``
        (``Lambda+_k(i)``) are in column-scaled units; ``lag_sums`` ``(M, w)`` is ``n_k
        R_k(i)`` and ``h`` the half window of the ``w`` lags held; ``inv_n = 1 / n_k`` (or
        ``(M,)``, one per model: with a residual burn-in each model's ``R_k(i)`` has its own
        weight total); ``scale`` ``(M, n, n)`` takes scaled units back to the regressors' (NaN
        outside the ready models' blocks) and ``diagonal_scale`` is ``2 diag(scale)`` ``(M,
        n)``; ``factor`` ``(M,)`` multiplies the corrected covariance alone (the small-sample
        factor of instrumental variables).
        """
        if not isinstance(inv_n, float):  # one 1/n_k per model: folded into the scales (same products)
            scale = scale * inv_n[:, None, None]
            diagonal_scale = diagonal_scale * inv_n[:, None]
            inv_n = 1.0
        hS = lag_sums * h  # n_k h_i R_k(i)
        N = np.matmul(hS[:, None, None, :], lag_products)[:, :, 0, :]  # n_k sum_i h_i R(i) Lambda+(i)
        if factor is not None:
            N *= factor[:, None, None]
        DN = np.matmul(D, N)
        if self.eq13:
            DN0 = None  # Eq. 13: P = R_k(0) D / 2
        else:  # Eq. 22 with n_tau = 0: N = R_k(0) Lambda_k(0) / 2
            DN0 = np.matmul(D, np.matmul(hS[:, None, None, :1], lag_products[:, :, :1])[:, :, 0, :])
        hS0 = hS[:, :1]
        var = np.empty((2, *D.shape[:2]))  # diag(P) = sum_c (D N)_ac D_ac
        vecdot(DN, D, out=var[0])  # Eq. 20 / 22
        if DN0 is None:
            np.multiply(hS0, D_diagonal, out=var[1])  # Eq. 13: R_k(0) D / 2
        else:
            vecdot(DN0, D, out=var[1])  # Eq. 22 with n_tau = 0
        negative = bool(np.minimum.reduce(var[0], axis=None) < 0.0)  # models not ready are 0 here
        var *= diagonal_scale * inv_n  # diag(P + P') * scale / n_k
        Dt = D.swapaxes(1, 2) if self.sandwich else D
        return Covariances(var, negative, (DN, DN0, D, hS0, scale, inv_n, Dt, var.copy()))
