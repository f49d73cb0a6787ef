"""Typed configuration: aircraft and model files, the parameters generated from the options
classes, the nested PipelineConfig built from dotted parameters, every validation with its
reason, and where a start-up parameter came from when it is refused."""

import dataclasses
import math
import signal
import subprocess
import sys
import time
from dataclasses import replace
from pathlib import Path

import pytest

from rls_uncertainty.aero.surface_mixing import SurfaceMixing
from rls_uncertainty.datapath.limits import PlausibilityLimits
from rls_uncertainty.errors import ConfigError
from rls_uncertainty.estimator import RESIDUALS, WINDOWS, EstimatorOptions
from rls_uncertainty.frequency import FrequencyOptions
from rls_uncertainty.settings import (
    NODE_NAME,
    PARAMETERS,
    InputConfig,
    ModelConfig,
    PipelineConfig,
    load_aircraft,
    load_models,
    load_parameters_file,
    node_config,
    parameter_defaults,
    pipeline_config,
    startup_parameters,
)
from rls_uncertainty.settings.config import intake_period
from rls_uncertainty.settings.parameters import COMPONENTS, frequency_options

ROOT = Path(__file__).resolve().parents[1]
T2 = load_aircraft("t2")


def test_table1_converted_to_si():
    assert T2.b == pytest.approx(6.849 * 0.3048, rel=1e-8)
    assert T2.S == pytest.approx(5.902 * 0.3048**2, rel=1e-6)
    assert T2.mass == pytest.approx(1.585 * 14.59390294, rel=1e-8)
    assert T2.Iyy == pytest.approx(4.520 * 14.59390294 * 0.3048**2, rel=1e-8)
    otter = load_aircraft("twin_otter_f1_017")
    assert (otter.mass, otter.Ixz, otter.S) == (4952.28, 1528.0, 39.25)


def test_aircraft_file_errors_are_clear(tmp_path):
    bad = tmp_path / "bad.yaml"
    bad.write_text("aircraft: {name: x, mass: -1, Ixx: 1, Iyy: 1, Izz: 1, Ixz: 0, S: 1, b: 1, cbar: 1}\n")
    with pytest.raises(ConfigError, match="mass must be positive"):
        load_aircraft(bad)
    bad.write_text("aircraft: {name: x}\n")
    with pytest.raises(ConfigError, match="needs"):
        load_aircraft(bad)
    with pytest.raises(ConfigError, match="no such file"):
        load_aircraft(tmp_path / "missing.yaml")


def test_models_are_configuration():
    models = load_models({"CZ": ["1", "alpha", "q_hat", "delta_e"]})
    assert models[0].parameter_names == ("CZ_0", "CZ_alpha", "CZ_q", "CZ_delta_e")
    with pytest.raises(ConfigError, match="unknown regressor"):
        ModelConfig("CZ", ("1", "alpha_dot"))
    with pytest.raises(ConfigError, match="output"):
        ModelConfig("CL", ("1",))


@pytest.mark.parametrize("params,match", [
    ({"estimator.window": "hann"}, "estimator.window"),
    ({"estimator.lag_span": -2}, "estimator.lag_span"),
    ({"estimator.lag_span": -0.5}, "estimator.lag_span"),  # in range, but neither -1, 0 nor a span
    ({"estimator.lag_span": 0.001}, "less than one sample at rate 50 Hz"),
    ({"estimator.lag_span": 200.0, "rate": 1000.0}, "at most 100000 are held"),
    ({"estimator.max_lag_span": 0.005}, "estimator.max_lag_span"),
    ({"estimator.residual_burn_in_span": -2}, "estimator.residual_burn_in_span"),
    ({"estimator.residual_burn_in_span": -0.5}, "estimator.residual_burn_in_span"),
    ({"estimator.residual_burn_in_span": 2001}, "estimator.residual_burn_in_span"),
    ({"estimator.lags": 50}, r"renamed: estimator.lag_span, in seconds \(lags / rate"),
    ({"identifiability.max_correlation": 1.0}, "identifiability.max_correlation"),
    ({"identifiability.min_r_squared": -0.1}, "identifiability.min_r_squared"),
    ({"rate": 0.0}, "rate"),
    ({"rate": "fast"}, "rate"),
    ({"models.enabled": ["CQ"]}, "unknown model"),
    ({"models.Cm": ["1", "gamma"]}, "unknown regressor"),
    ({"models.enabled": ["Cl"], "surfaces.aileron_right": []}, "no control surface"),
    ({"differentiator.lag": 9}, "differentiator.lag"),
    ({"differentiator.order": 9}, "differentiator.order"),
    ({"inputs.max_gap": 0.001}, "max_gap"),
    ({"inputs.max_gap": 1.0, "inputs.max_stamp_jump": 0.5}, "max_stamp_jump"),
    ({"colour": "red"}, "unknown parameter"),
    ({"aircraft": "concorde"}, "no such file"),
    ({"limits.alpha": 3.1}, "limits.alpha"),  # |alpha| near pi is flying backwards
    ({"limits.dynamic_pressure_min": 1e-300}, "limits.dynamic_pressure_min"),
    ({"limits.angular_rate": 1e100}, "limits.angular_rate"),
    ({"limits.airspeed_min": 90.0, "limits.airspeed_max": 80.0}, "limits.airspeed_min"),
    ({"inputs.frame_id": 7}, "inputs.frame_id"),
])
def test_invalid_settings_are_refused_with_the_reason(params, match):
    with pytest.raises(ConfigError, match=match):
        pipeline_config(params)


