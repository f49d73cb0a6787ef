"""Typed configuration: aircraft and model files, the parameter table, the nested
PipelineConfig built from dotted parameters, and every validation with its reason."""

import dataclasses

import pytest

from rls_uncertainty.config import (
    PARAMETERS,
    ConfigError,
    EstimatorOptions,
    InputConfig,
    ModelConfig,
    PipelineConfig,
    PlausibilityLimits,
    load_aircraft,
    load_models,
    load_parameters_file,
    parameter_defaults,
    pipeline_config,
)
from rls_uncertainty.differentiation import DifferentiatorConfig
from rls_uncertainty.estimator import RESIDUALS, WINDOWS
from rls_uncertainty.surface_mixing import SurfaceMixing

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
    ({"estimator.lags": -2}, "estimator.lags"),
    ({"estimator.residual_burn_in": -2}, "estimator.residual_burn_in"),
    ({"estimator.residual_burn_in": 2.5}, "estimator.residual_burn_in"),
    ({"estimator.residual_burn_in": 100001}, "estimator.residual_burn_in"),
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


@pytest.mark.parametrize("name", ["t2", "twin_otter_lateral", "twin_otter_longitudinal"])
def test_shipped_parameter_files_are_valid(name):
    cfg = pipeline_config(load_parameters_file(name))
    assert cfg.models


def test_every_parameter_reaches_its_nested_field():
    """Each pipeline parameter, set to a non-default value, changes exactly the field of the
    same name in its section (``estimator.lags`` -1 is ``"all"``, ``estimator.lag_selection``
    auto is ``lags="auto"``: :func:`.config.estimator_options`)."""
    changed = {
        "rate": ("rate", 100.0),
        "estimator.lags": (("estimator", "lags"), 11),
        "estimator.window": (("estimator", "window"), "bartlett"),
        "estimator.forgetting": (("estimator", "forgetting"), 0.99),
        "estimator.residual": (("estimator", "residual"), "a_priori"),
        "estimator.lag_selection": (("estimator", "lags"), "auto"),
        "estimator.max_lags": (("estimator", "max_lags"), 80),
        "estimator.residual_burn_in": (("estimator", "residual_burn_in"), 20),
        "differentiator.window": (("differentiator", "window"), 11),
        "differentiator.order": (("differentiator", "order"), 2),
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
    }
    sections = {"rate", "estimator", "differentiator", "inputs", "surfaces", "limits"}
    pipeline_params = [p.name for p in PARAMETERS if p.name.split(".")[0] in sections]
    assert sorted(changed) == sorted(pipeline_params)
    default = pipeline_config({})
    for name, (where, value) in changed.items():
        cfg = pipeline_config({name: value})
        if isinstance(where, str):
            assert getattr(cfg, where) == value
            assert dataclasses.replace(cfg, **{where: getattr(default, where)}) == default
            continue
        section, attr = where
        got = getattr(getattr(cfg, section), attr)
        assert got == (tuple(value) if isinstance(value, list) else value), name
        # Nothing else changed.
        restored = dataclasses.replace(getattr(cfg, section), **{attr: getattr(getattr(default, section), attr)})
        assert dataclasses.replace(cfg, **{section: restored}) == default, name
    assert pipeline_config({"estimator.lags": -1}).estimator.lags == "all"
    assert pipeline_config({"estimator.residual_burn_in": -1}).estimator.residual_burn_in is None


def test_defaults_of_the_table_and_the_dataclasses_agree():
    cfg = pipeline_config({})
    d = parameter_defaults()
    assert cfg.estimator == EstimatorOptions() and cfg.estimator.lags == d["estimator.lags"]
    assert cfg.differentiator == DifferentiatorConfig()
    assert cfg.inputs == InputConfig()
    assert cfg.surfaces == SurfaceMixing()
    assert cfg.limits == PlausibilityLimits()
    assert cfg.rate == d["rate"] == PipelineConfig(T2).rate


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
    cfg = pipeline_config({"models.enabled": ["Cm"], "models.Cm": ["1", "q_hat"], "estimator.lags": 7})
    assert cfg.fingerprint() == {
        "aircraft": [getattr(T2, f.name) for f in dataclasses.fields(T2)],
        "models": [["Cm", "1", "q_hat"]],
        "rate": 50.0,
        "estimator": {"lags": 7, "window": "truncated", "forgetting": 1.0, "residual": "standardized", "max_lags": 50,
                      "min_lags": 0, "residual_burn_in": 0, "noise_forgetting": 1.0, "init_condition": 1e8, "p0": None},
    }
    assert pipeline_config({"inputs.max_gap": 0.5}).fingerprint() == pipeline_config({}).fingerprint()


def test_residual_burn_in_defaults_by_lag_selection_and_enters_the_fingerprint_resolved():
    """-1 (None): 50 samples with lag_selection auto, 0 (the paper's Eq. 17) with fixed lags;
    the fingerprint holds the burn-in the bank uses, so the default and its value agree."""
    fixed, auto = pipeline_config({}), pipeline_config({"estimator.lag_selection": "auto"})
    assert (fixed.estimator.burn_in, auto.estimator.burn_in) == (0, 50)
    assert (fixed.fingerprint()["estimator"]["residual_burn_in"], auto.fingerprint()["estimator"]["residual_burn_in"]) \
        == (0, 50)
    explicit = pipeline_config({"estimator.lag_selection": "auto", "estimator.residual_burn_in": 50})
    assert explicit.fingerprint() == auto.fingerprint()
    assert pipeline_config({"estimator.lag_selection": "auto", "estimator.residual_burn_in": 0}).fingerprint() \
        != auto.fingerprint()
    twenty = pipeline_config({"estimator.residual_burn_in": 20})
    assert twenty.estimator.burn_in == 20 and twenty.fingerprint()["estimator"]["residual_burn_in"] == 20
    spec = {p.name: p for p in PARAMETERS}["estimator.residual_burn_in"]
    assert spec.default == -1 and (spec.low, spec.high) == (-1, 100000) and "-1: 50" in spec.description


def test_plausibility_defaults_lie_between_any_flight_and_absurd_values():
    """Each default: beyond what the bundled T-2 maneuver and the three Twin Otter flights
    reach (measured maxima, rounded up: 0.37 rad/s, 15.2 m/s^2, 40.8..74 m/s, |alpha| 0.126,
    |beta| 0.118 rad, 981..2834 Pa, 0.122 rad of surface, 6.6 kN of thrust) by an order of
    magnitude or more, and below the values of issue 12 (1e100 rad/s, 1e150, 1e-300 Pa,
    |alpha| near pi). The parameter ranges keep every setting in that band as well."""
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
        assert f"implausible_{f.name.removesuffix('_min').removesuffix('_max')}" in p.description
    assert spec["limits.alpha"].high < 0.5 * 3.14159 and spec["limits.beta"].high < 0.5 * 3.14159
    # A dynamic pressure above the one of the top airspeed at sea level (so both limits agree).
    assert d.dynamic_pressure_max >= 0.5 * 1.225 * d.airspeed_max**2
