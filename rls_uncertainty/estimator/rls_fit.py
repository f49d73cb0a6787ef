"""One recursive least-squares fit of ``M`` models, vectorised (Eqs. 15a-c, 16-17).

The bank runs it once for the estimator (forgetting ``f``) and, under forgetting, a second
time for the noise model whose residuals give ``R_k(i)`` (forgetting ``f_R``, see
``docs/estimator.md``): the same regressors, outputs and residual kind, another factor.

``D`` and ``theta`` are the rows of one array ``aug = [D; theta']`` ``(M, n+1, n)``, so that
one matmul gives ``g = (D x, theta' x)`` and Eqs. 15b-c are one rank-one update with
``u = (D x, -e)``: ``[D; theta'] -= u (D x)' / d``. ``D - (Dx)(Dx)'/d`` is exactly symmetric
in floating point; the algebraically equal ``(I - K x') D`` is not, and under forgetting its
antisymmetric rounding error grows like ``f^-k`` until the estimator diverges. The regressors
are the bank's column-scaled ones (``x / s``); so are ``D`` and ``theta`` (``S D S`` and
``S theta``).
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np
import numpy.typing as npt

from .lag_storage import assign_checked
from .numpy_compat import vecdot

__all__ = ["RlsFit"]

FloatArray = npt.NDArray[np.float64]


class RlsFit:
    """``[D; theta']`` of ``m`` models of at most ``n`` parameters with forgetting ``f``, and
    the sample being added: :meth:`prepare` (its ``D x``, innovation and ``d_k``), then
    :meth:`update` (Eq. 15) and :meth:`residual` (the ``v_k`` of Eqs. 16-17)."""

    def __init__(self, m: int, n: int, forgetting: float, residual: str) -> None:
        self.forgetting = forgetting
        self.residual_kind = residual
        self._aug = np.zeros((m, n + 1, n))  # [D; theta'] (scaled units)
        self.D = self._aug[:, :n]  # (read by the evaluation; written here only)
        self.theta = self._aug[:, n]
        self.theta_row = self._aug[:, n, None, :]
        # g = (D x, theta' x - z) as a column: the matmul's output, then -e_k in its last row.
        self._g = np.zeros((m, n + 1, 1))
        self._Dx = self._g[:, :n, 0]
        self._Dx_row = self._g[:, None, :n, 0]
        self._neg_e = self._g[:, n, 0]
        self._g_flat = self._g.reshape(-1)
        self._d = np.zeros(m)  # d_k = f + x' D x
        self._d_col = self._d[:, None, None]
        self._root = np.zeros(m)  # sqrt(d_k / f)
        self._outer = np.zeros((m, n + 1, n))

    def prepare(self, x: FloatArray, x_col: FloatArray, z: FloatArray) -> float:
        """``g = (D x, theta' x - z)`` and ``d_k = f + x' D x`` (Eq. 15a's denominator) of the
        scaled regressors ``x`` (``x_col`` their column view) and outputs ``z``, state
        untouched; returns ``|g|^2``, the magnitude the bank's overflow guard looks at."""
        np.matmul(self._aug, x_col, out=self._g)  # (D x, theta' x)
        d = vecdot(x, self._Dx, out=self._d)
        d += self.forgetting  # d_k = f + x' D x
        np.subtract(self._neg_e, z, out=self._neg_e)  # -e_k = x' theta_(k-1) - z_k
        magnitude: float = np.dot(self._g_flat, self._g_flat)
        return magnitude

    def update(self) -> None:
        """Eqs. 15a-c for the prepared sample: ``[D; theta'] -= (D x, -e_k) (D x)' / d_k``,
        then ``D /= f``."""
        outer = np.multiply(self._g, self._Dx_row, out=self._outer)
        outer /= self._d_col
        self._aug -= outer  # Eq. 15b (D rows), Eq. 15c (theta row)
        if self.forgetting != 1.0:
            self.D /= self.forgetting  # Eq. 15b with forgetting

    def residual(self, out: FloatArray) -> None:
        """The prepared sample's residual ``v_k`` of Eqs. 16-17, of the chosen kind, to ``out``
        (the caller's history slot)."""
        f, d, root = self.forgetting, self._d, self._root
        if self.residual_kind == "standardized":  # v_k = e_k sqrt(f/d_k)
            root = np.sqrt(d if f == 1.0 else np.divide(d, f, out=root), out=root)
            np.divide(self._neg_e, np.negative(root, out=root), out=out)
        elif self.residual_kind == "a_posteriori":
            np.multiply(self._neg_e / d, -f, out=out)  # v_k = e_k f/d_k = z_k - x_k' theta_k (Eq. 7)
        else:
            np.negative(self._neg_e, out=out)  # v_k = e_k

    def start(self, j: int, D: FloatArray, theta: FloatArray) -> None:
        """Model ``j``'s ``D`` and ``theta`` (scaled units, its ``s`` parameters): an exact
        initialization (Eq. 6)."""
        s, n = theta.shape[0], self._aug.shape[2]
        self._aug[j, :s, :s] = D
        self._aug[j, n, :s] = theta

    def set_prior(self, D: FloatArray) -> None:
        """``D_0`` of every model (scaled units), ``theta_0 = 0``."""
        self.D[...] = D

    # ------------------------------------------------------------------ state
    def arrays(self, prefix: str) -> dict[str, FloatArray]:
        """Copies of ``D`` and ``theta`` as ``{prefix}dispersion``, ``{prefix}theta``."""
        return {f"{prefix}dispersion": self.D.copy(), f"{prefix}theta": self.theta.copy()}

    def load(self, arrays: Mapping[str, npt.ArrayLike], prefix: str) -> None:
        """Inverse of :meth:`arrays`; another shape is refused by name."""
        assign_checked(self.D, arrays[f"{prefix}dispersion"], f"{prefix}dispersion")
        assign_checked(self.theta, arrays[f"{prefix}theta"], f"{prefix}theta")
