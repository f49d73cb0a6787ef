"""The estimator's choices, defined once, and their validation.

Configuration, ROS parameters and the command line read the choices from here; the fast
bank (:mod:`.bank`) and the executable specification (:mod:`.reference`) validate their
arguments with the same function, so both accept exactly the same options.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Literal, TypeGuard, get_args

import numpy as np

__all__ = [
    "Window",
    "Residual",
    "CovarianceKind",
    "WINDOWS",
    "RESIDUALS",
    "COVARIANCE_KINDS",
    "check_window",
    "check_kind",
    "check_options",
    "AUTO",
    "check_noise_forgetting",
    "default_noise_forgetting",
    "NOISE_MEMORY_LAGS",
    "prior_diagonal",
    "AUTO_BURN_IN",
    "MAX_BURN_IN",
    "check_burn_in",
]

# Default memory of the noise model under forgetting, in units of n_lags + 1 samples.
NOISE_MEMORY_LAGS = 40.0
# residual_burn_in: the default with n_lags="auto" (0, the paper, otherwise) and the largest
# value accepted (samples).
AUTO_BURN_IN = 50
MAX_BURN_IN = 100_000

Window = Literal["truncated", "bartlett"]
Residual = Literal["standardized", "a_posteriori", "a_priori"]
CovarianceKind = Literal["corrected", "conventional"]
WINDOWS: tuple[Window, ...] = get_args(Window)
RESIDUALS: tuple[Residual, ...] = get_args(Residual)
COVARIANCE_KINDS: tuple[CovarianceKind, ...] = get_args(CovarianceKind)


def check_window(window: str) -> None:
    if window not in WINDOWS:
        raise ValueError(f"window must be one of {WINDOWS}, got {window!r}")


def check_kind(kind: str) -> None:
    if kind not in COVARIANCE_KINDS:
        raise ValueError(f"kind must be one of {COVARIANCE_KINDS}, got {kind!r}")


def _is_count(value: object) -> TypeGuard[int | np.integer | float]:
    return not isinstance(value, (bool, str)) and isinstance(value, (int, np.integer, float)) and int(value) == value

AUTO = "auto"  # n_lags chosen from the data (lag_selection.flat_top_lags)


def check_options(
    n_lags: int | str | None, window: str, forgetting: float, residual: str, init_condition: float,
    *, max_lags: int = 50, min_lags: int = 0,
) -> None:
    """Refuse an invalid configuration with a message that names the option."""
    if n_lags == AUTO:
        if not (_is_count(max_lags) and max_lags >= 1):
            raise ValueError(f"max_lags must be an integer >= 1, got {max_lags!r}")
        if not (_is_count(min_lags) and 0 <= min_lags <= max_lags):
            raise ValueError(f"min_lags must be an integer in [0, max_lags = {max_lags}], got {min_lags!r}")
        if window != "truncated":
            raise ValueError(
                f"n_lags='auto' needs window='truncated', got {window!r}: the flat-top rule chooses a "
                "truncation point, and the Bartlett taper cannot let the anti-correlated lags of "
                "differentiated noise cancel (validation/auto_lags/REPORT.md)"
            )
    elif n_lags is not None and not (_is_count(n_lags) and n_lags >= 0):
        raise ValueError(f"n_lags must be None, 'auto' or an integer >= 0, got {n_lags!r}")
    check_window(window)
    if not (0.0 < float(forgetting) <= 1.0):
        raise ValueError(f"forgetting must be in (0, 1], got {forgetting!r}")
    if residual not in RESIDUALS:
        raise ValueError(f"residual must be one of {RESIDUALS}, got {residual!r}")
    if not float(init_condition) > 1.0:
        raise ValueError(f"init_condition must be > 1, got {init_condition!r}")


def default_noise_forgetting(forgetting: float, n_lags: int | None) -> float:
    """The default ``f_R`` of the noise model: ``max(f, 1 - 1/(NOISE_MEMORY_LAGS (n_lags + 1)))``,
    ``f`` itself when ``f = 1`` or all lags are kept (``n_lags=None``).

    The noise autocovariance is then averaged over ``40 (n_lags + 1)`` samples (2040 for 50
    lags, ``f_R = 0.99951``): the noise model's own fit absorbs about ``1/40`` of the lag sum
    (2.5 % in variance), and the relative spread of the lag sum is about ``sqrt(2/40)``."""
    f = float(forgetting)
    if f == 1.0 or n_lags is None:
        return f
    return max(f, 1.0 - 1.0 / (NOISE_MEMORY_LAGS * (int(n_lags) + 1)))


def check_noise_forgetting(noise_forgetting: float | None, forgetting: float, n_lags: int | None) -> float:
    """``f_R`` for the option ``noise_forgetting`` (``None``: :func:`default_noise_forgetting`),
    refused unless ``forgetting <= f_R <= 1``."""
    if noise_forgetting is None:
        return default_noise_forgetting(forgetting, n_lags)
    g = float(noise_forgetting)
    if not (float(forgetting) <= g <= 1.0):
        raise ValueError(
            f"noise_forgetting must be None or in [forgetting, 1] = [{forgetting}, 1], got {noise_forgetting!r}"
        )
    return g


def check_burn_in(residual_burn_in: int | None, n_lags: int | str | None) -> int:
    """The residual burn-in ``B`` for the option ``residual_burn_in`` (samples after a model's
    initialization whose residuals are left out of ``R_k(i)``; see :mod:`.reference`):
    ``None`` takes :data:`AUTO_BURN_IN` (50) with ``n_lags="auto"`` and 0 (the paper's Eq. 17)
    otherwise; an integer must lie in ``[0, MAX_BURN_IN]``."""
    if residual_burn_in is None:
        return AUTO_BURN_IN if n_lags == AUTO else 0
    if not (_is_count(residual_burn_in) and 0 <= residual_burn_in <= MAX_BURN_IN):
        raise ValueError(
            f"residual_burn_in must be None (the default: {AUTO_BURN_IN} with n_lags='auto', 0 otherwise) "
            f"or an integer in [0, {MAX_BURN_IN}], got {residual_burn_in!r}"
        )
    return int(residual_burn_in)


def prior_diagonal(p0: float | Sequence[float], n: int) -> np.ndarray:
    """The diagonal of the prior dispersion ``D_0 = diag(p0)`` for ``n`` parameters."""
    p = np.asarray(p0, dtype=float)
    p = np.full(n, float(p)) if p.ndim == 0 else p.reshape(-1)
    if p.shape != (n,):
        raise ValueError(f"p0 must be a scalar or have {n} entries, got {p.shape}")
    if not np.all(np.isfinite(p)) or np.any(p <= 0):
        raise ValueError(f"p0 must be positive and finite, got {p0!r}")
    return p
