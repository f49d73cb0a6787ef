"""The pipeline's configuration: frozen dataclasses, each checking its own fields when it is built,
so that a configuration that exists is a valid one.

:class:`PipelineConfig` is everything that decides the numbers: the rate, the aircraft and models
(:mod:`rls_uncertainty.aero.models`), and one options object per component
(:class:`rls_uncertainty.estimator.EstimatorOptions`, :class:`rls_uncertainty.frequency.FrequencyOptions`,
:class:`rls_uncertainty.aero.differentiation.DifferentiatorConfig`, :class:`InputConfig`,
:class:`rls_uncertainty.aero.surface_mixing.SurfaceMixing`, :class:`.limits.PlausibilityLimits`,
:class:`.convergence.ConvergenceConfig`, :class:`.identifiability.IdentifiabilityConfig`,
:class:`OutputConfig`). Every field of these is a :func:`rls_uncertainty.schema.option`: its
default, bounds, unit, meaning and node parameter are written there and nowhere else; the node's
parameters become these objects in :mod:`rls_uncertainty.settings.parameters`.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field, fields
from typing import Any

from ..aero.differentiation import DifferentiatorConfig, pass_band
from ..aero.models import DEFAULT_MODELS, AircraftConfig, ModelConfig
from ..aero.surface_mixing import SURFACES, SurfaceMixing
from ..errors import ConfigError
from ..estimator.options import EstimatorOptions
from ..frequency.options import FrequencyOptions
from ..instruments.options import InstrumentOptions
from ..schema import check, default_of, option
from .convergence import ConvergenceConfig
from .identifiability import IdentifiabilityConfig
from .limits import PlausibilityLimits
from .maneuver_detector import ManeuverOptions
from .targets import TargetOptions

# Models whose outputs need the angular accelerations (Eq. 1: the moments).
_MOMENT_MODELS = ("Cl", "Cm", "Cn")
# The top of the band the models are estimated over when the frequency domain is not used.
_DEFAULT_F_MAX = float(default_of(FrequencyOptions.__dataclass_fields__["f_max"]))

__all__ = [
    "METHODS",
    "InputConfig",
    "OutputConfig",
    "PipelineConfig",
]

# estimator.method: which estimates are published (docs/frequency.md, "In the node").
METHODS = ("time", "frequency", "both")


@dataclass(frozen=True)
class InputConfig:
    """How the input streams are used (``inputs.*`` parameters): the dynamic-pressure topic or
    ``0.5 air_density V^2`` (kg/m^3), the thrust topic or zero thrust, the longest gap
    interpolated across and how far a stream may run ahead before its old messages expire (s),
    the stream timelines (:mod:`.sampling`): the stamp jump (s) that needs
    ``jump_confirmation`` messages to be taken as a new timeline, the largest offset from the
    node's clock (s, 0 = not checked) and the most messages buffered per stream; and the
    ``header.frame_id`` every input must carry (empty: not checked)."""

    use_dynamic_pressure: bool = option(True, "use the dynamic_pressure topic; false computes 0.5 rho V^2 with "
                                        "inputs.air_density", ros="inputs.use_dynamic_pressure")
    air_density: float = option(1.225, "air density for 0.5 rho V^2 when the dynamic pressure topic is not used",
                                unit="kg/m^3", low=0.01, high=2.0, ros="inputs.air_density")
    use_thrust: bool = option(True, "use the thrust topic (force.x, N) in Eq. 1a; false sets thrust to 0",
                              ros="inputs.use_thrust")
    max_gap: float = option(0.25, "largest gap between two messages of one stream that is interpolated across",
                            unit="s", low=0.001, high=10.0, ros="inputs.max_gap")
    buffer_duration: float = option(2.0, "how far a stream may run ahead of the slowest one before its old messages "
                                    "expire", unit="s", low=0.1, high=60.0, ros="inputs.buffer_duration")
    max_stamp_jump: float = option(
        5.0, "a stamp this far behind a stream's newest, or this far ahead of it and of every stream, is a jump "
        "candidate: held until inputs.jump_confirmation more messages confirm a new timeline (a looped replay "
        "restarts), else rejected as stamp_jump", unit="s", low=0.01, high=1.0e9, ros="inputs.max_stamp_jump")
    jump_confirmation: int = option(5, "messages after a jump candidate that must continue its stamps before the "
                                    "jump is taken as real (0: at once)", low=0, high=1000,
                                    ros="inputs.jump_confirmation")
    max_clock_offset: float = option(
        0.0, "reject messages stamped farther than this from the node's clock as far_from_clock; 0 = off (replays "
        "played without /clock keep their recorded stamps)", unit="s", low=0.0, high=1.0e9,
        ros="inputs.max_clock_offset")
    max_buffered: int = option(20000, "messages buffered per stream at most (2 s at 10 kHz); beyond it the oldest "
                               "expire", low=10, high=10_000_000, ros="inputs.max_buffered")
    frame_id: str = option("base_link", "header.frame_id every input must carry (the REP-103 body frame); a message "
                           "in another frame is rejected as frame_mismatch; empty: not checked", ros="inputs.frame_id")

    def __post_init__(self) -> None:
        check(self, "inputs")
        if self.max_stamp_jump < self.max_gap:
            raise ConfigError(f"inputs.max_stamp_jump ({self.max_stamp_jump} s) must be at least "
                              f"inputs.max_gap ({self.max_gap} s)", parameter="inputs.max_stamp_jump")

    @property
    def max_gap_ns(self) -> int:
        return int(round(self.max_gap * 1e9))

    @property
    def buffer_ns(self) -> int:
        return int(round(self.buffer_duration * 1e9))

    @property
    def max_stamp_jump_ns(self) -> int:
        return int(round(self.max_stamp_jump * 1e9))

    @property
    def max_clock_offset_ns(self) -> int:
        return int(round(self.max_clock_offset * 1e9))


@dataclass(frozen=True)
class OutputConfig:
    """What the pipeline computes for its consumers beyond estimates and standard errors
    (``outputs.*`` parameters): full covariance matrices for the samples whose grid index is a
    multiple of ``covariance_decimation`` (0: never)."""

    covariance_decimation: int = option(
        10, "publish ~/M/covariance and ~/M/covariance_conventional for samples whose grid index (stamp x rate) is a "
        "multiple of this; 0 = never", low=0, high=100_000, ros="outputs.covariance_decimation")

    def __post_init__(self) -> None:
        check(self, "outputs")


# Where maneuver boundaries come from (maneuvers.source; :mod:`.maneuvers`).
SOURCES = ("off", "events", "detect")


@dataclass(frozen=True)
class ManeuverSettings:
    """``maneuvers.*``: where maneuver boundaries come from, the event topic, the history kept."""

    source: str = option("off", "where maneuver boundaries come from: off (one estimate across everything), events "
                         "(start/stop messages on maneuvers.topic) or detect (the control-surface excitation); each "
                         "maneuver starts the estimator afresh and its end is recorded (docs/node.md)",
                         choices=SOURCES, ros="maneuvers.source", read_only=True)
    topic: str = option("/test_point", "topic of the test-point events (diagnostic_msgs/msg/KeyValue: key the test "
                        "point's name, value start or stop) with maneuvers.source events",
                        ros="maneuvers.topic", read_only=True)
    history: int = option(100, "maneuvers kept in the history (~/maneuvers); the oldest beyond it is dropped",
                          low=1, high=10_000, ros="maneuvers.history", read_only=True)

    def __post_init__(self) -> None:
        check(self, "maneuvers")


@dataclass(frozen=True)
class PipelineConfig:
    """Everything that decides the numbers: sample rate (Hz), aircraft, models, and the nested
    estimator, differentiator, input, surface-mixing and plausibility settings. The node and
    the offline replay build it the same way (:func:`pipeline_config`)."""

    aircraft: AircraftConfig
    models: tuple[ModelConfig, ...] = DEFAULT_MODELS
    rate: float = option(50.0, "estimator sample rate; input streams are interpolated to it", unit="Hz", low=1.0,
                         high=1000.0, ros="rate")
    estimator: EstimatorOptions = field(default_factory=EstimatorOptions)
    differentiator: DifferentiatorConfig = DifferentiatorConfig()
    inputs: InputConfig = InputConfig()
    surfaces: SurfaceMixing = SurfaceMixing()
    limits: PlausibilityLimits = PlausibilityLimits()
    # Consumers' outputs (not part of the fingerprint: they do not change the estimator state).
    convergence: ConvergenceConfig = field(default_factory=ConvergenceConfig)
    identifiability: IdentifiabilityConfig = field(default_factory=IdentifiabilityConfig)
    outputs: OutputConfig = OutputConfig()
    # With estimator.algorithm iv: how the instruments are made and judged.
    instruments: InstrumentOptions = field(default_factory=InstrumentOptions)
    # Test points judged against target percent errors (targets.*; /diagnostics only).
    targets: TargetOptions = field(default_factory=TargetOptions)
    # Where maneuvers start and end (maneuvers.*; the caller's ManeuverTracker acts on them).
    maneuvers: ManeuverSettings = field(default_factory=ManeuverSettings)
    # The detection rule of maneuvers.source detect (maneuvers.f_max, .window, ...).
    detection: ManeuverOptions = field(default_factory=ManeuverOptions)
    # estimator.method and, unless it is "time", the frequency-domain estimator's options.
    method: str = option("time", "estimates published: time (recursive least squares, ~/M/estimates ...), "
                         "frequency (equation error on a recursive Fourier transform, ~/M/frequency/estimates ...) or "
                         "both (docs/frequency.md)", choices=METHODS, ros="estimator.method", cli="--method")
    frequency: FrequencyOptions | None = None

    def __post_init__(self) -> None:
        check(self, "")
        self._check_method()
        held = math.ceil(self.convergence.window * self.rate) + 2
        if held > self.convergence.max_samples:
            raise ConfigError(
                f"convergence.window ({self.convergence.window:g} s) at rate {self.rate:g} Hz spans {held - 2} "
                f"samples; at most {self.convergence.max_samples - 2} are kept (shorten the window)",
                parameter="convergence.window")
        if not self.models:
            raise ConfigError("at least one model must be enabled")
        outputs = [m.output for m in self.models]
        if len(set(outputs)) != len(outputs):
            raise ConfigError(f"a model is enabled twice: {outputs}")
        for m in self.models:
            for surface in SURFACES:
                if surface in m.regressors and not self.surfaces.names(surface):
                    raise ConfigError(
                        f"model {m.output} uses {surface} but no control surface is mapped to it "
                        "(surfaces.* parameters)"
                    )
        if self.inputs.max_gap * self.rate < 1.0:
            raise ConfigError(
                f"inputs.max_gap ({self.inputs.max_gap} s) is shorter than one estimator sample "
                f"(1/rate = {1 / self.rate:g} s)", parameter="inputs.max_gap")
        self._check_differentiator()
        self._check_instruments()
        known = {p for m in self.models for p in m.parameter_names}
        unknown = sorted(set(self.targets.percent()) - known)
        if unknown:
            raise ConfigError(f"targets.percent names {', '.join(unknown)}, not a parameter of the enabled models "
                              f"({', '.join(sorted(known))})", parameter="targets.percent")

    def _check_instruments(self) -> None:
        """``estimator.algorithm iv``: with ``instruments.source excitation``, models the
        auxiliary model serves (:class:`..instruments.InstrumentLayout` refuses the others in one line)."""
        if self.estimator.algorithm != "iv":
            return
        self.instruments.resolved_source(self.models)

    def _check_differentiator(self) -> None:
        """The angular accelerations of the moment models (Cl, Cm, Cn) pass the differentiator
        within 5 % up to ``frequency.f_max``, the top of the band the models are estimated over
        (its default stands for the time domain too); otherwise the maneuver is smoothed away."""
        moments = [m.output for m in self.models if m.output in _MOMENT_MODELS]
        if not moments:
            return
        top = self.frequency.f_max if self.frequency is not None else _DEFAULT_F_MAX
        d = self.differentiator
        band = pass_band(d, self.rate)
        if band < top:
            good = pass_band(DifferentiatorConfig(), self.rate)
            raise ConfigError(
                f"differentiator.window {d.window} (order {d.order}, lag {d.lag}) at {self.rate:g} Hz passes the "
                f"angular accelerations within 5 % only up to {band:.3g} Hz, below frequency.f_max {top:g} Hz, the "
                f"band the models are estimated over: {', '.join(moments)} loses the maneuver; shorten "
                f"differentiator.window ({DifferentiatorConfig().window} passes {good:.3g} Hz) or lower "
                "frequency.f_max", parameter="differentiator.window")

    def _check_method(self) -> None:
        """``method`` and ``frequency`` agree, and every model has a parameter the frequency
        domain estimates, on a grid with more frequencies than parameters (F5)."""
        if (self.method == "time") != (self.frequency is None):
            raise ConfigError(f"estimator.method {self.method} needs frequency options exactly when it is not 'time'")
        if self.frequency is None:
            return
        if self.frequency.rate_hz != self.rate:
            raise ConfigError(f"frequency options at {self.frequency.rate_hz} Hz for a pipeline at rate {self.rate} Hz")
        for m in self.models:
            if not m.frequency_parameter_names:
                raise ConfigError(f"model {m.output} has no regressor but the bias '1', which the frequency-domain "
                                  f"method does not estimate (estimator.method: {self.method}): give models."
                                  f"{m.output} a regressor, leave it out of models.enabled or use "
                                  "estimator.method: time")
        grid = self.frequency.frequencies().size
        most = max(len(m.frequency_parameter_names) for m in self.models)
        if grid <= most:
            raise ConfigError(f"the frequency grid (frequency.f_min .. f_max every f_step) has {grid} frequencies, a "
                              f"model {most} frequency-domain parameters: it needs more frequencies (lower "
                              "frequency.f_step or widen the band)")

    @property
    def publishes_time(self) -> bool:
        """``estimator.method`` publishes the time-domain estimates (``time``, ``both``)."""
        return self.method != "frequency"

    @property
    def published_methods(self) -> tuple[str, ...]:
        """The estimates ``estimator.method`` publishes: ``("time",)``, ``("frequency",)`` or both."""
        return ("time",) * self.publishes_time + ("frequency",) * (self.frequency is not None)

    def row_methods(self, model: ModelConfig, parameter: str) -> list[str]:
        """The methods with a result row for ``parameter`` of ``model`` (``maneuvers.csv``): those
        published, the frequency domain but for the bias."""
        return [m for m in self.published_methods if m == "time" or parameter in model.frequency_parameter_names]

    @property
    def period_ns(self) -> int:
        return int(round(1e9 / self.rate))

    def fingerprint(self) -> dict[str, Any]:
        """What a saved estimator state must match to be resumed."""
        return {
            "aircraft": [getattr(self.aircraft, f.name) for f in fields(AircraftConfig)],
            "models": [[m.output, *m.regressors] for m in self.models],
            "rate": self.rate,
            "estimator": self.estimator.resolved().as_dict(),
            **({"instruments": asdict(self.instruments)} if self.estimator.algorithm == "iv" else {}),
            **({"frequency": asdict(self.frequency)} if self.frequency is not None else {}),
        }
