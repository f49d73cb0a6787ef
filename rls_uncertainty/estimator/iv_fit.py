"""One recursive instrumental-variables fit of ``M`` models, vectorised (the IV form of
Eqs. 15-17).

With instruments ``zeta_k`` (uncorrelated with the equation error) the batch estimate is
``theta = (Z'X)^-1 Z'z = P Z'z`` (:func:`.reference.batch_iv`), and per sample, from the
exact initialization on (Sherman-Morrison on ``P^-1 = Z'X``):

    e_k = z_k - x_k' theta_(k-1),   g_k = P_(k-1) zeta_k,   h_k = P_(k-1)' x_k,
    d_k = 1 + x_k' g_k,   theta_k = theta_(k-1) + g_k e_k / d_k,   P_k = P_(k-1) - g_k h_k' / d_k.

``P`` is not symmetric, so it is kept transposed, ``Q = P'``, in the rows of one array
``aug = [Q; theta']`` ``(M, n+1, n)``: one matmul gives ``(h, theta' x)`` and the update is
one rank-one product ``[Q; theta'] -= (h, -e_k) g_k' / d_k``. With ``zeta = x``, ``P = D`` and
this is Eq. 15 with ``f = 1``.

The standardized residual is ``v_k = e_k / sqrt(1 + h_k' Lambda_(k-1)(0) h_k)``: with white
residuals of variance ``s^2`` the error of ``theta_(k-1)`` has covariance ``s^2 P Lambda(0)
P'`` (the sandwich with ``R(i) = 0`` for ``i > 0``), so ``var(e_k) = s^2 (1 + h' Lambda(0)
h)``; with ``zeta = x`` the denominator is ``d_k`` (the RLS's). ``a_posteriori`` is ``e_k /
d_k = z_k - x_k' theta_k``, ``a_priori`` is ``e_k``. Regressors and instruments are the bank's
column-scaled ones (``x / s``, ``zeta / t``), so ``P`` and ``theta`` are ``S P T`` and ``S theta``.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np
import numpy.typing as npt

from .lag_storage import LagStorage, Sample, assign_checked
from .numpy_compat import vecdot

__all__ = ["IvFit", "InstrumentSample"]

FloatArray = npt.NDArray[np.float64]


class IvFit:
    """``[P'; theta']`` of ``m`` models of at most ``n`` parameters and the sample being
    added: :meth:`prepare` (its ``h``, ``g``, innovation, ``d_k`` and standardization), then
    :meth:`update` and :meth:`residual`. :attr:`D` is ``P`` (a view), which the covariance
    evaluation uses as the sandwich's outer factor."""

    forgetting = 1.0

    def __init__(self, m: int, n: int, residual: str, instruments: InstrumentSample, lags: LagStorage) -> None:
        self.residual_kind = residual
        self._instruments, self._lags = instruments, lags
        self._aug = np.zeros((m, n + 1, n))  # [P'; theta'] (scaled units)
        self.Q = self._aug[:, :n]  # P'
        self.D = self.Q.swapaxes(1, 2)  # P (a view; read by the evaluation)
        self.theta = self._aug[:, n]
        self.theta_row = self._aug[:, n, None, :]
        self._h = np.zeros((m, n + 1, 1))  # (P' x, theta' x - z): -e_k in the last row
        self._hx = self._h[:, :n, 0]
        self._neg_e = self._h[:, n, 0]
        self._g = np.zeros((m, 1, n))  # (P zeta)'
        self._d = np.zeros(m)
        self._d_col = self._d[:, None, None]
        self._root = np.zeros(m)
        self._outer = np.zeros((m, n + 1, n))

    def prepare(self, x: FloatArray, x_col: FloatArray, z: FloatArray) -> float:
        """``h = P' x``, ``g = P zeta``, ``-e_k`` and ``d_k = 1 + x' g`` of the scaled regressors
        ``x`` (``x_col`` their column view), outputs ``z`` and the instruments' sample (set
        before), and the standardization ``sqrt(1 + h' Lambda_(k-1)(0) h)`` (the instruments'
        ``Lambda(0)`` of the lag storage); state untouched. Returns ``|(h, e)|^2 + |g|^2``, the
        magnitude the bank's overflow guard looks at."""
        np.matmul(self._aug, x_col, out=self._h)  # (P' x, theta' x)
        np.matmul(self._instruments.row, self.Q, out=self._g)  # zeta' P' = (P zeta)'
        d = vecdot(x, self._g[:, 0], out=self._d)
        d += 1.0
        np.subtract(self._neg_e, z, out=self._neg_e)
        if self.residual_kind == "standardized":
            h = self._hx
            lag0 = self._lags.lag0
            np.sqrt(1.0 + vecdot(h, np.matmul(lag0, h[:, :, None])[:, :, 0]), out=self._root)
        flat_h, flat_g = self._h.reshape(-1), self._g.reshape(-1)
        magnitude: float = np.dot(flat_h, flat_h) + np.dot(flat_g, flat_g)
        return magnitude

    def update(self) -> None:
        """The prepared sample: ``[P'; theta'] -= (h, -e_k) g' / d_k``."""
        outer = np.multiply(self._h, self._g, out=self._outer)
        outer /= self._d_col
        self._aug -= outer

    def residual(self, out: FloatArray) -> None:
        """The prepared sample's residual ``v_k`` of the chosen kind (module docstring), to
        ``out`` (the caller's history slot)."""
        if self.residual_kind == "standardized":
            np.divide(self._neg_e, np.negative(self._root), out=out)
        elif self.residual_kind == "a_posteriori":
            np.divide(self._neg_e, np.negative(self._d), out=out)
        else:
            np.negative(self._neg_e, out=out)

    def start(self, j: int, D: FloatArray, theta: FloatArray) -> None:
        """Model ``j``'s ``P`` and ``theta`` (scaled units, its ``s`` parameters): the batch
        estimate at its exact initialization."""
        s = theta.shape[0]
        self.Q[j, :s, :s] = D.T
        self.theta[j, :s] = theta

    # ------------------------------------------------------------------ state
    def arrays(self, prefix: str) -> dict[str, FloatArray]:
        """Copies of ``P`` and ``theta`` as ``{prefix}dispersion``, ``{prefix}theta``."""
        return {f"{prefix}dispersion": self.D.copy(), f"{prefix}theta": self.theta.copy()}

    def load(self, arrays: Mapping[str, npt.ArrayLike], prefix: str) -> None:
        """Inverse of :meth:`arrays`; another shape is refused by name."""
        assign_checked(self.D, arrays[f"{prefix}dispersion"], f"{prefix}dispersion")
        assign_checked(self.theta, arrays[f"{prefix}theta"], f"{prefix}theta")


class InstrumentSample:
    """The sample as the lag storage sees it under instrumental variables: ``x`` (``x_col``)
    the column-scaled instruments ``zeta / t``, ``y`` (``y_col``) the bank's scaled ``(x, z)``
    (``sample``, a :class:`.bank.ScaledSample`); ``row`` the instruments as ``(M, 1, n)``."""

    def __init__(self, sample: Sample, m: int, n: int) -> None:
        self.y, self.y_col = sample.y, sample.y_col
        self.x = np.zeros((m, n))
        self.x_col = self.x[:, :, None]
        self.row = self.x[:, None, :]

    def set(self, zeta: FloatArray, inv_t: FloatArray) -> bool:
        """``zeta / t``; True when every entry is at most 1e100 in magnitude."""
        np.multiply(zeta, inv_t, out=self.x)
        small: bool = np.max(np.abs(self.x)) <= 1e100
        return small
