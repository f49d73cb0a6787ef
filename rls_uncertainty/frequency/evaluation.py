"""The corrected covariance's two parts as one :class:`.bank.FrequencyBank` evaluation computes
them (docs/frequency.md, F7-F10), for all models at once with the fewest array operations:
:meth:`Evaluation.autocovariance` (F9-F10, the residual autocovariance of the record's
time-domain fit corrected for its degrees of freedom) and :meth:`Evaluation.middle` (F7-F8, the
middle of the sandwich in closed form). Their numbers are those of
:func:`.lags.residual_autocovariance` and :func:`.covariance.middle`, the explicit forms, to
rounding; here the transforms are taken frequency-last as the bank keeps them, the working
arrays are kept between evaluations and the fixed tables per grid, lag count and model
structure. numpy only.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from .covariance import PairGeometry, trim_terms
from .instrumental import instrumental_fit
from .lags import _bias_terms, centering, pseudo_inverse

__all__ = ["Evaluation"]

FloatArray = npt.NDArray[np.float64]
ComplexArray = npt.NDArray[np.complex128]
BoolArray = npt.NDArray[np.bool_]

# Up to this many frequencies :meth:`Evaluation.middle` maps the transforms with one product
# (fewer calls), beyond it with two of half the arithmetic (the K^2 part dominates).
ONE_PRODUCT = 100


class Evaluation:
    """Working arrays and fixed tables of one bank's evaluation: ``M`` models of ``q`` signals
    (``z`` and ``p = q - 1`` regressors, padded), ``K`` frequencies of ``geometry``."""

    def __init__(self, columns: BoolArray, geometry: PairGeometry) -> None:
        M, q = columns.shape
        K, p = geometry.angles.size, q - 1
        self.real: BoolArray = columns[:, 1:]
        self.geometry = geometry
        # [L(X), L(Y)] and [conj(b) X, -b Y, d X; Gamma; V], by parameter, frequency-last.
        self._xy: ComplexArray = np.empty((M, p, 2, K), complex)  # X and Y = conj(rho) X
        self._lxy: ComplexArray = np.empty((M, p, 2, K), complex)
        self._right: ComplexArray = np.zeros((M, p + 2, 3 * K), complex)
        self._factors: ComplexArray = np.empty((M, 3, K), complex)
        # L(a) = 1' Re a + cot_imag Im a + j cot_real Re a (:meth:`_map_rows`).
        self._map: FloatArray | None = None
        if K <= ONE_PRODUCT:
            self._map = np.zeros((2 * K, 2 * K))  # a real map of interleaved rows
            self._map[0::2, 0::2] = 1.0
            self._map[1::2, 0::2] = geometry.cot_imag.T
            self._map[0::2, 1::2] = geometry.cot_real.T
        else:
            self._cot_imag_t: FloatArray = np.ascontiguousarray(geometry.cot_imag.T)
            self._cot_real_t: FloatArray = np.ascontiguousarray(geometry.cot_real.T)
        self._shifted: FloatArray = np.zeros((M, 0))  # F10's T(j) laid out for its lag matrix
        self._w: FloatArray = np.ones((M, 1, q))
        self._outer: FloatArray = np.empty((M, q + 1, q + 1))

    # ------------------------------------------------------------------ F9-F10
    def autocovariance(
        self, augmented: FloatArray, N: int, correct: bool, cross: FloatArray | None = None,
    ) -> tuple[FloatArray, FloatArray]:
        """:func:`.lags.residual_autocovariance`: ``R(0..L)`` ``(M, L+1)`` of the record's
        least-squares (``cross``: instrumental-variable) fit with a bias, plus ``D R + D^2 R``
        when ``correct`` (Eq. F10), and ``C_0`` ``(M, q, q)``."""
        M, lags, q1 = augmented.shape[:3]
        first = augmented[:, 0]
        E = centering(augmented)
        C0 = E @ first @ E.swapaxes(1, 2)
        B_inv = pseudo_inverse(C0[:, 1:, 1:], self.real)
        w = self._w  # (1, -theta)
        if cross is None:
            np.negative(np.einsum("mab,mb->ma", B_inv, C0[:, 1:, 0]), out=w[:, 0, 1:])
        else:
            np.negative(instrumental_fit(cross, E, C0, self.real), out=w[:, 0, 1:])
        weight = w @ E  # R(i) = w' C_i w / N = (E'w)' Sa_i (E'w) / N
        flat = augmented.reshape(M, lags, q1 * q1)
        outer = np.multiply(weight.swapaxes(1, 2), weight, out=self._outer).reshape(M, q1 * q1, 1)
        R0: FloatArray = (flat @ outer)[:, :, 0] / N
        if not correct:
            return R0, C0
        Ex = E[:, 1:]
        Bt = Ex.swapaxes(1, 2) @ B_inv.swapaxes(1, 2) @ Ex  # tr(B^+ C^x_j) = Sa_j . Bt
        lagged = self._lagged_matrix((flat @ Bt.reshape(M, q1 * q1, 1))[:, :, 0], N)  # tr(B^+ C^x_i)
        R1 = R0 + self._apply(R0, lagged, flat, first, Bt, N)
        R: FloatArray = R0 + self._apply(R1, lagged, flat, first, Bt, N)
        return R, C0

    def _lagged_matrix(self, traces: FloatArray, N: int) -> FloatArray:
        """The part of ``N D`` (:func:`.lags.dof_correction`) linear in ``R`` through fixed
        matrices: ``T``'s Toeplitz and Hankel parts and the bias's terms, ``(M, L+1, L+1)``."""
        M, lags = traces.shape
        L = lags - 1
        if self._shifted.shape[1] != 4 * L + 1:
            self._shifted = np.zeros((M, 4 * L + 1))  # 2 T(j), j = -2L..2L (0 beyond L)
        shifted = self._shifted
        T2 = np.multiply(traces, 2.0, out=shifted[:, 2 * L : 3 * L + 1])
        shifted[:, L : 2 * L + 1] = T2[:, ::-1]
        step, offset = shifted.strides, 2 * L * shifted.strides[1]
        toeplitz = np.ndarray((M, lags, lags), np.float64, shifted, offset, (step[0], -step[1], step[1]))
        hankel = np.ndarray((M, lags, lags), np.float64, shifted, offset, (step[0], step[1], step[1]))
        lagged: FloatArray = toeplitz + hankel
        lagged[:, :, 0] -= T2  # the Hankel part starts at j = 1
        lagged += _bias_terms(N, L)
        return lagged

    @staticmethod
    def _apply(R: FloatArray, lagged: FloatArray, flat: FloatArray, first: FloatArray, Bt: FloatArray,
               N: int) -> FloatArray:
        """``(D R)`` of Eq. F10 (:func:`.lags.dof_correction`)."""
        M, q1 = first.shape[:2]
        summed = (R[:, None, :] @ flat).reshape(M, q1, q1)  # sum_l R(l) Sa_l
        middle = summed + summed.swapaxes(1, 2)
        middle -= R[:, :1, None] * first
        traces = flat @ (Bt @ middle @ Bt).reshape(M, q1 * q1, 1)
        out: FloatArray = (lagged @ R[:, :, None])[:, :, 0]
        out -= traces[:, :, 0]
        out /= N
        return out

    # ------------------------------------------------------------------ F7-F8
    def _map_rows(self, rows: FloatArray, out: FloatArray) -> None:
        """``L(a) = 1' Re a + cot_imag Im a + j cot_real Re a`` of every row ``a`` of ``rows``
        (complex numbers interleaved, ``(n, 2K)``), written to ``out`` alike: up to
        :data:`ONE_PRODUCT` frequencies one product with the fixed real ``(2K, 2K)`` map (its
        zero and all-ones blocks included: one call), beyond it the two ``K x K`` products on the
        rows' real and imaginary parts, half the arithmetic."""
        if self._map is not None:
            np.matmul(rows, self._map, out=out)
            return
        n, K = rows.shape[0], rows.shape[1] // 2
        parts = np.moveaxis(rows.reshape(n, K, 2), 2, 0).copy()  # real and imaginary rows
        shaped = out.reshape(n, K, 2)
        np.matmul(parts[1], self._cot_imag_t, out=shaped[:, :, 0])
        shaped[:, :, 0] += parts[0].sum(axis=1, keepdims=True)
        np.matmul(parts[0], self._cot_real_t, out=shaped[:, :, 1])

    def middle(self, R: FloatArray, X: ComplexArray, N: int, trim: int = 1) -> FloatArray:
        """:func:`.covariance.middle` of the transforms ``X`` taken frequency-last, ``(M, p, K)``,
        at ``N`` samples: ``(1/2) Re(X^H M X + X^H P conj(X))`` ``(M, p, p)``, divided by ``dt^2``."""
        g = self.geometry.at(N)
        m, p, K = X.shape
        sums = R[:, 1:] @ g.spectral_table(R.shape[1] - 1)  # S+ and Re S1
        plus: ComplexArray = sums[:, : 2 * K].view(np.complex128)
        r0 = R[:, :1]
        base = 2.0 * plus
        base += r0  # R(0) + 2 S
        xy, lxy, right = self._xy, self._lxy, self._right
        xy[:, :, 0] = X
        np.multiply(X, g.rho_conj, out=xy[:, :, 1])
        self._map_rows(xy.view(np.float64).reshape(2 * m * p, 2 * K), lxy.view(np.float64).reshape(2 * m * p, 2 * K))
        # The right-hand rows are X times conj(b), -b conj(rho) and (N s - 2 Re S1), b = R(0) + 2 S.
        factors = self._factors
        np.conjugate(base, out=factors[:, 0])
        np.multiply(base, g.rho_conj, out=factors[:, 1])
        np.negative(factors[:, 1], out=factors[:, 1])
        diagonal = np.multiply(base.real, g.N, out=factors[:, 2].real)
        diagonal -= 2.0 * sums[:, 2 * K :]
        factors[:, 2].imag = 0.0
        np.multiply(factors[:, None], X[:, :, None], out=right[:, :p].reshape(m, p, 3, K))
        if trim == 1:
            np.add(r0, plus, out=right[:, p + 1, 2 * K :])
            var = R[:, 0]
        else:
            right[:, p + 1, 2 * K :], var = trim_terms(R, g, trim)
        right[:, p, 2 * K :] = g.gamma
        # Re(left^H right) with left = [L(X), L(Y), X]: real products of the interleaved views.
        contracted = lxy.view(np.float64).reshape(m, p, 4 * K) @ right[:, :, : 2 * K].view(np.float64).swapaxes(1, 2)
        contracted += X.view(np.float64) @ right[:, :, 2 * K :].view(np.float64).swapaxes(1, 2)  # (M, p, p + 2)
        mid = contracted[:, :, :p]
        mid *= 0.5
        gam = contracted[:, :, p]
        mid += (var[:, None] * gam - 2.0 * contracted[:, :, p + 1])[:, :, None] * gam[:, None, :]
        out: FloatArray = mid + mid.swapaxes(1, 2)
        out *= 0.5
        return out