@pytest.mark.parametrize("params,match", [
    ({"intake_period": -0.001}, r"^intake_period must be a number in \[0, 0.05\] s, got -0.001$"),
    ({"intake_period": 0.06}, r"^intake_period must be a number in \[0, 0.05\] s, got 0.06$"),
    ({"intake_period": "fast"}, r"^intake_period must be a number in \[0, 0.05\] s, got 'fast'$"),
    ({"intake_period": 0.0005}, r"^intake_period must be 0 \(the default\) or at least 0.001 s, got 0.0005$"),
    ({"intake_period": 0.03}, r"^intake_period 0.03 s is longer than the estimator period at rate 50 Hz \(0.02 s\)"),
    ({"intake_period": 0.02, "rate": 100.0}, r"^intake_period 0.02 s is longer than the estimator period at rate "
                                             r"100 Hz \(0.01 s\): give at most that, or 0"),
])
def test_a_bad_intake_period_is_refused_in_one_line_naming_it(params, match):
    with pytest.raises(ConfigError, match=match) as exc:
        node_config(params)
    assert exc.value.parameter == "intake_period" and "\n" not in str(exc.value)


@pytest.mark.parametrize("rate,given,expected", [
    (50.0, 0.0, 0.005), (100.0, 0.0, 0.005), (200.0, 0.0, 0.005), (500.0, 0.0, 0.002), (1000.0, 0.0, 0.001),
    (1.0, 0.0, 0.005), (50.0, 0.02, 0.02), (50.0, 0.001, 0.001), (50.0, 0.01, 0.01), (20.0, 0.05, 0.05),
])
def test_the_intake_period_is_the_estimator_period_at_most_5_ms_unless_given(rate, given, expected):
    """The default is the node's intake period before the setting existed: 1 / rate, at most
    5 ms; a given period is used as it is."""
    params = {"rate": rate} if given == 0.0 else {"rate": rate, "intake_period": given}
    cfg = node_config(params)
    assert cfg.intake_period == given
    assert intake_period(cfg.intake_period, rate) == expected


@pytest.mark.parametrize("name", ["t2", "t2_turbulence", "twin_otter_lateral", "twin_otter_longitudinal"])
def test_shipped_parameter_files_are_valid(name):
    cfg = pipeline_config(load_parameters_file(name))
    assert cfg.models


def test_every_parameter_reaches_its_nested_field():
    """Each pipeline parameter, set to a non-default value, changes exactly the field of the
    same name in its section; the estimator's time spans are samples at the rate
    (``estimator.lag_span`` 0.22 s is 11 lags at 50 Hz, -1 is ``"all"``;
    ``estimator.lag_selection`` auto is ``lags="auto"``: :func:`.config.estimator_options`)."""
    changed = {
        "rate": ("rate", 100.0),
        "estimator.lag_span": (("estimator", "lags"), 11),
        "estimator.window": (("estimator", "window"), "bartlett"),
        "estimator.forgetting": (("estimator", "forgetting"), 0.99),
        "estimator.residual": (("estimator", "residual"), "a_priori"),
        "estimator.publish_lag_windows": (("estimator", "publish_lag_windows"), 3.0),
        "estimator.lag_selection": (("estimator", "lags"), "auto"),
        "estimator.max_lag_span": (("estimator", "max_lags"), 80),
        "estimator.residual_burn_in_span": (("estimator", "residual_burn_in"), 20),
        "differentiator.window": (("differentiator", "window"), 11),
        "differentiator.order": (("differentiator", "order"), 4),  # (2 passes 1.28 Hz at 9: refused)
        "differentiator.lag": (("differentiator", "lag"), 5),
        "inputs.use_dynamic_pressure": (("inputs", "use_dynamic_pressure"), False),
        "inputs.air_density": (("inputs", "air_density"), 1.0),
        "inputs.use_thrust": (("inputs", "use_thrust"), False),
        "inputs.max_gap": (("inputs", "max_gap"), 0.5),
        "inputs.buffer_duration": (("inputs", "buffer_duration"), 3.0),
        "inputs.max_stamp_jump": (("inputs", "max_stamp_jump"), 7.5),
        "inputs.jump_confirmation": (("inputs", "jump_confirmation"), 3),
        "inputs.max_clock_offset": (("inputs", "max_clock_offset"), 60.0),
        "inputs.max_buffered": (("inputs", "max_buffered"), 500),
        "inputs.frame_id": (("inputs", "frame_id"), "body"),
        "surfaces.elevator": (("surfaces", "elevator"), ["e1", "e2"]),
        "surfaces.aileron_right": (("surfaces", "aileron_right"), ["ar"]),
        "surfaces.aileron_left": (("surfaces", "aileron_left"), ["al"]),
        "surfaces.aileron_combined": (("surfaces", "aileron_combined"), "ail"),
        "surfaces.rudder": (("surfaces", "rudder"), ["r1"]),
        "limits.airspeed_min": (("limits", "airspeed_min"), 5.0),
        "limits.airspeed_max": (("limits", "airspeed_max"), 100.0),
        "limits.alpha": (("limits", "alpha"), 0.5),
        "limits.beta": (("limits", "beta"), 0.3),
        "limits.angular_rate": (("limits", "angular_rate"), 5.0),
        "limits.specific_force": (("limits", "specific_force"), 50.0),
        "limits.surface": (("limits", "surface"), 0.5),
        "limits.dynamic_pressure_min": (("limits", "dynamic_pressure_min"), 50.0),
        "limits.dynamic_pressure_max": (("limits", "dynamic_pressure_max"), 5000.0),
        "limits.thrust": (("limits", "thrust"), 1000.0),
        "limits.air_density_min": (("limits", "air_density_min"), 0.3),
        "limits.air_density_max": (("limits", "air_density_max"), 1.5),
        "limits.angular_acceleration": (("limits", "angular_acceleration"), 100.0),
        "identifiability.max_correlation": (("identifiability", "max_correlation"), 0.99),
        "identifiability.min_r_squared": (("identifiability", "min_r_squared"), 0.25),
        "identifiability.min_noise_ratio": (("identifiability", "min_noise_ratio"), 4.0),
        "identifiability.angle_resolution": (("identifiability", "angle_resolution"), 1e-3),
        "identifiability.rate_resolution": (("identifiability", "rate_resolution"), 1e-5),
        "estimator.small_sample": (("estimator", "small_sample"), 1.0),
        "instruments.refresh_span": (("instruments", "refresh_span"), 1.0),
        "instruments.weak_below": (("instruments", "weak_below"), 0.2),
        "instruments.max_backlog_span": (("instruments", "max_backlog_span"), 10.0),
        "instruments.source": (("instruments", "source"), "delayed"),
        "instruments.delay_span": (("instruments", "delay_span"), 0.2),
    }
    sections = {"rate", "estimator", "differentiator", "inputs", "surfaces", "limits", "identifiability", "instruments"}
    # (estimator.method and the frequency.* parameters: test_every_frequency_parameter_reaches_its_option;
    # estimator.algorithm, which needs models the instruments serve: test_instrument_path)
    pipeline_params = [p.name for p in PARAMETERS if p.name.split(".")[0] in sections
                       and p.name not in ("estimator.method", "estimator.algorithm")]
    assert sorted(changed) == sorted(pipeline_params)
    given = {"estimator.lag_span": 0.22, "estimator.max_lag_span": 1.6, "estimator.residual_burn_in_span": 0.4}
    default = pipeline_config({})
    for name, (where, value) in changed.items():
        cfg = pipeline_config({name: given.get(name, value)})
        if isinstance(where, str):  # the rate: the estimator's spans are samples at it
            assert getattr(cfg, where) == value and (cfg.estimator.lags, cfg.estimator.max_lags) == (100, 100)
            assert dataclasses.replace(cfg, **{where: getattr(default, where)}, estimator=default.estimator) == default
            continue
        section, attr = where
        got = getattr(getattr(cfg, section), attr)
        assert got == (tuple(value) if isinstance(value, list) else value), name
        # Nothing else changed.
        restored = dataclasses.replace(getattr(cfg, section), **{attr: getattr(getattr(default, section), attr)})
        if name == "estimator.lag_selection":  # residual_burn_in_span -1: 1 s with auto, 0 with fixed lags
            restored = dataclasses.replace(restored, residual_burn_in=0)
        assert dataclasses.replace(cfg, **{section: restored}) == default, name
    assert pipeline_config({"estimator.lag_span": -1}).estimator.lags == "all"
    assert pipeline_config({"estimator.lag_span": 0}).estimator.lags == 0
    assert pipeline_config({"estimator.residual_burn_in_span": -1}).estimator.residual_burn_in == 0


