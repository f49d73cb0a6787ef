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
    """``[D; theta']`` of ``m`` models of at most ``n`` parameters with forgetting ``f`` and
    its per-sample scratch; :meth:`prepare` then :meth:`apply` add one sample."""

    def __init__(self, m: int, n: int, forgetting: float, residual: str) -> None:
        self.forgetting = forgetting
        self.residual = residual
        self.aug = np.zeros((m, n + 1, n))  # [D; theta'] (scaled units)
        self.D = self.aug[:, :n]
        self.theta = self.aug[:, n]
        self.theta_row = self.aug[:, n, None, :]
        # g = (D x, theta' x - z) as a column: the matmul's output, then -e_k in its last row.
        self.g = np.zeros((m, n + 1, 1))
        self.Dx = self.g[:, :n, 0]
        self._Dx_row = self.g[:, None, :n, 0]
        self.neg_e = self.g[:, n, 0]
        self._g_flat = self.g.reshape(-1)
        self.d = np.zeros(m)  # d_k = f + x' D x
        self._d_col = self.d[:, None, None]
        self._root = np.zeros(m)  # sqrt(d_k / f)
        self._outer = np.zeros((m, n + 1, n))

    def prepare(self, xs: FloatArray, xs_col: FloatArray, z: FloatArray) -> float:
        """``g = (D x, theta' x - z)`` and ``d_k = f + x' D x`` (Eq. 15a's denominator) of the
        scaled regressors ``xs`` (``xs_col`` their column view), state untouched; returns
        ``|g|^2``, the magnitude the bank's overflow guard looks at."""
        np.matmul(self.aug, xs_col, out=self.g)  # (D x, theta' x)
        d = vecdot(xs, self.Dx, out=self.d)
        d += self.forgetting  # d_k = f + x' D x
        np.subtract(self.neg_e, z, out=self.neg_e)  # -e_k = x' theta_(k-1) - z_k
        magnitude: float = np.dot(self._g_flat, self._g_flat)
        return magnitude

    def apply(self, residual_out: FloatArray) -> None:
        """Eqs. 15a-c for the prepared sample, and its residual (Eqs. 16-17) to ``residual_out``."""
        f = self.forgetting
        outer = np.multiply(self.g, self._Dx_row, out=self._outer)
        outer /= self._d_col
        self.aug -= outer  # Eq. 15b (D rows), Eq. 15c (theta row)
        if f != 1.0:
            self.D /= f  # Eq. 15b with forgetting
        self._residual(residual_out)

    def _residual(self, out: FloatArray) -> None:
        """The residual of Eqs. 16-17 of the chosen kind from ``-e_k`` and ``d_k``."""
        f, d, root = self.forgetting, self.d, self._root
        if self.residual == "standardized":  # v_k = e_k sqrt(f/d_k)
            root = np.sqrt(d if f == 1.0 else np.divide(d, f, out=root), out=root)
            np.divide(self.neg_e, np.negative(root, out=root), out=out)
        elif self.residual == "a_posteriori":
            np.multiply(self.neg_e / d, -f, out=out)  # v_k = e_k f/d_k = z_k - x_k' theta_k (Eq. 7)
        else:
            np.negative(self.neg_e, out=out)  # v_k = e_k

    def set_model(self, j: int, D: FloatArray, theta: FloatArray) -> None:
        """Model ``j``'s ``D`` and ``theta`` (scaled units, its ``s`` parameters): an exact
        initialization (Eq. 6) or a prior."""
        s, n = theta.shape[0], self.aug.shape[2]
        self.aug[j, :s, :s] = D
        self.aug[j, n, :s] = theta

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
