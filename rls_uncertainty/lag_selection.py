"""Automatic lag selection: moved to :mod:`rls_uncertainty.estimator.lag_selection` (the
estimator's ``n_lags="auto"`` uses it, and the estimator package imports numpy only)."""

from .estimator.lag_selection import *  # noqa: F403
from .estimator.lag_selection import __all__  # noqa: F401
