"""Instruments from the measured surfaces and the delayed regressors, for any model.

When no excitation is recorded (and for models the short-period auxiliary model does not
serve: the lateral-directional Eq. 2b, 2d, 2f), each regression row ``x_k`` is instrumented by

    regressor   1     delta_e, delta_a, delta_r       any other (alpha, beta, p_hat, ...)
    instrument  1     the same, as measured at k       the same regressor at k - d        (I3)

with ``d`` samples of delay (``instruments.delay_span``). The surfaces are the inputs: they are
not driven by the equation error in open loop, so they instrument themselves. A state
regressor delayed by more samples than the equation error stays correlated is uncorrelated with
the sensor noise and the gusts of row ``k`` but still moves with the state through the
aircraft's dynamics (Soderstrom and Stoica's delayed-regressor instruments). The choice of
``d`` is a trade: shorter than the residual's correlation the instruments keep part of the
bias; much longer than the motion's period they become weak (:mod:`.strength` says when).

A row whose sample ``d`` periods earlier was not seen (the first ``d`` rows, and after a gap in
the stamps) gets no instruments: it is dropped and counted (:attr:`DelayedRegressors.dropped`).
"""

from __future__ import annotations

from collections import deque
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
import numpy.typing as npt

from ..aero.models import BIAS_REGRESSOR, ModelConfig
from ..aero.surface_mixing import SURFACES
from ..errors import ConfigError, NonFiniteInput
from .auxiliary import InstrumentedSample
from .bootstrap import saved_array

__all__ = ["DelayedRegressors"]

FloatArray = npt.NDArray[np.float64]


class DelayedRegressors:
    """I3 for ``models`` in the bank's ``(M, n_max)`` layout: ``delay`` samples of ``period_ns``
    nanoseconds each (rows are stamped on that grid)."""

    def __init__(self, models: Sequence[ModelConfig], delay: int, period_ns: int) -> None:
        if not models:
            raise ConfigError("estimator.algorithm: iv needs at least one model", parameter="estimator.algorithm")
        if delay < 1 or period_ns < 1:
            raise ConfigError(f"instruments.delay_span: the delay must be at least one sample, got {delay} of "
                              f"{period_ns} ns", parameter="instruments.delay_span")
        self.sizes = tuple(len(m.regressors) for m in models)
        m, n = len(self.sizes), max(self.sizes)
        self.mask = np.zeros((m, n), dtype=bool)
        self.delayed = np.zeros((m, n), dtype=bool)
        for j, model in enumerate(models):
            self.mask[j, : self.sizes[j]] = True
            for i, r in enumerate(model.regressors):
                self.delayed[j, i] = r != BIAS_REGRESSOR and r not in SURFACES
        self.delay = int(delay)
        self.span_ns = int(delay) * int(period_ns)
        self._history: deque[tuple[int, FloatArray]] = deque()
        self.dropped = 0

    @property
    def waiting(self) -> int:
        """Rows held back for later instruments: none (a row has its instruments at once or never)."""
        return 0

    def reset(self) -> None:
        """Forget the rows seen; the counter stays."""
        self._history.clear()

    def update(self, X: npt.ArrayLike, z: npt.ArrayLike, stamp_ns: int) -> list[InstrumentedSample]:
        """Row ``X`` ``(M, n_max)`` with outputs ``z`` stamped ``stamp_ns``: ``[]`` (dropped:
        no row ``delay`` samples earlier) or the row with its instruments (tag: the stamp).
        A non-finite row raises :class:`NonFiniteInput` and is not kept."""
        x = np.where(self.mask, np.asarray(X, dtype=float), 0.0)
        zz = np.array(z, dtype=float).reshape(-1)
        if zz.shape != (len(self.sizes),):
            raise ValueError(f"expected {len(self.sizes)} measured outputs, got shape {zz.shape}")
        if not (np.isfinite(x).all() and np.isfinite(zz).all()):
            raise NonFiniteInput("instruments: a regressor or output is not finite; the sample is refused")
        t = int(stamp_ns)
        history = self._history
        if history and history[-1][0] >= t:  # stamps went back: start again
            history.clear()
        history.append((t, x))
        target = t - self.span_ns
        while history[0][0] < target:
            history.popleft()
        if history[0][0] != target:
            self.dropped += 1
            return []
        zeta = np.where(self.delayed, history[0][1], x)
        return [InstrumentedSample(x, zz, zeta, t)]

    def snapshot(self) -> dict[str, Any]:
        """A copy of the state as plain data (``counters``: ``dropped``, ``history`` (rows
        kept); ``arrays``: ``history_X`` ``(history, M, n_max)`` and ``history_stamp`` (ns,
        int64), oldest first); :meth:`restore` continues bit-identically."""
        m, n = self.mask.shape
        rows = list(self._history)
        return {"counters": {"dropped": self.dropped, "history": len(rows)},
                "arrays": {"history_X": np.array([x for _, x in rows], dtype=float).reshape(len(rows), m, n),
                           "history_stamp": np.array([t for t, _ in rows], dtype=np.int64)}}

    def restore(self, saved: Mapping[str, Any]) -> None:
        """Continue from :meth:`snapshot` (arrays of another shape: :class:`ValueError`)."""
        rows = int(saved["counters"]["history"])
        X = saved_array(saved["arrays"]["history_X"], np.zeros((rows, *self.mask.shape)), "history_X")
        stamps = np.asarray(saved["arrays"]["history_stamp"], dtype=np.int64)
        if stamps.shape != (rows,):
            raise ValueError(f"saved history_stamp has shape {stamps.shape}, expected {(rows,)}")
        self._history = deque((int(t), x) for t, x in zip(stamps, X, strict=True))
        self.dropped = int(saved["counters"]["dropped"])
