"""The bare recursive least squares that gives the auxiliary model its first estimates.

Before the instrumental-variables estimator has estimates of its own, the auxiliary model
(:mod:`.auxiliary`) is built from an equation-error fit of the same models: Eq. 15 only (no
covariance, no residual sums), started exactly once ``X'X`` is well conditioned. Its estimates
are biased in gusts and noise; the auxiliary model only needs its poles roughly right.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
import numpy.typing as npt

__all__ = ["BareRls", "saved_array"]

FloatArray = npt.NDArray[np.float64]


class BareRls:
    """Eq. 15 for ``M`` models of ``sizes`` parameters in the bank's ``(M, n_max)`` layout.

    Until :attr:`ready` it sums ``X'X`` and ``X'z``; at the first sample ``k >= max(n,
    min_samples)`` at which every model's column-scaled ``X'X`` has a condition number below
    ``init_condition``, ``theta = (X'X)^-1 X'z`` and ``D = (X'X)^-1`` (Eq. 13-14); then
    Eq. 15 per sample. Padding stays 0 in ``theta``.
    """

    def __init__(self, sizes: Sequence[int], *, init_condition: float = 1e8, min_samples: int = 25) -> None:
        self.sizes = tuple(int(s) for s in sizes)
        m, n = len(self.sizes), max(self.sizes)
        self.mask = np.zeros((m, n), dtype=bool)
        for j, s in enumerate(self.sizes):
            self.mask[j, :s] = True
        self.A = np.zeros((m, n, n))
        self.b = np.zeros((m, n))
        self.D = np.zeros((m, n, n))
        self.theta = np.zeros((m, n))
        self.ready = False
        self.k = 0
        self.init_condition, self.min_samples = init_condition, min_samples

    def update(self, X: FloatArray, z: FloatArray) -> None:
        """One sample: ``X`` ``(M, n_max)`` (padding ignored), ``z`` ``(M,)``."""
        self.k += 1
        if not self.ready:
            X = np.where(self.mask, X, 0.0)
            self.A += X[:, :, None] * X[:, None, :]
            self.b += X * z[:, None]
            if self.k >= max(*self.sizes, self.min_samples):
                self._try_start()
            return
        # D and theta are 0 on the padding, so the padding of X drops out here.
        Dx = (self.D @ X[:, :, None])[:, :, 0]
        d = 1.0 + (X * Dx).sum(axis=1)
        e = z - (X * self.theta).sum(axis=1)
        self.theta += Dx * (e / d)[:, None]
        self.D -= Dx[:, :, None] * (Dx / d[:, None])[:, None, :]

    def _try_start(self) -> None:
        """Eq. 13-14 if every model's scaled ``X'X`` is well conditioned (padding: identity)."""
        pad = ~self.mask
        A = self.A + np.einsum("mi,ij->mij", pad.astype(float), np.eye(self.mask.shape[1]))
        s = np.sqrt(np.einsum("mii->mi", A))
        if not np.all(s > 0):
            return
        scaled = A / (s[:, :, None] * s[:, None, :])
        if not np.all(np.linalg.cond(scaled) < self.init_condition):
            return
        self.D = np.linalg.inv(A) * self.mask[:, :, None] * self.mask[:, None, :]
        self.theta = np.einsum("mij,mj->mi", self.D, self.b)
        self.ready = True

    def snapshot(self) -> dict[str, Any]:
        """A copy of the state as plain data (``counters``: ``k``, ``ready``; ``arrays``:
        ``A``, ``b``, ``D``, ``theta``); :meth:`restore` continues bit-identically."""
        return {"counters": {"k": self.k, "ready": self.ready},
                "arrays": {"A": self.A.copy(), "b": self.b.copy(), "D": self.D.copy(), "theta": self.theta.copy()}}

    def restore(self, saved: Mapping[str, Any]) -> None:
        """Continue from :meth:`snapshot` (arrays of another shape: :class:`ValueError`)."""
        arrays = saved["arrays"]
        for name in ("A", "b", "D", "theta"):
            setattr(self, name, saved_array(arrays[name], getattr(self, name), name))
        self.k, self.ready = int(saved["counters"]["k"]), bool(saved["counters"]["ready"])


def saved_array(value: npt.ArrayLike, like: FloatArray, name: str) -> FloatArray:
    """A float copy of ``value``, which must have the shape of ``like``."""
    arr = np.array(value, dtype=float)
    if arr.shape != like.shape:
        raise ValueError(f"saved {name} has shape {arr.shape}, expected {like.shape}")
    return arr
