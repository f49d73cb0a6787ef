"""What one estimator sample produced: :class:`SampleOutput` (numpy only)."""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from .frequency_path import FrequencyOutput

__all__ = ["SampleOutput"]


class SampleOutput(NamedTuple):
    """What one estimator sample produced.

    ``theta``, ``se`` (corrected, Eqs. 20/22) and ``se_conventional`` (Eq. 13) are
    ``(M, n_max)`` arrays in the order of ``config.models``; rows of models that are not
    ``ready`` yet (exact initialization still waiting) and the padding are NaN. ``ready`` is
    false too for a model whose estimates or standard errors are not all finite (withheld,
    counted in ``outputs_withheld``): a ready row is safe to publish (:mod:`.outputs`).
    ``converged`` ``(M, n_max)`` and ``model_converged`` ``(M,)`` are the
    :class:`.convergence.ConvergenceMonitor` flags (False on padding and models not ready; a
    model is converged when all its parameters are). ``covariance`` is ``None``, or on the
    samples whose grid index is a multiple of ``outputs.covariance_decimation`` the
    ``(2, M, n_max, n_max)`` corrected (``[0]``) and conventional (``[1]``) covariances
    (:meth:`.estimator.EstimatorBank.covariance`: a corrected one with a negative variance
    repaired to its nearest positive semi-definite matrix, zero for an exact fit; symmetrized),
    NaN off the ready models' parameters.
    ``lags`` ``(M,)`` ints: the largest lag of Eq. 22 behind each corrected SE (chosen per
    sample with ``estimator.lag_selection: auto``), 0 for models not ready. ``frequency``: with
    ``estimator.method`` ``frequency`` or ``both``, on the samples where the frequency-domain
    estimator publishes, its :class:`.frequency_path.FrequencyOutput`; else None.
    """

    stamp_ns: int
    index: int  # type: ignore[assignment]  # shadows tuple.index; the field name is the API
    theta: np.ndarray
    se: np.ndarray
    se_conventional: np.ndarray
    ready: np.ndarray
    converged: np.ndarray
    model_converged: np.ndarray
    covariance: np.ndarray | None = None
    lags: np.ndarray | None = None
    frequency: FrequencyOutput | None = None

    @property
    def time(self) -> float:
        return self.stamp_ns * 1e-9