@pytest.mark.parametrize("rate", [20.0, 50.0, 200.0, 1000.0])
def test_the_lag_window_follows_time_not_samples(rate):
    """The estimator's lags, automatic-lag cap and burn-in are the configured spans at the rate
    (rounded half up): the same seconds of residual autocorrelation at every rate."""
    est = pipeline_config({"rate": rate}).estimator
    assert est.lags == round(rate) and est.residual_burn_in == 0  # 1 s: the paper's 50 lags at 50 Hz
    auto = pipeline_config({"rate": rate, "estimator.lag_selection": "auto", "estimator.max_lag_span": 0.25})
    assert (auto.estimator.max_lags, auto.estimator.burn_in) == (math.floor(0.25 * rate + 0.5), round(rate))
    half = pipeline_config({"rate": rate, "estimator.lag_span": 0.5, "estimator.residual_burn_in_span": 0.1})
    assert (half.estimator.lags, half.estimator.burn_in) == (math.floor(0.5 * rate + 0.5), math.floor(0.1 * rate + 0.5))


def test_the_default_parameters_build_each_components_default_options():
    """The parameters' defaults go back into the options classes unchanged: every component of
    pipeline_config({}) is its class's default, the spans' seconds (1 s) the fields' samples at
    the default rate (50 lags), the residual burn-in's default resolved (0 with fixed lags)."""
    cfg = pipeline_config({})
    for name, cls in COMPONENTS:
        if name == "estimator":
            assert cfg.estimator == replace(EstimatorOptions(), residual_burn_in=0)
        elif name == "frequency":
            assert cfg.frequency is None and pipeline_config({"estimator.method": "both"}).frequency == \
                FrequencyOptions(rate_hz=cfg.rate)
        else:
            assert getattr(cfg, name) == cls(), name
    assert cfg.rate == PipelineConfig(T2).rate and cfg.models == PipelineConfig(T2).models
    assert cfg.aircraft == load_aircraft(parameter_defaults()["aircraft"])


def test_estimator_choices_are_the_estimators_own():
    spec = {p.name: p for p in PARAMETERS}
    assert spec["estimator.window"].choices == WINDOWS
    assert spec["estimator.residual"].choices == RESIDUALS
    for window in WINDOWS:
        assert pipeline_config({"estimator.window": window}).estimator.window == window
    for residual in RESIDUALS:
        assert pipeline_config({"estimator.residual": residual}).estimator.residual == residual


