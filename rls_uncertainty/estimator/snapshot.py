"""The snapshot of an :class:`.bank.EstimatorBank`: its complete state as plain data
(:mod:`.state`), a bank rebuilt from one, and the layout a state of a configuration must have.

Persistence is apart from the estimation: :class:`BankSnapshot` is the bank's base and reads
and writes the parts the bank composes (:mod:`.bank`), nothing else. numpy only.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any, Self

import numpy as np

from .counts import SampleCounts
from .evaluation import Evaluation
from .initialization import ExactInitialization
from .iv_fit import IvFit
from .lag_storage import LagStorage
from .options import EstimatorOptions
from .rls_fit import RlsFit
from .state import pack, unpack

__all__ = ["BankSnapshot"]


class BankSnapshot:
    """:meth:`state`, :meth:`from_state` and :meth:`state_layout` of a bank of ``sizes`` and
    ``options`` whose parts are the attributes below."""

    sizes: tuple[int, ...]
    options: EstimatorOptions
    _counts: SampleCounts
    _lags: LagStorage
    _fit: RlsFit | IvFit
    _noise: RlsFit | None
    _init: ExactInitialization
    _eval: Evaluation

    def __init__(self, sizes: Sequence[int], options: EstimatorOptions | None = None) -> None:
        raise NotImplementedError  # the bank's constructor

    @property
    def n_window(self) -> int:
        raise NotImplementedError

    def _readiness_changed(self) -> None:
        raise NotImplementedError

    def state(self) -> dict[str, Any]:
        """A deep copy of the complete state (:mod:`.state`); :meth:`from_state` continues
        bit-identically."""
        counters = {**self._counts.counters(), "cap": self._lags.cap}
        arrays: dict[str, np.ndarray] = {**self._fit.arrays("")}
        if self._noise is not None:
            arrays.update(self._noise.arrays("noise_"))
        arrays.update(self._init.arrays(), **self._eval.arrays())
        arrays.update(self._lags.arrays(self.n_window))
        return pack(self.sizes, self.options, counters, arrays)

    @classmethod
    def from_state(cls, saved: Mapping[str, Any]) -> Self:
        """Rebuild an estimator bank from :meth:`state` (also after a save to disk)."""
        sizes, options, counters, arrays = unpack(saved)
        bank = cls(sizes, options)
        bank._restore(counters, arrays)
        return bank

    @classmethod
    def state_layout(
        cls, sizes: Sequence[int], options: EstimatorOptions, counters: Mapping[str, Any], waiting: bool
    ) -> dict[str, tuple[tuple[int, ...], np.dtype]]:
        """``{name: (shape, dtype)}`` of the arrays of :meth:`state` of a bank of ``sizes`` and
        ``options`` at ``counters`` (``waiting``: some model waits for initialization),
        without any data: what a state file must hold."""
        bank = cls(sizes, options)
        bank._lay_out(counters, waiting)
        return {name: (a.shape, a.dtype) for name, a in bank.state()["arrays"].items()}

    def _lay_out(self, counters: Mapping[str, Any], waiting: bool) -> None:
        self._counts.load(counters)
        cap = int(counters["cap"])
        self._lags.lay_out(cap, waiting, min(self._counts.k, cap))

    def _restore(self, counters: Mapping[str, Any], arrays: Mapping[str, Any]) -> None:
        """Load a state of this configuration, in place."""
        self._init.load(arrays)
        self._eval.load(arrays)
        self._fit.load(arrays, "")
        if self._noise is not None:
            self._noise.load(arrays, "noise_")
        self._lay_out(counters, waiting=not bool(self._init.ready.all()))
        self._lags.load(arrays, self.n_window)
        self._readiness_changed()
