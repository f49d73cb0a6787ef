"""The complete state of a bank as plain data, and back (``state()`` / ``from_state()``).

A state is ``{"format", "config", "counters", "arrays"}``: the constructor arguments, the
sample counters and numpy arrays, nothing else (no pickle), so that it can be written to an
``.npz`` file. Restoring it and continuing gives bit-identically the same numbers as the
bank it was taken from. A state of another :data:`STATE_FORMAT` is refused by name.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import TYPE_CHECKING, Any

from .lag_storage import assign_checked

if TYPE_CHECKING:
    from .bank import EstimatorBank

__all__ = ["STATE_FORMAT", "capture", "restore"]

# 2: lagged moments as one array of y = (x, z) products; 3: Eq. 17 as sums, history windows
# only; 4: the package layout (lag_storage): Lambda+ of x alone once every model is
# initialized, the y products only while one waits, residuals with their sign, D and theta
# as separate arrays; 5: the noise model under forgetting (noise_forgetting; its dispersion,
# estimate and residual history u, the f-weighted lag-0 moments while a model waits) and
# n_lags="auto" with max_lags, min_lags; 6: residual_burn_in (with B > 0 the lag sums are
# those of the samples after each model's burn-in, whose end k0 + B follows from ready_at).
STATE_FORMAT = 6

_BANK_ARRAYS = ("_inv_s", "_ready", "_ready_at", "repairs")


def capture(bank: EstimatorBank) -> dict[str, Any]:
    """A deep copy of the complete state of ``bank``."""
    config = {
        "sizes": list(bank.sizes),
        "n_lags": bank.n_lags,
        "window": bank.window,
        "forgetting": bank.forgetting,
        "residual": bank.residual,
        "init_condition": bank.init_condition,
        "noise_forgetting": bank.noise_forgetting,
        "max_lags": bank.max_lags,
        "min_lags": bank.min_lags,
        "residual_burn_in": bank.residual_burn_in,
    }
    counters = {"k": bank.k, "n_eff": bank.n_eff, "n_noise": bank.n_noise, "cap": bank._lags.cap}
    n = bank.n_max
    arrays = {"dispersion": bank._aug[:, :n].copy(), "theta": bank._aug[:, n].copy()}
    if bank._noise:
        arrays.update(noise_dispersion=bank._naug[:, :n].copy(), noise_theta=bank._naug[:, n].copy())
    arrays.update({name.lstrip("_"): getattr(bank, name).copy() for name in _BANK_ARRAYS})
    arrays.update(bank._lags.arrays(bank.n_window))
    return {"format": STATE_FORMAT, "config": config, "counters": counters, "arrays": arrays}


def check_format(state: Mapping[str, Any]) -> None:
    if state.get("format") != STATE_FORMAT:
        raise ValueError(
            f"unknown estimator state format {state.get('format')!r} "
            f"(this version reads format {STATE_FORMAT})"
        )


def restore(bank: EstimatorBank, state: Mapping[str, Any]) -> None:
    """Load ``state`` into ``bank`` (built with the same configuration), in place."""
    check_format(state)
    c = state["counters"]
    arrays = state["arrays"]
    bank.k, bank.n_eff, bank.n_noise = int(c["k"]), float(c["n_eff"]), float(c["n_noise"])
    for name in _BANK_ARRAYS:
        assign_checked(getattr(bank, name), arrays[name.lstrip("_")], name.lstrip("_"))
    n = bank.n_max
    assign_checked(bank._aug[:, :n], arrays["dispersion"], "dispersion")
    assign_checked(bank._aug[:, n], arrays["theta"], "theta")
    if bank._noise:
        assign_checked(bank._naug[:, :n], arrays["noise_dispersion"], "noise_dispersion")
        assign_checked(bank._naug[:, n], arrays["noise_theta"], "noise_theta")
    lags = bank._lags
    lags.waiting = not bool(bank._ready.all())
    lags.allocate(int(c["cap"]))
    lags.load(arrays, bank.n_window)
    if lags.ptr == 0:  # a full buffer (all lags): the next sample needs a free slot
        lags.grow(bank.n_window)
    bank._readiness_changed()