@pytest.mark.parametrize("build,match", [
    (lambda: EstimatorOptions(lags=-1), "estimator.lags"),
    (lambda: EstimatorOptions(lags=2.5), "estimator.lags"),
    (lambda: EstimatorOptions(window="hann"), "estimator.window"),
    (lambda: EstimatorOptions(forgetting=0.0), "estimator.forgetting"),
    (lambda: EstimatorOptions(forgetting=1.5), "estimator.forgetting"),
    (lambda: EstimatorOptions(residual="raw"), "estimator.residual"),
    (lambda: EstimatorOptions(residual_burn_in=-1), "estimator.residual_burn_in"),
    (lambda: EstimatorOptions(residual_burn_in=True), "estimator.residual_burn_in"),
    (lambda: EstimatorOptions(residual_burn_in=7.0), "estimator.residual_burn_in"),
    (lambda: InputConfig(max_gap=0.0), "inputs.max_gap"),
    (lambda: InputConfig(air_density=float("nan")), "inputs.air_density"),
    (lambda: InputConfig(buffer_duration=-1.0), "inputs.buffer_duration"),
    (lambda: InputConfig(frame_id=None), "inputs.frame_id"),
    (lambda: PlausibilityLimits(angular_rate=0.0), "limits.angular_rate"),
    (lambda: PlausibilityLimits(thrust=float("inf")), "limits.thrust"),
    (lambda: PlausibilityLimits(specific_force=True), "limits.specific_force"),
    (lambda: PlausibilityLimits(alpha=1.6), "limits.alpha"),
    (lambda: PlausibilityLimits(beta=2.0), "limits.beta"),
    (lambda: PlausibilityLimits(airspeed_min=50.0, airspeed_max=40.0), "limits.airspeed_min"),
    (lambda: PlausibilityLimits(dynamic_pressure_min=1e4, dynamic_pressure_max=1e4), "limits.dynamic_pressure_min"),
    (lambda: PipelineConfig(T2, rate=0.0), "rate"),
    (lambda: PipelineConfig(T2, models=()), "at least one model"),
    (lambda: PipelineConfig(T2, models=(ModelConfig("CZ", ("1",)), ModelConfig("CZ", ("alpha",)))), "twice"),
    (lambda: PipelineConfig(T2, rate=50.0, inputs=InputConfig(max_gap=0.01)), "max_gap"),
    (lambda: PipelineConfig(T2, surfaces=SurfaceMixing(rudder=())), "delta_r"),
])
def test_the_dataclasses_refuse_invalid_values_when_built_directly(build, match):
    with pytest.raises(ConfigError, match=match):
        build()


def test_fingerprint_is_what_a_state_file_stores():
    """The state file compares this dict as saved: its keys and layout must stay."""
    cfg = pipeline_config({"models.enabled": ["Cm"], "models.Cm": ["1", "q_hat"], "estimator.lag_span": 0.14})
    assert cfg.fingerprint() == {
        "aircraft": [getattr(T2, f.name) for f in dataclasses.fields(T2)],
        "models": [["Cm", "1", "q_hat"]],
        "rate": 50.0,
        "estimator": {"lags": 7, "window": "truncated", "forgetting": 1.0, "residual": "standardized", "max_lags": 50,
                      "min_lags": 0, "residual_burn_in": 0, "noise_forgetting": 1.0, "init_condition": 1e8, "p0": None,
                      "publish_lag_windows": 2.0, "algorithm": "rls", "small_sample": 0.0,
                      "iv_init_samples": 0},
    }
    assert pipeline_config({"inputs.max_gap": 0.5}).fingerprint() == pipeline_config({}).fingerprint()


def test_residual_burn_in_defaults_by_lag_selection_and_enters_the_fingerprint_resolved():
    """-1: 1 s (50 samples at 50 Hz) with lag_selection auto, 0 (the paper's Eq. 17) with fixed
    lags; the fingerprint holds the burn-in the bank uses, so the default and its value agree."""
    fixed, auto = pipeline_config({}), pipeline_config({"estimator.lag_selection": "auto"})
    assert (fixed.estimator.burn_in, auto.estimator.burn_in) == (0, 50)
    assert (fixed.fingerprint()["estimator"]["residual_burn_in"], auto.fingerprint()["estimator"]["residual_burn_in"]) \
        == (0, 50)
    explicit = pipeline_config({"estimator.lag_selection": "auto", "estimator.residual_burn_in_span": 1.0})
    assert explicit.fingerprint() == auto.fingerprint()
    assert pipeline_config({"estimator.lag_selection": "auto", "estimator.residual_burn_in_span": 0}).fingerprint() \
        != auto.fingerprint()
    twenty = pipeline_config({"estimator.residual_burn_in_span": 0.4})
    assert twenty.estimator.burn_in == 20 and twenty.fingerprint()["estimator"]["residual_burn_in"] == 20
    spec = {p.name: p for p in PARAMETERS}["estimator.residual_burn_in_span"]
    assert spec.default == -1 and (spec.low, spec.high) == (-1, 2000)
    assert [(x.seconds, x.meaning[:4]) for x in spec.specials] == [(-1.0, "1 s "), (0.0, "none")]


