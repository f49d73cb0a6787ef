"""``models.json``: the identified models at the end of a run, for ``rls-uncertainty predict``.

``replay`` and ``campaign`` write it beside their other outputs. Per maneuver (a replay is one
maneuver, named after its bag, or with ``maneuvers.source`` on one entry per maneuver
recorded; a campaign has one entry per maneuver, in order, a recording's cut as the replay
cuts it), per model that published time-domain estimates at its last sample
(:mod:`..datapath.fitted`):

* ``model``, ``regressors`` and ``parameters`` (names, in the order of the configuration);
* ``estimate``: the final estimates (the recursive estimates of Eqs. 15-16 at the last sample);
* ``covariance``: their corrected covariance (Eq. 20 with all lags, Eq. 22 with the configured
  window; repaired to the nearest positive semi-definite matrix when needed, as published),
  and ``covariance_conventional`` (Eq. 13);
* ``residual_variance``: the fit-error variance ``R(0)`` (Eq. 16) and ``samples`` the samples
  the estimator used.

:func:`run_models` takes them out of a pipeline; :func:`read_models` reads
the file back, refusing, in one line, a file that is not one, a value that is not a finite number
(text and ``true`` are not numbers), a covariance that is not symmetric or has a negative
variance, a ``samples`` that is not a whole number >= 1, or a model given twice in a maneuver.
"""

from __future__ import annotations

import json
import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from ..datapath.fitted import FittedModel, run_models
from ..errors import ConfigError

__all__ = ["FittedModel", "MODELS_FILE", "MODELS_FORMAT", "run_models", "models_json", "read_models"]

MODELS_FILE = "models.json"
MODELS_FORMAT = "rls_uncertainty models 1"


def models_json(maneuvers: Sequence[tuple[str, Sequence[FittedModel]]]) -> str:
    """The text of ``models.json`` of ``(maneuver, models)`` pairs."""
    doc = {"format": MODELS_FORMAT,
           "maneuvers": [{"name": name, "models": [m.as_json() for m in models]} for name, models in maneuvers]}
    return json.dumps(doc, indent=1) + "\n"


def _numbers(value: Any, depth: int) -> bool:
    """Whether ``value`` is a number (not a bool, not text) or, ``depth`` deep, lists of them."""
    if depth == 0:
        return isinstance(value, (int, float)) and not isinstance(value, bool)
    return isinstance(value, list) and all(_numbers(v, depth - 1) for v in value)


def _array(value: Any, shape: tuple[int, ...], where: str) -> np.ndarray:
    if not _numbers(value, len(shape)):
        raise ConfigError(f"{where}: not numbers (expected a {'x'.join(map(str, shape))} array of numbers)")
    try:
        a = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError, OverflowError):
        raise ConfigError(f"{where}: not numbers") from None
    if a.shape != shape:
        raise ConfigError(f"{where}: shape {a.shape}, expected {shape}")
    if not np.isfinite(a).all():
        raise ConfigError(f"{where}: a value is not finite")
    return a


def _covariance(value: Any, n: int, where: str) -> np.ndarray:
    """A covariance matrix: finite, symmetric, its variances (diagonal) not negative."""
    c = _array(value, (n, n), where)
    scale = float(np.max(np.abs(c)))
    if not np.allclose(c, c.T, rtol=1e-9, atol=1e-12 * scale):
        raise ConfigError(f"{where}: not symmetric (not a covariance matrix)")
    if (np.diag(c) < 0).any():
        raise ConfigError(f"{where}: a variance (diagonal entry) is negative (not a covariance matrix)")
    return c


def _model(entry: Any, where: str) -> FittedModel:
    if not isinstance(entry, dict):
        raise ConfigError(f"{where}: not a model entry")
    try:
        name, regressors, parameters = str(entry["model"]), tuple(entry["regressors"]), tuple(entry["parameters"])
        n = len(regressors)
        where = f"{where} ({name})"
        if len(parameters) != n or n == 0:
            raise ConfigError(f"{where}: {len(parameters)} parameters for {n} regressors")
        variance, samples = entry["residual_variance"], entry["samples"]
        if not (_numbers(variance, 0) and math.isfinite(variance) and variance >= 0):
            raise ConfigError(f"{where}: residual_variance must be a finite number >= 0, got {variance!r}")
        if not (isinstance(samples, int) and not isinstance(samples, bool) and samples >= 1):
            raise ConfigError(f"{where}: samples must be a whole number >= 1, got {samples!r}")
        estimate = _array(entry["estimate"], (n,), f"{where} estimate")
        cov = _covariance(entry["covariance"], n, f"{where} covariance")
        conv = _covariance(entry["covariance_conventional"], n, f"{where} covariance_conventional")
    except (KeyError, TypeError, ValueError) as exc:
        if isinstance(exc, ConfigError):
            raise
        raise ConfigError(f"{where}: malformed ({type(exc).__name__}: {exc})") from None
    return FittedModel(name, tuple(map(str, regressors)), tuple(map(str, parameters)), estimate, cov, conv,
                       float(variance), samples)


def read_models(run_dir: str | Path) -> list[tuple[str, list[FittedModel]]]:
    """The ``(maneuver, models)`` pairs of ``run_dir``'s ``models.json``. A directory without it,
    a file that is not one, or an entry refused (module docstring) is a :class:`.errors.ConfigError`."""
    path = Path(run_dir) / MODELS_FILE
    if not Path(run_dir).is_dir():
        raise ConfigError(f"{run_dir}: not a directory (give the output directory of a replay or a campaign)")
    if not path.is_file():
        raise ConfigError(f"{run_dir}: no {MODELS_FILE} (the final models a replay or a campaign writes); "
                          "give the output directory of a replay or a campaign")
    try:
        doc = json.loads(path.read_text())
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise ConfigError(f"{path}: not readable as JSON ({' '.join(str(exc).split())})") from None
    except RecursionError:  # arrays nested thousands deep
        raise ConfigError(f"{path}: not a {MODELS_FORMAT!r} file (nested too deep)") from None
    if not isinstance(doc, dict) or doc.get("format") != MODELS_FORMAT or not isinstance(doc.get("maneuvers"), list):
        raise ConfigError(f"{path}: not a {MODELS_FORMAT!r} file")
    out = []
    for i, m in enumerate(doc["maneuvers"]):
        if not isinstance(m, dict) or not isinstance(m.get("models"), list):
            raise ConfigError(f"{path}: maneuver {i + 1}: malformed")
        name = str(m.get("name", i + 1))
        models = [_model(e, f"{path}: maneuver {name}, model {k + 1}") for k, e in enumerate(m["models"])]
        names = [f.model for f in models]
        if twice := sorted({n for n in names if names.count(n) > 1}):
            raise ConfigError(f"{path}: maneuver {name}: model {', '.join(twice)} given more than once")
        out.append((name, models))
    return out
