"""The residual burn-in and the sample counts behind ``R_k(i)`` (``docs/estimator.md``).

With ``residual_burn_in`` ``B > 0`` a model initialized at ``k0`` forms ``R_k(i)`` from the
residuals of samples ``k0 + B + 1 .. k`` only (:mod:`.reference` defines it). Nothing of it
is stored: each model's last left-out sample ``k0 + B`` follows from ``ready_at``, the weight
total of its ``R_k(i)`` and the lag rule's sample count are closed forms of ``k - k0 - B``,
and the products reaching back into the burn-in are zeroed (:meth:`BurnIn.mask`) only while
some model's lag window still reaches into it (``held + 1`` samples after it; always with all
lags). With ``B = 0`` every count is one float for all models, as in the paper.
"""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt

__all__ = ["BurnIn"]

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]
BoolArray = npt.NDArray[np.bool_]

_NEVER = 2**62  # the burn-in end of a model that is not initialized (no sample reaches it)


class BurnIn:
    """The burn-in ``B`` of ``m`` models whose ``R_k(i)`` is weighted ``g^(k-j)`` (``g = f_R``)."""

    def __init__(self, m: int, burn_in: int, noise_forgetting: float) -> None:
        self.B = burn_in
        self.active = burn_in > 0
        self.g = noise_forgetting
        self.end: IntArray = np.full(m, _NEVER, dtype=np.int64)  # each model's last left-out sample k0 + B
        self.masking = self.active  # some model's lag window still reaches into its burn-in
        self._at: int | None = None  # the sample _counts is of
        self._counts: FloatArray | None = None

    def restart(self, ready: BoolArray, ready_at: IntArray, k: int, cap: int) -> None:
        """The ends after a model initialized or a state was restored (``cap`` lags held at most)."""
        if self.active:
            self.end = np.where(ready, ready_at + self.B, _NEVER)
            self.masking = int((k - self.end).min()) < max(1, cap - 1)
            self._at = None

    def mask(self, sums: FloatArray, lagged: FloatArray, k: int, w: int, cap: int) -> None:
        """At sample ``k`` (``w`` lags held): a model whose burn-in ended at the previous sample
        starts its lag sums afresh, and the products with a partner ``v_(k-i)`` of the burn-in
        (``k - i <= k0 + B``) are left out. Called while :attr:`masking`."""
        after = k - self.end  # samples since the burn-in ended (<= 0: in it, the paper's Eq. 17)
        sums[after == 1] = 0.0
        lagged[(np.arange(w) >= after[:, None]) & (after[:, None] > 0)] = 0.0
        if int(after.min()) >= max(1, cap - 1):  # every start done, no window reaches back
            self.masking = False

    def counts(self, k: int) -> FloatArray | None:
        """Each model's samples after its burn-in (0 during it) as floats, or None while no
        model is past it (always with ``B = 0``); computed once per sample."""
        if not self.active:
            return None
        if self._at != k:
            after = k - self.end
            self._counts = np.maximum(after, 0).astype(float) if int(after.max()) > 0 else None
            self._at = k
        return self._counts

    def weight_totals(self, k: int, n: float) -> float | FloatArray:
        """The weight total of each model's ``R_k(i)``: ``n`` (``sum_j g^(k-j)``) while no
        model is past its burn-in, else per model ``sum_(j > k0+B) g^(k-j)``."""
        c = self.counts(k)
        if c is None:
            return n
        g = self.g
        burned = c if g == 1.0 else -np.expm1(c * math.log(g)) / (1.0 - g)  # sum_(j > k0+B) g^(k-j)
        totals: FloatArray = np.where(c > 0.0, burned, n)
        return totals

    def rule_samples(self, k: int) -> float | FloatArray:
        """The lag rule's sample count: ``k``, or under forgetting Kish's effective size
        ``(1 - g^k)(1 + g) / ((1 - g)(1 + g^k))`` of the weights ``g^(k-j)``; after a model's
        burn-in the same with ``k - k0 - B`` samples (one float while no model is past it)."""
        g = self.g
        if g == 1.0:
            n = float(k)
        else:
            gk = g**k
            n = (1.0 - gk) * (1.0 + g) / ((1.0 - g) * (1.0 + gk))
        c = self.counts(k)
        if c is None:
            return n
        if g == 1.0:
            burned = c
        else:
            gc = np.power(g, c)
            burned = (1.0 - gc) * (1.0 + g) / ((1.0 - g) * (1.0 + gc))
        counts: FloatArray = np.where(c > 0.0, burned, n)
        return counts