def test_plausibility_defaults_lie_between_any_flight_and_absurd_values():
    """Each default: beyond what the bundled T-2 maneuver and the three Twin Otter flights
    reach (measured maxima, rounded up: 0.37 rad/s, 15.2 m/s^2, 40.8..74 m/s, |alpha| 0.126,
    |beta| 0.118 rad, 981..2834 Pa, 0.122 rad of surface, 6.6 kN of thrust) by an order of
    magnitude or more, and below absurd values a corrupt recording may hold (1e100 rad/s, 1e150,
    1e-300 Pa, |alpha| near pi). The parameter ranges keep every setting in that band as well."""
    d = PlausibilityLimits()
    flight = {"angular_rate": 0.37, "specific_force": 15.2, "alpha": 0.126, "beta": 0.118, "surface": 0.122,
              "thrust": 6.6e3, "airspeed_max": 74.0, "dynamic_pressure_max": 2834.0}
    for name, reached in flight.items():
        assert getattr(d, name) >= 3 * reached, name
    assert d.airspeed_min <= 40.8 / 10 and d.dynamic_pressure_min <= 981.0 / 100
    assert d.alpha < 0.5 * 3.14159 and d.beta < 0.5 * 3.14159
    spec = {p.name: p for p in PARAMETERS}
    for f in dataclasses.fields(PlausibilityLimits):
        p = spec[f"limits.{f.name}"]
        assert p.default == getattr(d, f.name) and p.low <= p.default <= p.high
        assert p.high < 1e9 and p.low > 1e-3, p.name
        quantity = f.name.removesuffix("_min").removesuffix("_max")
        reason = "inconsistent_dynamic_pressure" if quantity == "air_density" else f"implausible_{quantity}"
        assert reason in p.description, p.name
    assert spec["limits.alpha"].high < 0.5 * 3.14159 and spec["limits.beta"].high < 0.5 * 3.14159
    # A dynamic pressure above the one of the top airspeed at sea level (so both limits agree).
    assert d.dynamic_pressure_max >= 0.5 * 1.225 * d.airspeed_max**2
    # The densities the flights imply (2 qbar / V^2: 1.001..1.035 for the Twin Otter, 1.177 for
    # the T-2) well inside; the bundled bag's angular accelerations (2.7 rad/s^2 at most between
    # IMU messages; the Twin Otter's 2.6) two orders of magnitude below the bound.
    assert d.air_density_min <= 1.0 / 10 and d.air_density_max >= 1.18 * 1.5
    assert d.angular_acceleration >= 100 * 2.7


# ------------------------------------------------------------------ the node's parameter sources
def _file(tmp_path, text, name="p.yaml"):
    path = tmp_path / name
    path.write_text(text)
    return str(path)


def _startup(*ros_args):
    return startup_parameters(["estimator_node", "--ros-args", *ros_args])


def _refused(*ros_args):
    with pytest.raises(ConfigError) as exc:
        _startup(*ros_args)
    return str(exc.value)


@pytest.mark.parametrize("args,needles", [
    (["-p", "estimator.lag_span:=-5.0"], ["parameter 'estimator.lag_span' must be -1 (keeps all lags (Eq. 20)), 0 "
                                          "(the conventional covariance) or a number of seconds in (0, 2000], got -5.0",
                                          "(from -p estimator.lag_span:=-5.0)"]),
    (["-p", "estimator.lags:=50"], ["-p estimator.lags:=50: unknown parameter 'estimator.lags' (renamed: "
                                    "estimator.lag_span, in seconds (lags / rate: 50 lags at 50 Hz = 1.0; "
                                    "-1 all lags))"]),
    (["-p", "rate:=fast"], ["rate must be a number in [1, 1000] Hz, got 'fast'", "(from -p rate:=fast)"]),
    (["-p", "estimator.window:=hann"], ["must be one of ['truncated', 'bartlett'], got 'hann'"]),
    (["-p", "differentiator.window:=9.5"], ["differentiator.window must be an integer in [3, 201] samples, got 9.5 "
                                            "(from -p differentiator.window:=9.5)"]),
    (["-p", "use_sim_time:=1"], ["parameter 'use_sim_time' must be true or false, got 1"]),
    (["-p", "estimator.lag:=20"], ["-p estimator.lag:=20: unknown parameter 'estimator.lag' "
                                   "(did you mean estimator.lag_span?)"]),
    (["-p", "colour:=red"], ["unknown parameter 'colour'"]),
    (["-p", "rls_estimator:estimator.lag:=20"], ["did you mean estimator.lag_span?"]),
    (["-p", "aircraft:=concorde"], ["concorde.yaml: no such file"]),
    (["-p", "inputs.max_gap:=1.0", "-p", "inputs.max_stamp_jump:=0.5"],
     ["inputs.max_stamp_jump", "(from -p inputs.max_stamp_jump:=0.5)"]),
    (["-p", "intake_period:=0.05"], ["intake_period 0.05 s is longer than the estimator period at rate 50 Hz (0.02 s)",
                                     "(from -p intake_period:=0.05)"]),
    (["--params-file", "missing.yaml"], ["parameter file missing.yaml: no such file"]),
    (["--foo"], ["unknown ROS argument '--foo'"]),
])
def test_a_bad_start_up_parameter_is_refused_naming_it_and_its_source(args, needles):
    message = _refused(*args)
    assert all(n in message for n in needles) and "\n" not in message, message


def test_an_argument_outside_ros_args_is_refused():
    with pytest.raises(ConfigError, match="unexpected argument"):
        startup_parameters(["estimator_node", "-p", "rate:=100.0"])
    assert startup_parameters(["estimator_node"]).values == {}
    assert startup_parameters([]).values == {}


def test_start_up_values_are_converted_to_the_parameters_types(tmp_path):
    """An integer for a floating-point parameter is that number, as the replay reads it."""
    values = _startup("-p", "rate:=100", "-p", "estimator.forgetting:=1", "-p", "models.enabled:=[CZ, Cm]").values
    assert values == {"rate": 100.0, "estimator.forgetting": 1.0, "models.enabled": ["CZ", "Cm"]}
    assert type(values["rate"]) is float


