"""The node's parameters: generated from the options classes, and read back into them.

:data:`PARAMETERS` lists every parameter the node declares and the replay reads from a
parameter file, one :class:`Parameter` each, made from the fields of the options classes
(:mod:`rls_uncertainty.schema`: the name, the default, the range or choices, the unit and the
meaning are written on the field), plus the aircraft's name and the models' regressors
(:mod:`.models`). The node's parameter descriptors, the parameter table of docs/node.md
(``scripts/parameter_table.py``) and the command line's flags come from this list.

:func:`pipeline_config` and :func:`node_config` turn dotted parameter values into the options
objects: each parameter goes to the field that declares it unchanged, but a span, whose
seconds become samples at the pipeline's rate (:func:`rls_uncertainty.schema.span_value`, the
one conversion). Nothing is checked here that a class checks: a bad value is refused by the
class that holds it, naming the parameter (:class:`.errors.ConfigError`, whose ``parameter``
says which, so that the caller can say where the value came from).
"""

from __future__ import annotations

import difflib
from collections.abc import Iterator
from dataclasses import dataclass
from typing import Any

from ..aero.differentiation import DifferentiatorConfig
from ..aero.models import DEFAULT_MODELS, OUTPUTS, REGRESSORS, ModelConfig
from ..aero.surface_mixing import SurfaceMixing
from ..datapath.config import InputConfig, ManeuverSettings, OutputConfig, PipelineConfig
from ..datapath.convergence import ConvergenceConfig
from ..datapath.identifiability import IdentifiabilityConfig
from ..datapath.limits import PlausibilityLimits
from ..datapath.maneuver_detector import ManeuverOptions
from ..datapath.targets import TargetOptions
from ..errors import ConfigError
from ..estimator.options import AUTO_BURN_IN, MAX_BURN_IN, EstimatorOptions
from ..frequency.options import FrequencyOptions
from ..instruments.options import InstrumentOptions
from ..schema import (
    Setting,
    Special,
    default_of,
    expected,
    kind_of,
    samples,
    seconds,
    setting_of,
    settings,
    span_value,
    valid,
)
from .config import InputTopics, NodeConfig
from .models import DEFAULT_AIRCRAFT, load_aircraft

__all__ = ["Parameter", "PARAMETERS", "PARAMETER_NAMES", "COMPONENTS", "RENAMED", "parameter_defaults", "typed",
           "pipeline_config", "node_config", "estimator_options", "frequency_options", "unknown_parameter",
           "in_group"]

# The options object of each group of parameters: PipelineConfig's field of that name holds it.
COMPONENTS: tuple[tuple[str, type], ...] = (
    ("estimator", EstimatorOptions),
    ("frequency", FrequencyOptions),
    ("differentiator", DifferentiatorConfig),
    ("inputs", InputConfig),
    ("limits", PlausibilityLimits),
    ("surfaces", SurfaceMixing),
    ("convergence", ConvergenceConfig),
    ("identifiability", IdentifiabilityConfig),
    ("outputs", OutputConfig),
    ("instruments", InstrumentOptions),
    ("targets", TargetOptions),
    ("maneuvers", ManeuverSettings),
    ("detection", ManeuverOptions),
)
# Parameters renamed when the lag window began to follow time: said when an old file names them.
RENAMED = {
    "estimator.lags": "estimator.lag_span, in seconds (lags / rate: 50 lags at 50 Hz = 1.0; -1 all lags)",
    "estimator.max_lags": "estimator.max_lag_span, in seconds (max_lags / rate)",
    "estimator.residual_burn_in": "estimator.residual_burn_in_span, in seconds (samples / rate; -1 the default)",
}


@dataclass(frozen=True)
class Parameter:
    """One ROS parameter: dotted ``name``, ``default`` (a ROS value: a bool, int, float, str or
    list of str, whose type is the parameter's), meaning, ``unit``, the range ``low``..``high``
    or the ``choices``, the ``specials`` of a span (values with a meaning of their own),
    ``read_only`` (a change needs a restart), the command line's ``flag`` for it, if any, and
    the ``companion`` parameter that may decide the same field instead (a span's
    :class:`.schema.Choice`: ``estimator.lag_selection`` beside ``estimator.lag_span``)."""

    name: str
    default: Any
    description: str
    unit: str = ""
    low: float | None = None
    high: float | None = None
    choices: tuple[Any, ...] = ()
    specials: tuple[Special, ...] = ()
    read_only: bool = False
    flag: str = ""
    companion: str = ""


def _span_default(default: Any, s: Setting) -> float:
    """A span's default in seconds: the special that stands for the field's default, or the
    field's default samples at the reference rate."""
    assert s.span is not None
    for special in s.span.specials:
        if special.value is default or (type(special.value) is type(default) and special.value == default):
            return special.seconds
    return seconds(default)


