"""The complete state of a bank as plain data (``EstimatorBank.state()`` / ``from_state()``),
and the checks a saved one passes before it is trusted.

A state is ``{"format", "sizes", "options", "counters", "arrays"}``: the model sizes, the
options (:meth:`.options.EstimatorOptions.as_dict`), the sample counters and numpy arrays,
nothing else (no pickle), so that it can be written to a file. Restoring it and continuing
gives bit-identically the same numbers as the bank it was taken from. A state of another
:data:`STATE_FORMAT` is refused by name.

**Checks of a saved state** (for a state read back from anywhere: the node's state file,
:mod:`rls_uncertainty.state_file`, reads its fields as JSON and its arrays from the file and
calls these in order): each field by type and range (:func:`check_format`,
:func:`check_sizes`, :func:`check_options`, :func:`check_counters`, the JSON values with
:func:`integer`, :func:`number` and :func:`json_object`); its agreement with the configuration
the caller continues with (:func:`check_expected`); the memory its counters imply
(:func:`implied_bytes`), before anything is allocated; the arrays' names, shapes and dtypes
(``EstimatorBank.state_layout``) and their values (:func:`check_values`). Each failure is one
:class:`.errors.StateFileError` naming the field (``field 'bank_counters.cap' is ...``);
:meth:`EstimatorBank.from_state` checks the shapes again (a second line).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import numpy as np

from ..errors import ConfigError, StateFileError
from .lag_storage import GROWTH_START
from .options import EstimatorOptions

__all__ = [
    "STATE_FORMAT",
    "COUNTERS",
    "MAX_COUNT",
    "ANOTHER_CONFIGURATION",
    "pack",
    "unpack",
    "invalid",
    "integer",
    "number",
    "describe",
    "json_object",
    "check_format",
    "check_sizes",
    "check_options",
    "check_expected",
    "check_counters",
    "implied_bytes",
    "check_values",
]

# 2: lagged moments as one array of y = (x, z) products; 3: Eq. 17 as sums, history windows
# only; 4: the package layout (lag_storage): Lambda+ of x alone once every model is
# initialized, the y products only while one waits, residuals with their sign, D and theta
# as separate arrays; 5: the noise model under forgetting (its dispersion, estimate and
# residual history u, the f-weighted lag-0 moments while a model waits) and automatic lags;
# 6: the residual burn-in (its end k0 + B follows from ready_at); 7: the options as one
# object (EstimatorOptions.as_dict: lags "all" / "auto" / an integer, p0 stored); 8: with
# estimator.algorithm iv, the instruments' state beside the bank's (rls_uncertainty.state_file).
STATE_FORMAT = 9

COUNTERS = ("k", "n_eff", "n_noise", "cap")

MAX_COUNT = 2**53  # samples: exact as a float
_MAX_MODELS, _MAX_PARAMETERS = 64, 64
_MAX_LAGS = 10_000_000
ANOTHER_CONFIGURATION = "saved with another aircraft, model or estimator configuration"


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


# ---------------------------------------------------------------------------------------------
# the fields of a saved state, by type and range


def invalid(field: str, problem: str) -> StateFileError:
    """The error of one field: ``field 'FIELD' PROBLEM``."""
    return StateFileError(f"field '{field}' {problem}")


def _is_int(value: Any) -> bool:
    return isinstance(value, int) and not isinstance(value, bool)


def integer(value: Any, field: str, low: int, high: int) -> int:
    """A JSON integer in ``[low, high]``."""
    if not _is_int(value):
        raise invalid(field, f"must be an integer, found {describe(value)}")
    if not low <= value <= high:
        raise invalid(field, f"must be in [{low}, {high}], found {value}")
    checked: int = value  # (an int: _is_int)
    return checked


def number(value: Any, field: str) -> float:
    """A finite JSON number."""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise invalid(field, f"must be a number, found {describe(value)}")
    found = float(value)
    if not math.isfinite(found):
        raise invalid(field, f"must be finite, found {found}")
    return found


def describe(value: Any) -> str:
    """A short description of a JSON value for a message (never the whole value)."""
    if isinstance(value, (dict, list)):
        return f"a {'JSON object' if isinstance(value, dict) else 'list'} of {len(value)} items"
    text = repr(value)
    return f"{type(value).__name__} {text[:40]}{'...' if len(text) > 40 else ''}"


def _short(value: Any) -> str:
    text = repr(list(value) if isinstance(value, tuple) else value)
    return text if len(text) <= 60 else text[:57] + "..."


def json_object(value: Any, field: str, keys: tuple[str, ...]) -> dict[str, Any]:
    """A JSON object with exactly ``keys`` (``field`` empty: the top level)."""
    if not isinstance(value, dict):
        raise invalid(field, f"must be a JSON object, found {describe(value)}")
    missing = [k for k in keys if k not in value]
    if missing:
        raise invalid(f"{field}.{missing[0]}" if field else missing[0], "is missing")
    extra = sorted(str(k) for k in value if k not in keys)
    if extra:
        raise invalid(f"{field}.{extra[0]}" if field else extra[0][:40], "is not part of a state file")
    checked: dict[str, Any] = value  # (a JSON object: string keys)
    return checked


def check_format(meta: Any) -> None:
    """``meta`` is an object whose ``format`` is :data:`STATE_FORMAT`."""
    if not isinstance(meta, dict):
        raise invalid("meta", f"must be a JSON object, found {describe(meta)}")
    if "format" not in meta:
        raise invalid("format", "is missing")
    found = meta["format"]
    if found != STATE_FORMAT or not _is_int(found):
        raise StateFileError(
            f"state format {describe(found) if not _is_int(found) else found}, this version reads "
            f"{STATE_FORMAT} (saved by another version; delete it to start afresh)"
        )


def check_sizes(raw: Any) -> tuple[int, ...]:
    """The models' parameter counts: 1 to 64 models of 1 to 64 parameters."""
    if not isinstance(raw, list) or not 1 <= len(raw) <= _MAX_MODELS:
        raise invalid("sizes", f"must be a list of 1 to {_MAX_MODELS} sizes, found {describe(raw)}")
    return tuple(integer(s, f"sizes[{i}]", 1, _MAX_PARAMETERS) for i, s in enumerate(raw))