def test_a_section_naming_the_node_refuses_unknown_names(tmp_path):
    for key in ("rls_estimator", "/rls_estimator"):
        path = _file(tmp_path, f"{key}:\n  ros__parameters:\n    estimator:\n      lag: 20\n")
        message = _refused("--params-file", path)
        assert f"parameter file {path}:4:7, section {key}: unknown parameter 'estimator.lag' " \
               "(did you mean estimator.lag_span?)" in message
    path = _file(tmp_path, "x:\n  rls_estimator:\n    ros__parameters:\n      rat: 20.0\n")
    assert "did you mean rate?" in _refused("-r", "__ns:=/x", "--params-file", path)


def test_a_wildcard_section_refuses_names_of_the_nodes_groups_and_warns_about_others(tmp_path):
    assert "unknown parameter 'estimator.lag'" in _refused("--params-file", _file(
        tmp_path, "/**:\n  ros__parameters:\n    estimator.lag: 20\n"))
    assert "did you mean aircraft?" in _refused("--params-file", _file(
        tmp_path, "/**:\n  ros__parameters:\n    aircraf: t2\n"))
    path = _file(tmp_path, "/**:\n  ros__parameters:\n    estimator.lag_span: 0.4\n    speed: 3\n"
                           "    use_sim_time: true\n    qos_overrides./clock.subscription.depth: 5\n")
    params = _startup("--params-file", path)
    assert params.values == {"estimator.lag_span": 0.4, "use_sim_time": True,
                             "qos_overrides./clock.subscription.depth": 5}
    assert params.warnings == (f"parameter file {path}, section /**: parameters that are not this node's ignored "
                               "(meant for other nodes?): speed",)


def test_a_file_with_no_section_for_the_node_is_refused(tmp_path):
    path = _file(tmp_path, "rls_estimatr:\n  ros__parameters:\n    estimator:\n      lags: 20\n")
    assert _refused("--params-file", path) == (
        f"parameter file {path}: no section for node /rls_estimator (it has sections for rls_estimatr; did you mean "
        "rls_estimator?); name the node (rls_estimator, /NAMESPACE/rls_estimator) or use a wildcard (/**)")
    # Sections for the node in another namespace, or renamed, do not apply either.
    path = _file(tmp_path, "/x/rls_estimator:\n  ros__parameters:\n    rate: 20.0\n")
    assert "no section for node /rls_estimator" in _refused("--params-file", path)
    assert "no section for node /y/rls_estimator" in _refused("-r", "__ns:=/y", "--params-file", path)
    assert "no section for node /x/renamed" in _refused("-r", "__ns:=/x", "-r", "__node:=renamed", "--params-file",
                                                        path)
    assert _startup("-r", "__ns:=/x", "--params-file", path).values == {"rate": 20.0}
    assert "no 'NODE: ros__parameters:' section" in _refused("--params-file", _file(tmp_path, "# empty\n"))


def test_sections_and_rules_for_other_nodes_are_one_warning_each(tmp_path):
    path = _file(tmp_path, "rls_estimator:\n  ros__parameters:\n    rate: 20.0\nplanner:\n  ros__parameters:\n"
                           "    speed: 3\nmapper:\n  ros__parameters:\n    size: 3\n")
    params = _startup("--params-file", path, "-p", "planner:speed:=4")
    assert params.values == {"rate": 20.0}
    assert params.warnings == (f"parameter file {path}: sections for other nodes ignored: planner, mapper",
                               "-p planner:speed:=4: for node /planner, not /rls_estimator: ignored")


def test_the_replay_reads_a_file_as_the_node_in_any_namespace(tmp_path):
    path = _file(tmp_path, "/x/rls_estimator:\n  ros__parameters:\n    rate: 20\nplanner:\n  ros__parameters:\n"
                           "    speed: 3\n")
    with pytest.warns(UserWarning, match="sections for other nodes ignored: planner"):
        assert load_parameters_file(path) == {"rate": 20.0}
    path = _file(tmp_path, "rls_estimatr:\n  ros__parameters:\n    rate: 20.0\n")
    with pytest.raises(ConfigError, match="no section for node rls_estimator"):
        load_parameters_file(path)
    path = _file(tmp_path, "rls_estimator:\n  ros__parameters:\n    estimator.lag: 20\n")
    with pytest.raises(ConfigError, match=r"did you mean estimator\.lag_span"):
        load_parameters_file(path)


def test_the_value_that_wins_is_the_one_rcl_gives_the_node(tmp_path):
    """A section naming the node that rcl filed before /** keeps /**'s later values from winning
    (ros_arguments.in_rcl_order; the rcl oracle is in test_ros_arguments.py)."""
    path = _file(tmp_path, "/**:\n  ros__parameters:\n    rate: 40.0\nrls_estimator:\n  ros__parameters:\n"
                           "    rate: 30.0\n")
    assert _startup("--params-file", path, "-p", "rate:=20.0").values["rate"] == 30.0
    assert _startup("-p", "rate:=20.0", "--params-file", path).values["rate"] == 30.0
    assert _startup("--params-file", path, "-p", "rls_estimator:rate:=20.0").values["rate"] == 20.0


