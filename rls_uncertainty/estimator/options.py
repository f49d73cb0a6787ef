"""The estimator's options: one frozen object, validated once.

:class:`EstimatorOptions` is the only place the options are listed, checked and given their
defaults: each field is a :func:`..schema.option` carrying its default, bounds, unit, meaning
and, where the node has one, its ROS parameter and command-line flag (the spans in seconds
there, :class:`..schema.Span`; in samples here). The fast bank (:class:`.bank.EstimatorBank`),
the executable specification (:class:`.reference.RecursiveReference`),
:class:`.recursive.RecursiveEstimator` and the state file take it as it is and check nothing
again; :mod:`rls_uncertainty.settings.parameters` builds it from the node's parameters. What
each option means is defined in :mod:`.reference` and tabulated in ``docs/estimator.md``.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, fields, replace
from typing import Any, Literal, get_args

import numpy as np

from ..errors import ConfigError
from ..schema import Choice, Span, Special, check, option, seconds

__all__ = [
    "EstimatorOptions",
    "Lags",
    "Window",
    "Residual",
    "Algorithm",
    "ALGORITHMS",
    "SMALL_SAMPLE",
    "CovarianceKind",
    "WINDOWS",
    "RESIDUALS",
    "COVARIANCE_KINDS",
    "LAG_SELECTIONS",
    "AUTO_BURN_IN",
    "MAX_BURN_IN",
    "MAX_LAGS",
    "NOISE_MEMORY_LAGS",
    "PUBLISH_LAG_WINDOWS",
    "PUBLISH_LAG_WINDOWS_RANGE",
    "PUBLISH_MEANING",
    "check_window",
    "check_kind",
]

# Default memory of the noise model under forgetting, in units of (lags held + 1) samples.
NOISE_MEMORY_LAGS = 40.0
# residual_burn_in: the default with lags="auto" (0, the paper, otherwise), samples (1 s at the
# paper's 50 Hz; the node's estimator.residual_burn_in_span default is that span at its rate),
# and the largest value accepted.
AUTO_BURN_IN = 50
MAX_BURN_IN = 100_000
MAX_LAGS = 100_000  # the most lags held (the memory of Eq. 22's lag products)
# estimator.publish_lag_windows: its default and range (both methods' banks take it).
PUBLISH_LAG_WINDOWS = 2.0
PUBLISH_LAG_WINDOWS_RANGE = (1.0, 100.0)
PUBLISH_MEANING = (
    "a model publishes its estimates and standard errors once its residual degrees of freedom (samples since the "
    "start less its parameters) reach this many lag windows of its corrected covariance (Eq. 22); below one window "
    "the corrected standard error is an artefact of the window")

Lags = int | Literal["all", "auto"]
Window = Literal["truncated", "bartlett"]
Residual = Literal["standardized", "a_posteriori", "a_priori"]
Algorithm = Literal["rls", "iv"]
ALGORITHMS: tuple[Algorithm, ...] = get_args(Algorithm)
# small_sample: the default factor s of n_R / (n_R - n - s L) on the instrumental-variables
# corrected covariance, and the largest value accepted.
SMALL_SAMPLE = 0.5
# iv_init_samples: the default fewest samples before an instrumental-variables model initializes.
IV_INIT_SAMPLES = 25
MAX_SMALL_SAMPLE = 10.0
CovarianceKind = Literal["corrected", "conventional"]
WINDOWS: tuple[Window, ...] = get_args(Window)
RESIDUALS: tuple[Residual, ...] = get_args(Residual)
COVARIANCE_KINDS: tuple[CovarianceKind, ...] = get_args(CovarianceKind)
# estimator.lag_selection: lags fixed by estimator.lag_span, or chosen by the data ("auto").
LAG_SELECTIONS = ("fixed", "auto")

def check_window(window: object) -> None:
    """Refuse a lag window other than :data:`WINDOWS` (an argument of the batch formulas)."""
    if window not in WINDOWS:
        raise ConfigError(f"window must be one of {list(WINDOWS)}, got {window!r}")


def check_kind(kind: object) -> None:
    """Refuse a covariance kind other than :data:`COVARIANCE_KINDS` (an argument, not an option)."""
    if kind not in COVARIANCE_KINDS:
        raise ConfigError(f"kind must be one of {list(COVARIANCE_KINDS)}, got {kind!r}")


def _is_int(value: object) -> bool:
    return isinstance(value, (int, np.integer)) and not isinstance(value, (bool, np.bool_))


def _is_number(value: object) -> bool:
    return _is_int(value) or isinstance(value, (float, np.floating))


def _fail(option: str, expected: str, value: object) -> ConfigError:
    return ConfigError(f"estimator.{option} must be {expected}, got {value!r}")


@dataclass(frozen=True)
class EstimatorOptions:
    """How the estimator runs; every field is checked when the object is made.

    ``lags``: the largest lag ``L`` of Eq. 22 (an integer >= 0; 0 is the conventional
    covariance), ``"all"`` (Eq. 20: memory and time grow with the samples) or ``"auto"`` (each
    model's ``L`` chosen at every sample by Politis' flat-top rule, from ``min_lags`` to
    ``max_lags``, with the memory of ``lags=max_lags``). ``window``: ``"truncated"`` (Eq. 22)
    or ``"bartlett"`` (positive semi-definite; not with ``"auto"``). ``forgetting``: ``0 < f
    <= 1``, 1 is the paper. ``residual``: the residual of Eqs. 16-17. ``residual_burn_in``:
    samples after each model's initialization left out of ``R_k(i)`` (``None``: 50 with
    ``"auto"`` or algorithm ``"iv"``, 0 otherwise). ``noise_forgetting``: ``f_R`` of the noise model under
    forgetting, ``forgetting <= f_R <= 1`` (``None``: the default of
    :attr:`noise_forgetting_used`). ``init_condition``: exact initialization waits for a
    column-scaled ``X'X`` better conditioned than this. ``p0``: ``None`` (exact
    initialization) or the prior ``D_0 = diag(p0)``, ``theta_0 = 0``, a positive scalar or one
    value per parameter. ``algorithm``: ``"rls"`` (Eq. 15) or ``"iv"`` (instrumental
    variables, :mod:`.iv_fit`; ``small_sample`` its covariance factor, ``iv_init_samples``
    the fewest samples before it initializes).
    Definitions: :mod:`.reference`; the table: ``docs/estimator.md``.
    """

    lags: Lags = option(
        50, "time span of the residual autocorrelation kept in the corrected covariance (Eq. 22): lags = lag_span x "
        "rate (1 s: the paper's 50 lags at 50 Hz), so the standard errors do not depend on the rate",
        unit="samples", low=0, high=MAX_LAGS, own_check=True, ros="estimator.lag_span", cli="--lag-span",
        span=Span(-1.0, 2000.0, (Special(-1.0, "all", "all", "keeps all lags (Eq. 20)"),
                                 Special(0.0, 0, "", "the conventional covariance"))),
        choice=Choice("estimator.lag_selection", LAG_SELECTIONS, "auto",
                      "fixed: estimator.lag_span; auto: each model's lags chosen from its residual autocorrelation "
                      "at every sample (Politis flat-top rule, truncated window only), up to "
                      "estimator.max_lag_span"))
    window: Window = option("truncated", "lag window: truncated (Eq. 22) or bartlett (always positive semi-definite)",
                            choices=WINDOWS, ros="estimator.window", cli="--window")
    forgetting: float = option(1.0, "exponential forgetting factor; 1 is the paper's growing-memory estimator",
                               low=0.5, high=1.0, ros="estimator.forgetting", cli="--forgetting")
    residual: Residual = option(
        "standardized", "residual used in Eqs. 16-17: standardized (innovation / sqrt(1 + x'Dx), makes Eq. 16 "
        "equal the batch Eq. 14), a_posteriori (z - x'theta_k) or a_priori (z - x'theta_k-1)",
        choices=RESIDUALS, ros="estimator.residual")
    max_lags: int = option(
        50, "with estimator.lag_selection auto: the longest lag span the rule may choose, and the memory kept (as "
        "estimator.lag_span of that value)", unit="samples", low=1, high=MAX_LAGS, ros="estimator.max_lag_span",
        cli="--max-lag-span", span=Span(0.001, 2000.0))
    min_lags: int = option(0, "with automatic lags: the fewest lags used", unit="samples", own_check=True)
    residual_burn_in: int | None = option(
        None, "time after each model's initialization whose residuals are left out of the residual "
        "autocorrelation (Eq. 17; the first residuals, while the estimate is still poor, inflate it)",
        unit="samples", low=0, high=MAX_BURN_IN, own_check=True, ros="estimator.residual_burn_in_span",
        cli="--burn-in-span",
        span=Span(-1.0, 2000.0, (Special(-1.0, None, "default", f"{seconds(AUTO_BURN_IN):g} s with "
                                 "estimator.lag_selection auto or the iv algorithm, 0 (the paper) "
                                 "otherwise"),
                                 Special(0.0, 0, "", "none (the paper)"))))
    noise_forgetting: float | None = option(
        None, "forgetting f_R of the noise model under forgetting, in [forgetting, 1] (None: the default of "
        "noise_forgetting_used)", own_check=True)
    init_condition: float = option(
        1e8, "exact initialization waits for a column-scaled X'X better conditioned than this", low=1.0,
        low_open=True)
    p0: float | tuple[float, ...] | None = option(
        None, "None (exact initialization) or the prior D_0 = diag(p0), theta_0 = 0: a positive number or one per "
        "parameter", own_check=True)
    publish_lag_windows: float = option(
        PUBLISH_LAG_WINDOWS, PUBLISH_MEANING, low=PUBLISH_LAG_WINDOWS_RANGE[0], high=PUBLISH_LAG_WINDOWS_RANGE[1],
        ros="estimator.publish_lag_windows", cli="--publish-lag-windows")
    algorithm: Algorithm = option(
        "rls", "rls: recursive least squares (Eq. 15); iv: recursive instrumental variables, the estimate "
        "(Z'X)^-1 Z'z from instruments given with every sample and the sandwich covariance P N P' whose middle is "
        "Eqs. 17-22 with the instruments in Lambda (no forgetting, exact initialization); docs/estimator.md, "
        "instrumental variables", choices=ALGORITHMS, ros="estimator.algorithm")
    small_sample: float = option(
        SMALL_SAMPLE, "with algorithm iv: s of the factor n_R / (n_R - n - s L) on the corrected covariance (the "
        "residuals were fitted with n parameters and the L-lag sum loses about s samples per lag); 0 is Eq. 22",
        low=0.0, high=MAX_SMALL_SAMPLE, ros="estimator.small_sample")
    iv_init_samples: int = option(
        IV_INIT_SAMPLES, "with algorithm iv: the exact initialization waits for at least this many samples as well as "
        "for a well-conditioned column-scaled Z'X (an estimate from a handful of samples is poor, and its residuals "
        "inflate the autocorrelation)", unit="samples", low=0, high=MAX_BURN_IN)

    def __post_init__(self) -> None:
        check(self, "estimator")
        self._check_lags()
        if self.lags == "auto" and self.window != "truncated":
            raise _fail(
                "window", "'truncated' with automatic lags (the flat-top rule chooses a truncation point; "
                "the Bartlett taper cannot let the anti-correlated lags of differentiated noise cancel)", self.window,
            )
        b: Any = self.residual_burn_in  # (whatever was given: checked here)
        if b is not None and not (_is_int(b) and 0 <= b <= MAX_BURN_IN):
            raise _fail("residual_burn_in", f"None (the default: {AUTO_BURN_IN} with automatic lags, 0 otherwise) "
                        f"or an integer in [0, {MAX_BURN_IN}]", b)
        self._set("residual_burn_in", None if b is None else int(b))
        f, g = self.forgetting, self.noise_forgetting
        if g is not None:
            if not (_is_number(g) and f <= float(g) <= 1.0):
                raise _fail("noise_forgetting", f"None or a number in [forgetting, 1] = [{f:g}, 1]", g)
            self._set("noise_forgetting", float(g))
        self._check_p0()
        if self.algorithm == "iv":
            if self.forgetting != 1.0:
                raise _fail("forgetting", "1 with algorithm iv (instrumental variables without forgetting)",
                            self.forgetting)
            if self.p0 is not None:
                raise _fail("p0", "None with algorithm iv (exact initialization)", self.p0)

    def _set(self, name: str, value: object) -> None:
        object.__setattr__(self, name, value)  # the normalised value (frozen dataclass)

    def _check_lags(self) -> None:
        lags: Any = self.lags  # (whatever was given: checked here)
        high = self.max_lags
        if not (lags in ("all", "auto") if isinstance(lags, str) else _is_int(lags) and 0 <= lags <= MAX_LAGS):
            raise _fail("lags", f"an integer in [0, {MAX_LAGS}], 'all' or 'auto'", lags)
        if not (_is_int(self.min_lags) and 0 <= self.min_lags <= high):
            raise _fail("min_lags", f"an integer in [0, max_lags = {high}]", self.min_lags)
        if not isinstance(lags, str):
            self._set("lags", int(lags))
        self._set("min_lags", int(self.min_lags))

    def _check_p0(self) -> None:
        p0: Any = self.p0  # (whatever was given: checked here)
        if p0 is None:
            return
        values: list[Any] | None = None
        if _is_number(p0):
            values = [p0]
        elif isinstance(p0, (tuple, list, np.ndarray)):
            values = list(p0)
        if not values or not all(_is_number(v) and math.isfinite(v) and v > 0 for v in values):
            raise _fail("p0", "None, a positive number or a sequence of them", p0)
        self._set("p0", float(values[0]) if _is_number(p0) else tuple(float(v) for v in values))

    # ------------------------------------------------------------------ resolved values
    @property
    def auto(self) -> bool:
        """Lags chosen from the data (``lags="auto"``)."""
        return self.lags == "auto"

    @property
    def held(self) -> int | None:
        """The largest lag held in memory: ``lags``, ``max_lags`` with ``"auto"``, None for all."""
        if self.lags == "all":
            return None
        return self.max_lags if self.lags == "auto" else int(self.lags)

    @property
    def publish_lags(self) -> int:
        """The lag window ``L`` the publication rule counts in: ``lags`` when fixed and
        positive; ``max_lags`` with ``"auto"``, all lags and ``lags=0`` (the conventional
        covariance), which have no window of their own (0 would publish the exact fit)."""
        lags = self.lags
        return lags if isinstance(lags, int) and lags > 0 else self.max_lags

    def publish_samples(self, n: int) -> int:
        """The samples a model of ``n`` parameters needs before it publishes: ``n +
        ceil(publish_lag_windows x L)`` (counted after the residual burn-in, when there is one)."""
        return n + math.ceil(self.publish_lag_windows * self.publish_lags - 1e-9)

    @property
    def burn_in(self) -> int:
        """The residual burn-in ``B`` used: ``residual_burn_in``, or its default (50 with
        ``"auto"`` or algorithm ``"iv"``, 0, the paper's Eq. 17, otherwise)."""
        if self.residual_burn_in is None:
            return AUTO_BURN_IN if self.auto or self.algorithm == "iv" else 0
        return self.residual_burn_in

    @property
    def noise_forgetting_used(self) -> float:
        """``f_R``: ``noise_forgetting``, or by default ``max(f, 1 - 1/(40 (held + 1)))``, and
        ``f`` itself when ``f = 1`` or all lags are kept (``docs/estimator.md``).

        The noise autocovariance is then averaged over ``40 (held + 1)`` samples (2040 for 50
        lags, ``f_R = 0.99951``): the noise model's own fit absorbs about ``1/40`` of the lag
        sum, and the relative spread of the lag sum is about ``sqrt(2/40)``."""
        if self.noise_forgetting is not None:
            return self.noise_forgetting
        f, held = self.forgetting, self.held
        if f == 1.0 or held is None:
            return f
        return max(f, 1.0 - 1.0 / (NOISE_MEMORY_LAGS * (held + 1)))

    @property
    def noise_model(self) -> bool:
        """``R_k(i)`` comes from the noise model (``f_R != f``, so ``f < 1``)."""
        return self.noise_forgetting_used != self.forgetting

    def prior(self, n: int) -> np.ndarray | None:
        """The diagonal of ``D_0 = diag(p0)`` for ``n`` parameters, None for exact initialization."""
        if self.p0 is None:
            return None
        if isinstance(self.p0, float):
            return np.full(n, self.p0)
        if len(self.p0) != n:
            raise ConfigError(f"estimator.p0 must be a number or have {n} entries (the most parameters of a "
                              f"model), got {len(self.p0)}")
        return np.array(self.p0)

    def resolved(self) -> EstimatorOptions:
        """The same options with the defaults resolved (``residual_burn_in``,
        ``noise_forgetting``; ``small_sample`` and ``iv_init_samples`` 0 with ``rls``, which does
        not use them): two objects that run the same estimator resolve to equal ones."""
        return replace(self, residual_burn_in=self.burn_in, noise_forgetting=self.noise_forgetting_used,
                       small_sample=self.small_sample if self.algorithm == "iv" else 0.0,
                       iv_init_samples=self.iv_init_samples if self.algorithm == "iv" else 0)

    # ------------------------------------------------------------------ state file
    def as_dict(self) -> dict[str, Any]:
        """The options as JSON-ready values, as given (:meth:`from_dict` gives back an equal
        object; compare ``resolved().as_dict()`` to know whether two run the same estimator)."""
        out = {f.name: getattr(self, f.name) for f in fields(self)}
        if isinstance(self.p0, tuple):
            out["p0"] = list(self.p0)
        return out

    @classmethod
    def from_dict(cls, values: Mapping[str, Any]) -> EstimatorOptions:
        """Inverse of :meth:`as_dict`; refuses a missing or unknown key and any invalid value
        (:class:`ConfigError` naming the option)."""
        if not isinstance(values, Mapping):
            raise ConfigError(f"estimator options must be a mapping, got {type(values).__name__}")
        names = [f.name for f in fields(cls)]
        missing = [n for n in names if n not in values and n not in cls.optional_keys()]
        if missing:
            raise ConfigError(f"estimator.{missing[0]} is missing")
        extra = sorted(str(k) for k in values if k not in names)
        if extra:
            raise ConfigError(f"estimator.{extra[0][:40]} is not an estimator option")
        p0 = values["p0"]
        return cls(**{**values, "p0": tuple(p0) if isinstance(p0, list) else p0})

    @staticmethod
    def optional_keys() -> tuple[str, ...]:
        """Keys :meth:`from_dict` may miss (options added later: their defaults)."""
        return ("publish_lag_windows", "algorithm", "small_sample", "iv_init_samples")
