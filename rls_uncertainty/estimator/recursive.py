"""One recursive least-squares model: a bank of one (:class:`.bank.EstimatorBank`)."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
import numpy.typing as npt

from .bank import EstimatorBank
from .options import EstimatorOptions

__all__ = ["RecursiveEstimator"]


class RecursiveEstimator:
    """Recursive least squares for one model, with corrected and conventional covariances.

    ``RecursiveEstimator(n_params, options)`` with :class:`.options.EstimatorOptions` (default
    ``EstimatorOptions()``), as :class:`EstimatorBank`. ``update(x, z)`` processes one sample.
    """

    def __init__(self, n_params: int, options: EstimatorOptions | None = None) -> None:
        self._bank = EstimatorBank((int(n_params),), options)

    @classmethod
    def _wrap(cls, bank: EstimatorBank) -> RecursiveEstimator:
        est = cls.__new__(cls)
        est._bank = bank
        return est

    def update(self, x: npt.ArrayLike, z: float, instruments: npt.ArrayLike | None = None) -> None:
        """Eq. 15-17, 21 for one sample (``instruments``, one per parameter, with the option
        ``algorithm="iv"`` only); non-finite input raises :class:`NonFiniteInput`."""
        x = np.asarray(x, dtype=float).reshape(1, -1)
        if x.shape[1] != self._bank.n_max:
            raise ValueError(f"expected {self._bank.n_max} regressors, got {x.shape[1]}")
        zeta = None if instruments is None else np.asarray(instruments, dtype=float).reshape(1, -1)
        self._bank.update(x, np.asarray([z], dtype=float).reshape(1), zeta)

    @property
    def n_params(self) -> int:
        return self._bank.n_max

    @property
    def options(self) -> EstimatorOptions:
        return self._bank.options

    @property
    def bank(self) -> EstimatorBank:
        """The bank of one behind this estimator (its per-model results, :attr:`EstimatorBank.n_R` ...)."""
        return self._bank

    @property
    def lags_used(self) -> int:
        """The largest lag of Eq. 22 used at this sample (chosen with ``lags="auto"``)."""
        return int(self._bank.lags_used[0])

    @property
    def n_samples(self) -> int:
        return self._bank.k

    @property
    def is_ready(self) -> bool:
        return bool(self._bank.ready[0])

    @property
    def theta(self) -> np.ndarray:
        return self._bank.theta(0)

    @property
    def repairs(self) -> int:
        """How many evaluated corrected covariances needed a positive semi-definite repair."""
        return int(self._bank.repairs[0])

    @property
    def residual_variance(self) -> float:
        return self._bank.residual_variance(0)

    def autocorrelation(self) -> np.ndarray:
        return self._bank.autocorrelation(0)

    def residuals(self) -> np.ndarray:
        return self._bank.residuals(0)

    def noise_residuals(self) -> np.ndarray:
        return self._bank.noise_residuals(0)

    def covariance(self, kind: str = "corrected", *, repair: bool = True) -> np.ndarray:
        return self._bank.covariance(0, kind, repair=repair)

    def standard_errors(self, kind: str = "corrected") -> np.ndarray:
        return self._bank.standard_errors(0, kind)

    def state(self) -> dict[str, Any]:
        return self._bank.state()

    @classmethod
    def from_state(cls, state: Mapping[str, Any]) -> RecursiveEstimator:
        if len(state["sizes"]) != 1:
            raise ValueError("state holds several models: use EstimatorBank.from_state")
        return cls._wrap(EstimatorBank.from_state(state))
