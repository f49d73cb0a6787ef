"""Recursive least squares with a colored-residual parameter covariance.

Grauer & Morelli, "Parameter Uncertainty for Aircraft Aerodynamic Modeling using Recursive
Least Squares" (AIAA SciTech 2016), Eqs. 6-22. Every module of this package imports numpy
only.

* :mod:`.reference`: the equations as the paper writes them, and the definition of every
  option (forgetting, residual kinds, exact initialization, lag window); the test oracle.
* :mod:`.bank`: :class:`EstimatorBank`, the fast per-sample path for ``M`` models at once;
  :mod:`.recursive`: :class:`RecursiveEstimator`, a bank of one.
* :mod:`.lag_storage` (history and lag-indexed sums), :mod:`.initialization` (exact
  initialization), :mod:`.covariance` (Eqs. 13, 20, 22 from one computation),
  :mod:`.state` (``state()`` / ``from_state()``), :mod:`.batch` (Eqs. 6-14),
  :mod:`.lag_window` (Eq. 22 and the Bartlett window), :mod:`.options` (the choices).
"""

from ..errors import EstimatorNotReady, NonFiniteInput
from .bank import EstimatorBank
from .batch import batch_estimate
from .covariance import nearest_psd
from .lag_window import lag_weights
from .options import COVARIANCE_KINDS, RESIDUALS, WINDOWS, CovarianceKind, Residual, Window
from .recursive import RecursiveEstimator

__all__ = [
    "EstimatorBank",
    "RecursiveEstimator",
    "EstimatorNotReady",
    "NonFiniteInput",
    "batch_estimate",
    "lag_weights",
    "nearest_psd",
    "WINDOWS",
    "Window",
    "Residual",
    "CovarianceKind",
    "RESIDUALS",
    "COVARIANCE_KINDS",
]