def check_options(raw: Any) -> EstimatorOptions:
    """Valid options (:meth:`EstimatorOptions.from_dict`) holding at most 10 million lags."""
    try:
        options = EstimatorOptions.from_dict(raw)
    except ConfigError as exc:
        raise invalid("options", f"is not valid ({str(exc)[:160]})") from None
    if (options.held or 0) > _MAX_LAGS:
        raise invalid("options.lags", f"holds {options.held} lags, more than a state file may ({_MAX_LAGS})")
    return options


def check_expected(
    sizes: tuple[int, ...], options: EstimatorOptions, expect: tuple[tuple[int, ...], EstimatorOptions] | None
) -> None:
    """The saved sizes and options are those of the configuration the caller continues with
    (``expect``; the options with their defaults resolved)."""
    if expect is None:
        return
    want_sizes, want_options = expect
    if list(sizes) != list(want_sizes):
        raise StateFileError(f"{ANOTHER_CONFIGURATION}: field 'sizes' is {_short(sizes)}, the configuration has "
                             f"{_short(want_sizes)}")
    found, want = options.resolved().as_dict(), want_options.resolved().as_dict()
    for key in want:
        if found[key] != want[key]:
            raise StateFileError(f"{ANOTHER_CONFIGURATION}: field 'options.{key}' is {_short(found[key])}, the "
                                 f"configuration has {_short(want[key])}")


def _all_lags_capacity(k: int) -> int:
    """The lag capacity of an all-lags bank after ``k`` samples: 64, doubled until it holds k."""
    cap = GROWTH_START
    while cap < k:
        cap *= 2
    return cap


def check_counters(raw: Any, options: EstimatorOptions) -> dict[str, Any]:
    """The counters (:data:`COUNTERS`, in ``bank_counters``): ``0 <= n_eff, n_noise <= k``
    and the lag capacity the options hold after ``k`` samples."""
    c = json_object(raw, "bank_counters", COUNTERS)
    k = integer(c["k"], "bank_counters.k", 0, MAX_COUNT)
    for name in ("n_eff", "n_noise"):
        value = number(c[name], f"bank_counters.{name}")
        if not 0.0 <= value <= k * (1.0 + 1e-9):
            raise invalid(f"bank_counters.{name}", f"must be in [0, k = {k}], found {value}")
    held = options.held
    want = _all_lags_capacity(k) if held is None else held + 1
    cap = integer(c["cap"], "bank_counters.cap", 1, 2 * MAX_COUNT)
    if cap != want:
        lags = "all lags" if held is None else f"{held} lags"
        raise invalid("bank_counters.cap", f"is {cap}; {lags} after {k} samples hold {want}")
    return c


def implied_bytes(sizes: tuple[int, ...], counters: Mapping[str, Any]) -> int:
    """An upper bound of the memory an empty bank of ``sizes`` takes at ``counters``' lag
    capacity (histories, lag sums and products of y = (x, z))."""
    m, n1, cap = len(sizes), max(sizes) + 1, int(counters["cap"])
    return 8 * m * cap * (2 * n1 * n1 + 4 * 3 * n1 + 4)


def check_values(arrays: Mapping[str, np.ndarray], k: int) -> None:
    """Every float finite (a bank's state never holds NaN or infinity) and the counts
    ``ready_at`` in ``[0, k]``, ``repairs`` in ``[0, 2^53]``."""
    for name, arr in arrays.items():
        if arr.dtype.kind == "f" and not np.isfinite(arr).all():
            raise invalid(f"arrays.{name}", "holds NaN or infinite values (a bank's state never does)")
    for name, low, high in (("ready_at", 0, k), ("repairs", 0, MAX_COUNT)):
        counts = arrays.get(name)
        if counts is not None and counts.size > 0 and not (counts.min() >= low and counts.max() <= high):
            raise invalid(f"arrays.{name}", f"must hold counts in [{low}, {high}]")