def _from_class(cls: type) -> Iterator[Parameter]:
    """The parameters the fields of an options class declare, in field order."""
    for f, s in settings(cls):
        if not s.ros:
            continue
        default = default_of(f)
        if s.span is not None:
            yield Parameter(s.ros, _span_default(default, s), s.description, "s", s.span.low, s.span.high,
                            specials=s.span.specials, read_only=s.read_only, flag=s.cli,
                            companion=s.choice.ros if s.choice else "")
        else:
            yield Parameter(s.ros, list(default) if isinstance(default, tuple) else default, s.description, s.unit,
                            s.low, s.high, s.choices, read_only=s.read_only, flag=s.cli)
        if s.choice is not None:
            c = s.choice
            yield Parameter(c.ros, c.choices[0], c.description, choices=c.choices)


def _domain() -> Iterator[Parameter]:
    """The aircraft and the models: what is flown and what is estimated."""
    yield Parameter("aircraft", DEFAULT_AIRCRAFT,
                    "aircraft properties: a name in config/aircraft/ (t2, twin_otter_f1_017, ...) or a YAML path")
    yield Parameter("models.enabled", list(OUTPUTS), "models to estimate, a subset of " + ", ".join(OUTPUTS),
                    flag="--models")
    defaults = {m.output: m for m in DEFAULT_MODELS}
    for out in OUTPUTS:
        yield Parameter(f"models.{out}", list(defaults[out].regressors),
                        f"regressors of the {out} model (Eq. 2); names: " + ", ".join(REGRESSORS))


def _all() -> tuple[Parameter, ...]:
    top = {p.name: p for p in _from_class(PipelineConfig)}
    return (top.pop("rate"), *_domain(), *top.values(), *(p for _, cls in COMPONENTS for p in _from_class(cls)),
            *_from_class(InputTopics), *_from_class(NodeConfig))


PARAMETERS: tuple[Parameter, ...] = _all()
PARAMETER_NAMES: dict[str, Parameter] = {p.name: p for p in PARAMETERS}
_GROUPS = frozenset(p.name.split(".", 1)[0] for p in PARAMETERS if "." in p.name)


def parameter_defaults() -> dict[str, Any]:
    """Every parameter's default, by name (lists copied)."""
    return {p.name: (list(p.default) if isinstance(p.default, list) else p.default) for p in PARAMETERS}


def typed(name: str, value: Any) -> Any:
    """A value given to a parameter, in the parameter's ROS type where it is one already in
    other words: an integer for a floating-point parameter is that number, a missing list is
    empty, and the empty names a ROS list of names needs (``[""]``) are dropped. Nothing is
    checked: the options classes do that."""
    p = PARAMETER_NAMES.get(name)
    if p is None:
        return value
    if isinstance(p.default, float) and isinstance(value, int) and not isinstance(value, bool):
        return float(value)
    if isinstance(p.default, list):
        if value is None:
            return []
        if isinstance(value, (list, tuple)):
            return [v for v in value if v != ""]
    return value


def unknown_parameter(name: str, known: tuple[str, ...] = ()) -> str:
    """The hint after an unknown parameter's name: its new name, or the closest known one."""
    if name in RENAMED:
        return f" (renamed: {RENAMED[name]})"
    close = difflib.get_close_matches(name, [*PARAMETER_NAMES, *known], n=1, cutoff=0.75)
    return f" (did you mean {close[0]}?)" if close else ""


def in_group(name: str) -> bool:
    """Whether ``name`` is in one of the node's parameter groups (``estimator.``, ``inputs.``, ...)."""
    return name.split(".", 1)[0] in _GROUPS


def _values(params: dict[str, Any]) -> dict[str, Any]:
    """Every parameter's value: the given ones (typed) over the defaults; an unknown name is refused."""
    unknown = sorted(set(params) - set(PARAMETER_NAMES) - {"use_sim_time"})
    if unknown:
        raise ConfigError(f"unknown parameter(s) {unknown}{unknown_parameter(unknown[0])}", parameter=unknown[0])
    values = parameter_defaults()
    values.update({k: typed(k, v) for k, v in params.items() if k in PARAMETER_NAMES})
    return values


