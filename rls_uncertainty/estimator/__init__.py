"""Recursive least squares with a colored-residual parameter covariance.

Grauer & Morelli, "Parameter Uncertainty for Aircraft Aerodynamic Modeling using Recursive
Least Squares" (AIAA SciTech 2016), Eqs. 6-22. Every module of this package imports numpy
only (and the package's ``errors``).

* :mod:`.options`: :class:`EstimatorOptions`, every option, validated once.
* :mod:`.reference`: the equations as the paper writes them, and the definition of every
  option (forgetting and the noise model, residual kinds, exact initialization, the lag
  window, automatic lags, the residual burn-in); the test oracle.
* :mod:`.bank`: :class:`EstimatorBank`, the fast per-sample path for ``M`` models at once,
  built from parts that each own their arrays: :mod:`.rls_fit` (Eqs. 15-16),
  :mod:`.counts` (the sample counts and the residual burn-in), :mod:`.lag_storage` (Eqs. 17,
  21), :mod:`.initialization` (Eqs. 6, 7, 10), :mod:`.evaluation` and :mod:`.covariance`
  (Eqs. 13, 20, 22) with :mod:`.lag_window` and :mod:`.lag_selection` (the flat-top rule),
  and :mod:`.state` (the state as plain data and the checks of a saved one);
  :mod:`.recursive`: :class:`RecursiveEstimator`, a bank of one; :mod:`.batch`: Eqs. 6-14.
  The node's state file, which reads and writes :mod:`.state`, is
  :mod:`rls_uncertainty.state_file`, outside the core.

The options table, the theory behind the options and the figures of the studies behind their
defaults: ``docs/estimator.md``.
"""

from ..errors import EstimatorNotReady, NonFiniteInput
from .bank import EstimatorBank
from .batch import batch_estimate
from .covariance import nearest_psd
from .lag_window import lag_weights
from .options import COVARIANCE_KINDS, RESIDUALS, WINDOWS, CovarianceKind, EstimatorOptions, Lags, Residual, Window
from .recursive import RecursiveEstimator

__all__ = [
    "EstimatorBank",
    "EstimatorOptions",
    "Lags",
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
