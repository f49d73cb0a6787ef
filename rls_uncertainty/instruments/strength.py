"""Weak instruments: the smallest canonical correlation between instruments and regressors.

From running sums over the samples (``S_ab = sum a b'``, with ``zeta`` the instruments and
``x`` the regressors) and the bias column ``b`` (the regressor ``1``, whose instrument is also
1) partialled out of the others ``o``:

    C_ab = S_ab[o, o] - S_ab[o, b] S_ab[b, o] / S_ab[b, b]
    rho  = singular values of C_zz^(-1/2) C_zx C_xx^(-1/2)                               (W1)

(without a bias column, ``C_ab = S_ab``: correlations about the origin). ``rho`` lies in
[0, 1]; ``rho_min`` near 0 means some direction of the regressors is not moved by the
instruments: the excitation does not excite it beyond the noise and the gusts, and the
instrumental-variables estimate and its standard error are not to be used. ``S_zz`` is the
``Lambda(0)`` of Eq. 21 with instruments in place of regressors and ``S_zx`` the inverse of the
estimator's ``P``; ``S_xx`` is the one sum more. Calm and open-loop gust data give ``rho_min``
of about 0.2-0.96 on the T-2 maneuver; weak closed-loop cases fall below 0.04. The default
threshold :data:`WEAK_BELOW` lies between.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
import numpy.typing as npt

from .bootstrap import saved_array

__all__ = ["WEAK_BELOW", "canonical_correlations", "InstrumentStrength"]

FloatArray = npt.NDArray[np.float64]

WEAK_BELOW = 0.1
# Directions whose variance is below this fraction of the largest are treated as absent.
_RANK_TOL = 1e-12


def _partial(S: FloatArray, bias: int | None) -> FloatArray:
    if bias is None:
        return S
    o = [i for i in range(S.shape[0]) if i != bias]
    out: FloatArray = S[np.ix_(o, o)] - np.outer(S[o, bias], S[bias, o]) / S[bias, bias]
    return out


def _whitener(C: FloatArray) -> FloatArray:
    """``V_r diag(w_r)^(-1/2)`` over the eigen-directions of ``C`` that are not negligible."""
    w, V = np.linalg.eigh(0.5 * (C + C.T))
    keep = w > _RANK_TOL * max(float(w.max(initial=0.0)), np.finfo(float).tiny)
    out: FloatArray = V[:, keep] / np.sqrt(w[keep])
    return out


def canonical_correlations(S_zz: npt.ArrayLike, S_xx: npt.ArrayLike, S_zx: npt.ArrayLike,
                           bias: int | None = None) -> FloatArray:
    """W1 for one model: its canonical correlations, descending, one per non-bias regressor
    (a direction that the instruments or the regressors do not span counts as 0)."""
    Czz, Cxx, Czx = (_partial(np.asarray(S, dtype=float), bias) for S in (S_zz, S_xx, S_zx))
    n = Czx.shape[0]
    if n == 0:
        return np.zeros(0)
    if bias is not None and not np.asarray(S_zz, dtype=float)[bias, bias] > 0:
        return np.zeros(n)
    K = _whitener(Czz).T @ Czx @ _whitener(Cxx)
    rho = np.zeros(n)
    if K.size:
        s = np.linalg.svd(K, compute_uv=False)
        rho[: s.size] = np.clip(s, 0.0, 1.0)
    return rho


class InstrumentStrength:
    """Running sums for W1 over ``M`` models of ``sizes`` parameters in the ``(M, n_max)``
    layout; ``bias``: each model's bias column (``None``: none); ``weak_below``: the threshold
    of :meth:`weak`."""

    def __init__(self, sizes: Sequence[int], bias: Sequence[int | None], weak_below: float = WEAK_BELOW) -> None:
        self.sizes, self.bias = tuple(sizes), tuple(bias)
        if len(self.bias) != len(self.sizes):
            raise ValueError(f"expected a bias column for each of {len(self.sizes)} models, got {len(self.bias)}")
        m, n = len(self.sizes), max(self.sizes)
        self.S_zz = np.zeros((m, n, n))
        self.S_xx = np.zeros((m, n, n))
        self.S_zx = np.zeros((m, n, n))
        self.k = 0
        self.weak_below = weak_below

    def update(self, X: FloatArray, Z: FloatArray) -> None:
        """Add one sample's regressors ``X`` and instruments ``Z`` (both ``(M, n_max)``)."""
        self.S_zz += Z[:, :, None] * Z[:, None, :]
        self.S_xx += X[:, :, None] * X[:, None, :]
        self.S_zx += Z[:, :, None] * X[:, None, :]
        self.k += 1

    def correlations(self, j: int) -> FloatArray:
        """Model ``j``'s canonical correlations, descending."""
        s = self.sizes[j]
        return canonical_correlations(self.S_zz[j, :s, :s], self.S_xx[j, :s, :s], self.S_zx[j, :s, :s], self.bias[j])

    def rho_min(self) -> FloatArray:
        """Each model's smallest canonical correlation ``(M,)``; NaN until a model has more
        samples than parameters, or for a model with only the bias."""
        out = np.full(len(self.sizes), np.nan)
        for j, s in enumerate(self.sizes):
            if self.k > s and s > (self.bias[j] is not None):
                out[j] = self.correlations(j).min()
        return out

    def weak(self) -> npt.NDArray[np.bool_]:
        """Which models' instruments are weak (``rho_min < weak_below``; NaN: not yet known, False)."""
        with np.errstate(invalid="ignore"):
            return self.rho_min() < self.weak_below

    def snapshot(self) -> dict[str, Any]:
        """A copy of the sums as plain data (``counters``: ``k``; ``arrays``: ``S_zz``,
        ``S_xx``, ``S_zx``); :meth:`restore` continues bit-identically."""
        return {"counters": {"k": self.k},
                "arrays": {"S_zz": self.S_zz.copy(), "S_xx": self.S_xx.copy(), "S_zx": self.S_zx.copy()}}

    def restore(self, saved: Mapping[str, Any]) -> None:
        """Continue from :meth:`snapshot` (arrays of another shape: :class:`ValueError`)."""
        for name in ("S_zz", "S_xx", "S_zx"):
            setattr(self, name, saved_array(saved["arrays"][name], getattr(self, name), name))
        self.k = int(saved["counters"]["k"])
