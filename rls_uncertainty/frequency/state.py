"""A :class:`.bank.FrequencyBank`'s record as plain data, so that a resumed estimator continues
it (the state file, :mod:`rls_uncertainty.state_file`; numpy only).

The record is what the estimates are computed from (docs/frequency.md): the recursive Fourier
transforms of every signal with the first sample subtracted (Eq. F2), that first sample, the
sum of the samples of the trim (F1), the augmented lag-product sums and the window of the last
samples (F9), with instruments the sums ``sum w (u, 1)'`` (F11), and the sample count ``n``,
which is the transforms' clock; and the results of the last evaluation (F4-F12: estimates,
both covariances and standard errors, the residual autocovariance, the output variance, which
models were ready, solved and withheld), which a bank answers with until its next evaluation
(with ``frequency.every > 1`` they belong to an earlier sample than the record).

:func:`snapshot` returns ``counters`` (``n``, ``evaluated_at``, ``repairs`` and ``due``: whether
the next request evaluates) and ``arrays`` named as the state file stores them (``fq_``
prefixed); :func:`restore` continues from them bit-identically; :func:`layout` gives the
arrays' shapes and dtypes, which the state file checks before reading any.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:  # annotations only
    from .bank import FrequencyBank

__all__ = ["snapshot", "restore", "layout", "PREFIX", "RESULTS"]

PREFIX = "fq_"  # the state file's names of the record's arrays
# The last evaluation's results (NaN where a bank has none): the others are the record.
RESULTS = tuple(PREFIX + k for k in ("theta", "cov", "se", "published_se", "R", "output_variance", "flags"))


def snapshot(bank: FrequencyBank) -> dict[str, Any]:
    """The record of ``bank`` as plain data (module docstring), copies."""
    lags, first = bank._lags, bank._first
    arrays = {
        "transform": bank._transform.values,
        "first": np.zeros_like(bank._trim_sum) if first is None else first.copy(),
        "trim_sum": bank._trim_sum.copy(),
        "lag_sums": lags.sums,
        "lag_buffer": lags.buffer,
    }
    if bank._cross is not None:
        arrays["cross"] = bank._cross.copy()
    arrays |= {"theta": bank._theta.copy(), "cov": bank._cov.copy(), "se": bank._se.copy(),
               "published_se": bank._published_se.copy(), "R": bank._R.copy(),
               "output_variance": bank._output_variance.copy(),
               "flags": np.stack([bank._ready, bank._solved, bank._withheld])}  # (3, M)
    counters = {"n": int(lags.n), "evaluated_at": int(bank._evaluated_at), "repairs": int(bank.repairs),
                "due": bool(bank._due)}
    return {"counters": counters, "arrays": {PREFIX + k: v for k, v in arrays.items()}}


def layout(bank: FrequencyBank, evaluated_at: int) -> dict[str, tuple[tuple[int, ...], np.dtype]]:
    """``{name: (shape, dtype)}`` of :func:`snapshot`'s arrays for a bank like ``bank`` (its
    sizes, options and instruments) last evaluated at sample ``evaluated_at`` (the lags of the
    residual autocovariance: ``min(n_lags + 1, evaluated_at)``, 1 before an evaluation)."""
    out = {name: (a.shape, a.dtype) for name, a in snapshot(bank)["arrays"].items()}
    lags = min(bank.options.n_lags + 1, evaluated_at) if evaluated_at else 1
    out[PREFIX + "R"] = ((len(bank.sizes), lags), np.dtype(np.float64))
    return out


def restore(bank: FrequencyBank, saved: Mapping[str, Any]) -> None:
    """Continue ``bank`` (fresh, of the saved bank's sizes, options and instruments) from
    :func:`snapshot`. Its checks are the state file's; here only the shapes and counters
    (:class:`ValueError`)."""
    c = saved["counters"]
    n, evaluated_at, repairs, due = int(c["n"]), int(c["evaluated_at"]), int(c["repairs"]), bool(c["due"])
    if not 0 <= evaluated_at <= n or repairs < 0 or (due and (n == 0 or evaluated_at == n)):
        raise ValueError(f"saved frequency counters out of range: {dict(c)}")
    want = layout(bank, evaluated_at)
    arrays = dict(saved["arrays"])
    if set(arrays) != set(want):
        raise ValueError(f"saved frequency record has arrays {sorted(arrays)}, expected {sorted(want)}")
    for name, (shape, dtype) in want.items():
        if np.shape(arrays[name]) != shape:
            raise ValueError(f"saved {name} has shape {np.shape(arrays[name])}, expected {shape}")
        arrays[name] = np.array(arrays[name], dtype=dtype)
    bank.reset()
    a = {k[len(PREFIX):]: v for k, v in arrays.items()}
    bank._transform.values = a["transform"]
    bank._transform.n = n
    bank._lags.sums = a["lag_sums"]
    bank._lags.buffer = a["lag_buffer"]
    bank._lags.n = n
    bank._trim_sum[...] = a["trim_sum"]
    bank._first = a["first"] if n else None
    if bank._cross is not None:
        bank._cross[...] = a["cross"]
    bank._theta, bank._cov, bank._se = a["theta"], a["cov"], a["se"]
    bank._published_se, bank._R, bank._output_variance = a["published_se"], a["R"], a["output_variance"]
    bank._ready, bank._solved, bank._withheld = (flag.copy() for flag in a["flags"])
    bank._evaluated_at, bank._due, bank.repairs = evaluated_at, due, repairs