def test_a_key_given_twice_or_a_parameter_spelled_twice_is_refused_naming_both_places(tmp_path):
    """YAML leaves a repeated key to the reader (PyYAML keeps the last in silence); a dotted name
    beside the same name nested is the same parameter twice: both are refused in one line with
    the file, line and column, whichever value is first."""
    path = _file(tmp_path, "rls_estimator:\n  ros__parameters:\n    rate: 5000.0\n    rate: 50.0\n")
    assert _refused("--params-file", path) == (
        f"parameter file {path}:4:5: not valid YAML: key 'rate' given twice (first at line 3, column 5); give it once")
    for first, second in (("estimator.lag_span: 0.4", "estimator:\n      lag_span: 0.6"),
                          ("estimator:\n      lag_span: 0.6", "estimator.lag_span: 0.4")):
        path = _file(tmp_path, f"rls_estimator:\n  ros__parameters:\n    {first}\n    {second}\n")
        message = _refused("--params-file", path)
        assert message.startswith(f"parameter file {path}:") and "parameter estimator.lag_span given twice in " \
            "section /rls_estimator (first at line " in message and "\n" not in message, message
    # Two files, or a file and a -p rule, are two sources: the later one wins, as in rcl.
    one = _file(tmp_path, "rls_estimator:\n  ros__parameters:\n    rate: 40.0\n", "one.yaml")
    two = _file(tmp_path, "rls_estimator:\n  ros__parameters:\n    rate: 30.0\n", "two.yaml")
    assert _startup("--params-file", one, "--params-file", two).values["rate"] == 30.0


def test_a_value_refused_by_its_options_class_names_its_file_line_and_column(tmp_path):
    path = _file(tmp_path, "rls_estimator:\n  ros__parameters:\n    inputs:\n      max_gap: 20.0\n")
    assert _refused("--params-file", path) == ("inputs.max_gap must be a number in [0.001, 10] s, got 20.0 (from "
                                               f"parameter file {path}:4:7, section rls_estimator)")


# ------------------------------------------------------------------ the console script
def _run_node(*ros_args):
    return subprocess.run([sys.executable, "-m", "rls_uncertainty.ros.node", "--ros-args", *ros_args],
                          capture_output=True, text=True, timeout=120, cwd=ROOT)


@pytest.mark.parametrize("args,needle", [
    (["-p", "estimator.lag_span:=-5.0"], "parameter 'estimator.lag_span' must be -1 (keeps all lags (Eq. 20)), 0"),
    (["-p", "rate:=fast"], "rate must be a number in [1, 1000] Hz, got 'fast'"),
    (["--params-file", "missing.yaml"], "parameter file missing.yaml: no such file"),
    (["--params-file", "{malformed}"], "m.yaml:4:1: not valid YAML: expected ',' or ']', but got '<stream end>'"),
    (["-p", "estimator.lag:=20"], "did you mean estimator.lag_span?"),
    (["--params-file", "{section}"], "no section for node /rls_estimator"),
])
def test_the_node_refuses_a_misconfiguration_in_one_line_with_exit_status_2(tmp_path, args, needle):
    files = {"malformed": _file(tmp_path, "rls_estimator:\n  ros__parameters:\n    rate: [1, 2\n", "m.yaml"),
             "section": _file(tmp_path, "rls_estimatr:\n  ros__parameters:\n    rate: 20.0\n", "s.yaml")}
    run = _run_node(*(a.format(**files) for a in args))
    assert run.returncode == 2, run.stderr
    assert run.stderr.startswith("rls_estimator: invalid configuration: ") and needle in run.stderr, run.stderr
    assert len(run.stderr.splitlines()) == 1 and run.stdout == ""


def test_the_node_starts_with_checked_values_and_logs_each_warning_once(tmp_path):
    path = _file(tmp_path, "/**:\n  ros__parameters:\n    rate: 100\n    speed: 3\nplanner:\n  ros__parameters:\n"
                           "    speed: 3\n")
    log = tmp_path / "node.log"
    with open(log, "w") as fh:
        proc = subprocess.Popen([sys.executable, "-m", "rls_uncertainty.ros.node", "--ros-args", "--params-file", path],
                                stdout=fh, stderr=subprocess.STDOUT, cwd=ROOT)
    try:
        deadline = time.monotonic() + 120
        while log.read_text().count("WARN") < 2 and proc.poll() is None and time.monotonic() < deadline:
            time.sleep(0.1)
        text = log.read_text()
        assert proc.poll() is None, text  # running: an integer rate is the number 100.0
        assert "at 100 Hz" in text
        warnings_ = [line for line in text.splitlines() if "WARN" in line]
        assert len(warnings_) == 2 and "ignored: planner" in warnings_[0] and "ignored (meant for other nodes?): " \
               "speed" in warnings_[1], text
    finally:
        proc.send_signal(signal.SIGINT)
        try:
            proc.wait(30)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()


def test_what_only_rcl_refuses_is_still_one_line_of_ours_and_exit_status_2():
    """A remap rule rcl cannot read (the start-up check reads parameters, not topic names): rcl
    logs its own error line, then the node says why in one line; no traceback."""
    run = _run_node("-r", "imu:=bad:name")
    assert run.returncode == 2 and "Traceback" not in run.stderr, run.stderr
    assert run.stderr.splitlines()[-1].startswith("rls_estimator: invalid configuration: ") and "imu:=bad:name" in \
        run.stderr.splitlines()[-1]


def test_parameter_files_are_matched_against_the_name_the_node_runs_under():
    from rls_uncertainty.ros import node
    assert NODE_NAME == node.NODE_NAME


