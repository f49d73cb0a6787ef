"""The complete state of a bank as plain data (``EstimatorBank.state()`` / ``from_state()``).

A state is ``{"format", "sizes", "options", "counters", "arrays"}``: the model sizes, the
options (:meth:`.options.EstimatorOptions.as_dict`), the sample counters and numpy arrays,
nothing else (no pickle), so that it can be written to an ``.npz`` file. Restoring it and
continuing gives bit-identically the same numbers as the bank it was taken from. A state of
another :data:`STATE_FORMAT` is refused by name.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from ..errors import ConfigError
from .options import EstimatorOptions

__all__ = ["STATE_FORMAT", "COUNTERS", "pack", "unpack"]

# 2: lagged moments as one array of y = (x, z) products; 3: Eq. 17 as sums, history windows
# only; 4: the package layout (lag_storage): Lambda+ of x alone once every model is
# initialized, the y products only while one waits, residuals with their sign, D and theta
# as separate arrays; 5: the noise model under forgetting (its dispersion, estimate and
# residual history u, the f-weighted lag-0 moments while a model waits) and automatic lags;
# 6: the residual burn-in (its end k0 + B follows from ready_at); 7: the options as one
# object (EstimatorOptions.as_dict: lags "all" / "auto" / an integer, p0 stored).
STATE_FORMAT = 7

COUNTERS = ("k", "n_eff", "n_noise", "cap")


def pack(
    sizes: tuple[int, ...], options: EstimatorOptions, counters: Mapping[str, Any], arrays: dict[str, np.ndarray]
) -> dict[str, Any]:
    """A state of the current format from its parts."""
    return {"format": STATE_FORMAT, "sizes": list(sizes), "options": options.as_dict(),
            "counters": dict(counters), "arrays": arrays}


def unpack(state: Mapping[str, Any]) -> tuple[tuple[int, ...], EstimatorOptions, dict[str, Any], Mapping[str, Any]]:
    """``(sizes, options, counters, arrays)`` of a state; one of another format is refused
    (:class:`ValueError`), and so are invalid options (:class:`.errors.ConfigError`)."""
    if state.get("format") != STATE_FORMAT:
        raise ValueError(
            f"unknown estimator state format {state.get('format')!r} (this version reads format {STATE_FORMAT})"
        )
    options = EstimatorOptions.from_dict(state["options"])
    counters = {name: state["counters"][name] for name in COUNTERS}
    sizes = tuple(int(s) for s in state["sizes"])
    if not sizes or min(sizes) < 1:
        raise ConfigError(f"estimator state sizes must be positive parameter counts, got {list(sizes)}")
    return sizes, options, counters, state["arrays"]
