"""The sample counts behind ``R_k(i)``, and the residual burn-in (``docs/estimator.md``).

:class:`SampleCounts` owns the counters of a bank: the sample count ``k``, the weight total
``n_k = sum_j f^(k-j)`` of the estimator (``k`` when ``f = 1``) and, with a noise model, that
of the noise model, ``n^N_k = sum_j f_R^(k-j)``: ``R_k(i)`` of Eq. 17 is its lag sums over
the latter (over ``n_k`` without a noise model).

With ``residual_burn_in`` ``B > 0`` a model initialized at ``k0`` forms ``R_k(i)`` from the
residuals of samples ``k0 + B + 1 .. k`` only (:mod:`.reference` defines it). Nothing of it
is stored: each model's last left-out sample ``k0 + B`` follows from ``ready_at``, the weight
total of its ``R_k(i)`` and the lag rule's sample count are closed forms of ``k - k0 - B``,
and the products reaching back into the burn-in are left out (:meth:`SampleCounts.burn_in`)
only while some model's lag window still reaches into it (``held + 1`` samples after it;
always with all lags). With ``B = 0`` every count is one float for all models, as in the
paper.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import numpy as np
import numpy.typing as npt

__all__ = ["SampleCounts"]

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]
BoolArray = npt.NDArray[np.bool_]

_NEVER = 2**62  # the burn-in end of a model that is not initialized (no sample reaches it)


class SampleCounts:
    """``k``, ``n_k`` and ``n^N_k`` of ``m`` models (forgetting ``f``; ``g = f_R`` weighs
    ``R_k(i)``, with a separate count only with a ``noise_model``) and their burn-in ``B``."""

    def __init__(self, m: int, forgetting: float, noise_forgetting: float, noise_model: bool, burn_in: int) -> None:
        self.k = 0
        self.n = 0.0  # n_k = sum_j f^(k-j)
        self.n_noise = 0.0  # n^N_k = sum_j f_R^(k-j) (0 without a noise model)
        self.f, self.g, self._noise_model = forgetting, noise_forgetting, noise_model
        self.B = burn_in
        self._active = burn_in > 0
        self._end: IntArray = np.full(m, _NEVER, dtype=np.int64)  # each model's last left-out sample k0 + B
        self.masking = self._active  # some model's lag window still reaches into its burn-in
        self._at: int | None = None  # the sample _after and _totals are of
        self._after: FloatArray | None = None
        self._totals: float | FloatArray = 0.0

    def add(self) -> None:
        """One more sample: ``k``, ``n_k = f n_(k-1) + 1`` and ``n^N_k = f_R n^N_(k-1) + 1``."""
        self.k += 1
        self.n = self.f * self.n + 1.0
        if self._noise_model:
            self.n_noise = self.g * self.n_noise + 1.0

    def restart(self, ready: BoolArray, ready_at: IntArray, cap: int) -> None:
        """The burn-in ends after a model initialized or a state was restored (``cap`` lags
        held at most)."""
        if self._active:
            self._end = np.where(ready, ready_at + self.B, _NEVER)
            self.masking = int((self.k - self._end).min()) < max(1, cap - 1)
            self._at = None

    def burn_in(self, w: int, cap: int) -> tuple[BoolArray, BoolArray]:
        """At this sample (``w`` lags held), called while :attr:`masking`: the models whose
        burn-in ended at the previous sample (their lag sums start afresh) and, per model and
        lag ``i``, the products whose partner ``v_(k-i)`` lies in the burn-in (``k - i <= k0 +
        B``: left out)."""
        after = self.k - self._end  # samples since the burn-in ended (<= 0: in it, the paper's Eq. 17)
        starts: BoolArray = after == 1
        left_out: BoolArray = (np.arange(w) >= after[:, None]) & (after[:, None] > 0)
        if int(after.min()) >= max(1, cap - 1):  # every start done, no window reaches back
            self.masking = False
        return starts, left_out

    def _samples_after(self) -> FloatArray | None:
        """Each model's samples after its burn-in (0 during it) as floats, or None while no
        model is past it (always with ``B = 0``); computed once per sample."""
        if not self._active:
            return None
        if self._at != self.k:
            after = self.k - self._end
            self._after = np.maximum(after, 0).astype(float) if int(after.max()) > 0 else None
            self._totals = self._weight_totals(self._after)
            self._at = self.k
        return self._after

    def weight_totals(self) -> float | FloatArray:
        """The weight total of each model's ``R_k(i)``: ``n^N_k`` (``n_k`` without a noise
        model) while no model is past its burn-in, one float; else per model ``sum_(j > k0+B)
        f_R^(k-j)``."""
        if not self._active:
            return self.n_noise if self._noise_model else self.n
        self._samples_after()
        return self._totals

    def _weight_totals(self, c: FloatArray | None) -> float | FloatArray:
        n = self.n_noise if self._noise_model else self.n
        if c is None:
            return n
        g = self.g
        burned = c if g == 1.0 else -np.expm1(c * math.log(g)) / (1.0 - g)  # sum_(j > k0+B) g^(k-j)
        totals: FloatArray = np.where(c > 0.0, burned, n)
        return totals

    def rule_samples(self) -> float | FloatArray:
        """The lag rule's sample count: ``k``, or under forgetting Kish's effective size
        ``(1 - g^k)(1 + g) / ((1 - g)(1 + g^k))`` of the weights ``g^(k-j)``; after a model's
        burn-in the same with ``k - k0 - B`` samples (one float while no model is past it)."""
        g, k = self.g, self.k
        if g == 1.0:
            n = float(k)
        else:
            gk = g**k
            n = (1.0 - gk) * (1.0 + g) / ((1.0 - g) * (1.0 + gk))
        c = self._samples_after()
        if c is None:
            return n
        if g == 1.0:
            burned = c
        else:
            gc = np.power(g, c)
            burned = (1.0 - gc) * (1.0 + g) / ((1.0 - g) * (1.0 + gc))
        counts: FloatArray = np.where(c > 0.0, burned, n)
        return counts

    # ------------------------------------------------------------------ state
    def counters(self) -> dict[str, Any]:
        """``k``, ``n_eff`` (``n_k``) and ``n_noise`` (``n^N_k``), as a state stores them."""
        return {"k": self.k, "n_eff": self.n, "n_noise": self.n_noise}

    def load(self, counters: Mapping[str, Any]) -> None:
        """Inverse of :meth:`counters`."""
        self.k, self.n, self.n_noise = int(counters["k"]), float(counters["n_eff"]), float(counters["n_noise"])
        self._at = None
