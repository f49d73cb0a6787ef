"""The estimator state file: a restarted node resumes the estimation where it stopped.

One ``.npz`` archive (numpy only, no pickle): the :meth:`.EstimatorBank.state`
arrays, plus a ``meta`` entry holding one JSON text with

* ``format``: :attr:`EstimatorBank.STATE_FORMAT` (a file of another layout is refused by name);
* ``fingerprint``: what the state must match to be resumed (aircraft, models, rate and the
  estimator settings; :meth:`rls_uncertainty.config.PipelineConfig.fingerprint`);
* ``bank_config``, ``bank_counters``: the rest of the bank's state;
* ``samples_used``, ``zsum``, ``zsq``: the samples behind the estimates and the running sums
  of each model's output and its square (the R^2 of the model fit).

It is written with :func:`rls_uncertainty.files.atomic_file`, so a crash never leaves half a file.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import StateFileError
from ..files import atomic_file
from .bank import EstimatorBank

__all__ = ["EstimatorState", "save_state", "load_state", "StateFileError"]


@dataclass
class EstimatorState:
    """What a state file holds: the estimator bank, the samples it has used, and the sums of
    each model's output ``z`` and ``z^2`` over them (one entry per model)."""

    bank: EstimatorBank
    samples_used: int
    output_sum: np.ndarray
    output_sum_squares: np.ndarray


def save_state(path: str | Path, state: EstimatorState, fingerprint: dict) -> None:
    """Write ``state`` (atomically) with the configuration ``fingerprint`` it belongs to."""
    bank = state.bank.state()
    meta = {
        "format": EstimatorBank.STATE_FORMAT,
        "fingerprint": fingerprint,
        "bank_config": bank["config"],
        "bank_counters": bank["counters"],
        "samples_used": int(state.samples_used),
        "zsum": np.asarray(state.output_sum, dtype=float).tolist(),
        "zsq": np.asarray(state.output_sum_squares, dtype=float).tolist(),
    }
    with atomic_file(Path(path)) as fh:
        np.savez(fh, meta=np.array(json.dumps(meta)), **bank["arrays"])


def load_state(path: str | Path, fingerprint: dict) -> EstimatorState:
    """The state saved in ``path``. Raises :class:`StateFileError` when the file is missing,
    unreadable, of another format, or saved with another configuration than ``fingerprint``."""
    path = Path(path)
    try:
        with np.load(path, allow_pickle=False) as data:
            meta = json.loads(str(data["meta"]))
            arrays = {k: data[k] for k in data.files if k != "meta"}
    except FileNotFoundError as exc:
        raise StateFileError(f"{path}: no such state file") from exc
    except Exception as exc:  # noqa: BLE001 - any corruption is reported the same way
        raise StateFileError(f"{path}: not a readable state file ({exc})") from exc
    if not isinstance(meta, dict) or meta.get("format") != EstimatorBank.STATE_FORMAT:
        found = meta.get("format") if isinstance(meta, dict) else None
        raise StateFileError(
            f"{path}: state format {found!r}, this version reads "
            f"{EstimatorBank.STATE_FORMAT} (saved by another version; delete it to start afresh)"
        )
    # Compare as JSON would store it (tuples become lists).
    if meta.get("fingerprint") != json.loads(json.dumps(fingerprint)):
        raise StateFileError(f"{path}: saved with another aircraft, model or estimator configuration")
    try:
        bank = EstimatorBank.from_state(
            {
                "format": EstimatorBank.STATE_FORMAT,
                "config": meta["bank_config"],
                "counters": meta["bank_counters"],
                "arrays": arrays,
            }
        )
        m = bank.n_models
        state = EstimatorState(
            bank=bank,
            samples_used=int(meta["samples_used"]),
            output_sum=np.array(meta["zsum"], dtype=float),
            output_sum_squares=np.array(meta["zsq"], dtype=float),
        )
        if state.output_sum.shape != (m,) or state.output_sum_squares.shape != (m,):
            raise ValueError(f"output sums of {m} models expected")
    except (KeyError, TypeError, ValueError) as exc:
        raise StateFileError(f"{path}: inconsistent estimator state ({exc})") from exc
    return state