def test_every_frequency_parameter_reaches_its_option():
    """``estimator.method`` frequency or both builds :class:`FrequencyOptions` from the
    ``frequency.*`` parameters (the spans are samples at the rate, rounded: 0.5 s trim at 50 Hz
    is 25 samples, 0 the first sample; 0.3 s of lags 15); ``time`` builds none and ignores them,
    so a grid beyond a low rate's Nyquist frequency does not stop a time-domain user."""
    default = pipeline_config({})
    assert (default.method, default.frequency, default.published_methods) == ("time", None, ("time",))
    both = pipeline_config({"estimator.method": "both"})
    assert both.published_methods == ("time", "frequency")
    assert both.frequency == FrequencyOptions(rate_hz=50.0)  # the defaults of the table are the options'
    assert pipeline_config({"estimator.method": "frequency"}).published_methods == ("frequency",)
    changed = {
        "frequency.f_min": ("f_min", 0.2, 0.2),
        "frequency.f_max": ("f_max", 2.2, 2.2),
        "frequency.f_step": ("f_step", 0.05, 0.05),
        "frequency.trim_span": ("trim_samples", 0.5, 25),
        "frequency.lag_span": ("n_lags", 0.3, 15),
        "frequency.every": ("every", 5, 5),
    }
    assert sorted(changed) == sorted(p.name for p in PARAMETERS if p.name.startswith("frequency."))
    for name, (attr, value, want) in changed.items():
        cfg = pipeline_config({"estimator.method": "both", name: value})
        assert cfg.frequency is not None and getattr(cfg.frequency, attr) == want, name
        assert replace(cfg.frequency, **{attr: getattr(both.frequency, attr)}) == both.frequency, name
    assert pipeline_config({"estimator.method": "both", "frequency.lag_span": 0.0}).frequency.n_lags == 0
    # One publication rule for both methods: estimator.publish_lag_windows reaches both banks' options.
    rule = pipeline_config({"estimator.method": "both", "estimator.publish_lag_windows": 3.5})
    assert rule.frequency.publish_lag_windows == rule.estimator.publish_lag_windows == 3.5
    assert pipeline_config({"estimator.method": "both", "rate": 100.0}).frequency.rate_hz == 100.0
    # Nyquist 1 Hz: the default grid reaches 1.5 Hz. (Force models only: no differentiator passes
    # the moment models' angular accelerations up to 1.5 Hz at 2 Hz, refused on its own.)
    low = {"rate": 2.0, "inputs.max_gap": 1.0, "models.enabled": ["CX", "CY", "CZ"]}
    assert pipeline_config(low).frequency is None
    with pytest.raises(ConfigError, match=r"frequency\.f_max must stay below the Nyquist frequency rate / 2 = 1\.0"):
        pipeline_config({**low, "estimator.method": "frequency"})
    values = {**parameter_defaults(), "estimator.method": "both", "frequency.trim_span": 0.001}
    with pytest.raises(ConfigError, match=r"'frequency\.trim_span' = 0\.001 s is less than one sample"):
        frequency_options(values, 50.0)


def test_t2_file_sets_the_grid_of_table_2_and_the_twin_otter_files_keep_the_default():
    """config/t2.yaml: 0.2-2.2 Hz every 0.04 Hz (Table 2's multisines; docs/frequency.md) and
    the half second before the input as trim; the Twin Otter files the default grid."""
    t2 = pipeline_config({**load_parameters_file("t2"), "estimator.method": "both"}).frequency
    assert (t2.f_min, t2.f_max, t2.f_step, t2.trim_samples, t2.n_lags) == (0.2, 2.2, 0.04, 25, 50)
    assert t2.frequencies().size == 51
    for name in ("twin_otter_lateral", "twin_otter_longitudinal"):
        cfg = pipeline_config({**load_parameters_file(name), "estimator.method": "both"})
        # The default grid; 1 s of lags at the recording's rate (9752ed20: 100 Hz).
        assert cfg.frequency == FrequencyOptions(rate_hz=cfg.rate, n_lags=round(cfg.rate)), name


@pytest.mark.parametrize(
    ("params", "match"),
    [
        ({"estimator.method": "fourier"}, r"estimator\.method must be one of \['time', 'frequency', 'both'\]"),
        ({"estimator.method": "both", "models.enabled": ["CX"], "models.CX": ["1"]},
         r"model CX has no regressor but the bias '1'.*models\.CX.*estimator\.method: time"),
        ({"estimator.method": "both", "frequency.f_min": 0.5, "frequency.f_max": 0.6},
         r"grid .* has 3 frequencies, a model 5 frequency-domain parameters.*frequency\.f_step"),
        ({"estimator.method": "frequency", "frequency.f_step": 1e-4}, r"frequency\.f_step .* more than 1000"),
        ({"estimator.method": "frequency", "frequency.f_max": 0.05}, r"frequency\.f_max must be >= f_min"),
        ({"estimator.method": "frequency", "frequency.trim_span": 250.0},
         r"'frequency\.trim_span' must be 0 \(the first sample\) or a number of seconds in \(0, 200\], got 250\.0"),
        ({"estimator.method": "frequency", "frequency.every": 0},
         r"frequency\.every must be an integer in \[1, 1000000\] samples, got 0"),
    ],
)
def test_frequency_settings_are_refused_naming_the_parameter(params, match):
    with pytest.raises(ConfigError, match=match):
        pipeline_config(params)


def test_a_pipeline_config_built_directly_keeps_method_and_options_in_agreement():
    with pytest.raises(ConfigError, match=r"estimator\.method both needs frequency options"):
        PipelineConfig(aircraft=T2, method="both")
    with pytest.raises(ConfigError, match=r"estimator\.method time needs frequency options exactly"):
        PipelineConfig(aircraft=T2, frequency=FrequencyOptions(rate_hz=50.0))
    with pytest.raises(ConfigError, match=r"frequency options at 100\.0 Hz for a pipeline at rate 50\.0 Hz"):
        PipelineConfig(aircraft=T2, method="both", frequency=FrequencyOptions(rate_hz=100.0))