def _arguments(cls: type, values: dict[str, Any], rate: float | None) -> dict[str, Any]:
    """The keyword arguments of ``cls`` from the parameters its fields declare: a span's
    seconds as samples at ``rate``, a field's second parameter (:class:`.schema.Choice`)
    over its own, lists of names as tuples."""
    out: dict[str, Any] = {}
    for f, s in settings(cls):
        if not s.ros:
            continue
        value = values[s.ros]
        if s.choice is not None:
            chosen = values[s.choice.ros]
            if chosen not in s.choice.choices:
                raise ConfigError(f"parameter {s.choice.ros!r} must be one of {list(s.choice.choices)}, got "
                                  f"{chosen!r}", parameter=s.choice.ros)
            if chosen != s.choice.choices[0]:
                out[f.name] = s.choice.value
                continue
        if s.span is not None:
            assert rate is not None
            value = span_value(s.ros, s, value, rate)
        elif kind_of(f) is tuple and isinstance(value, list):
            value = tuple(value)
        out[f.name] = value
    return out


def estimator_options(params: dict[str, Any], rate: float) -> EstimatorOptions:
    """The ``estimator.*`` parameters (missing ones at their defaults) as
    :class:`.estimator.EstimatorOptions` at ``rate`` Hz (the command line's simulations: 50). The
    residual burn-in's default (``estimator.residual_burn_in_span: -1``) is a span as well: the
    estimator's default count at the reference rate (1 s), in samples at ``rate``, with
    automatic lags or instrumental variables; 0 (the paper) otherwise."""
    args = _arguments(EstimatorOptions, _values(params), rate)
    if args["residual_burn_in"] is None:
        name = "estimator.residual_burn_in_span"
        args["residual_burn_in"] = samples(name, seconds(AUTO_BURN_IN), rate, MAX_BURN_IN) \
            if args["lags"] == "auto" or args.get("algorithm") == "iv" else 0
    return EstimatorOptions(**args)


def frequency_options(values: dict[str, Any], rate: float) -> FrequencyOptions | None:
    """The ``frequency.*`` parameters as :class:`.frequency.FrequencyOptions` at ``rate``, or
    None when ``estimator.method`` is ``time`` (they are not used then, and a grid the rate
    cannot carry is not refused). ``estimator.publish_lag_windows`` is the publication rule of
    both methods."""
    if values["estimator.method"] == "time":
        return None
    return FrequencyOptions(rate_hz=rate, publish_lag_windows=values["estimator.publish_lag_windows"],
                            **_arguments(FrequencyOptions, values, rate))


def _rate(value: Any) -> float:
    """The rate, checked first by its field's setting: the spans are converted at it."""
    s = setting_of(PipelineConfig.__dataclass_fields__["rate"])
    assert s is not None
    ok, rate = valid(float, s, value)
    if not ok:
        raise ConfigError(f"rate must be {expected(float, s)}, got {value!r}", parameter="rate")
    return float(rate)


def _models(values: dict[str, Any]) -> tuple[ModelConfig, ...]:
    def names(name: str) -> tuple[str, ...]:
        value = values[name]
        if not isinstance(value, list) or not all(isinstance(v, str) for v in value):
            raise ConfigError(f"parameter {name!r} must be a list of names, got {value!r}", parameter=name)
        return tuple(value)

    enabled = names("models.enabled")
    bad = [m for m in enabled if m not in OUTPUTS]
    if bad:
        raise ConfigError(f"parameter 'models.enabled': unknown model(s) {bad}; known: {list(OUTPUTS)}",
                          parameter="models.enabled")
    return tuple(ModelConfig(out, names(f"models.{out}")) for out in enabled)


def pipeline_config(params: dict[str, Any] | None = None) -> PipelineConfig:
    """A :class:`PipelineConfig` from dotted parameters (ROS parameters or a parameter file's);
    missing ones take their defaults. Raises :class:`ConfigError` naming the bad setting."""
    v = _values(params or {})
    rate = _rate(v["rate"])
    if not isinstance(v["aircraft"], str):
        raise ConfigError(f"parameter 'aircraft' must be a name or a path, got {v['aircraft']!r}",
                          parameter="aircraft")
    components: dict[str, Any] = {
        name: cls(**_arguments(cls, v, rate)) for name, cls in COMPONENTS if name not in ("estimator", "frequency")}
    return PipelineConfig(
        aircraft=load_aircraft(v["aircraft"]), models=_models(v), rate=rate, estimator=estimator_options(v, rate),
        method=v["estimator.method"], frequency=frequency_options(v, rate), **components)


def node_config(params: dict[str, Any] | None = None) -> NodeConfig:
    """A :class:`NodeConfig` from dotted parameters; missing ones take their defaults. The
    intake period is checked against the estimator period at ``rate``."""
    v = _values(params or {})
    cfg = NodeConfig(topics=InputTopics(**_arguments(InputTopics, v, None)), **_arguments(NodeConfig, v, None))
    cfg.check_rate(_rate(v["rate"]))
    return cfg

