"""In-process replays for tests (rls_uncertainty/testing/offline.py): replay_bag is the
replay's pipeline, read as a stream, every sample kept; parameters are named as the node
names them, or with __ for the dots. No ROS."""

import numpy as np
import pytest

from rls_uncertainty.errors import ConfigError
from rls_uncertainty.offline.bags import read_inputs
from rls_uncertainty.offline.replay import run_pipeline
from rls_uncertainty.settings import load_parameters_file, pipeline_config
from rls_uncertainty.testing import parameters, replay_bag

from conftest import ROOT

BUNDLED = ROOT / "bags" / "t2_maneuver"


@pytest.fixture(scope="module")
def listed():
    """The bundled bag as a list through run_pipeline: every SampleOutput kept."""
    return run_pipeline(read_inputs(BUNDLED)[0], pipeline_config(load_parameters_file("t2")))


def test_replay_bag_gives_every_sample_of_the_pipeline(listed):
    result = replay_bag(BUNDLED, "t2")
    assert result.parameters == tuple(p for names in listed.pipeline.parameter_names for p in names)
    assert result.estimates == listed.estimates and result.outputs == []  # series kept, SampleOutputs not
    for j, names in enumerate(listed.pipeline.parameter_names):
        ready = [o for o in listed.outputs if o.ready[j]]
        for i, name in enumerate(names):
            s = result.series(name)
            assert np.array_equal(s.stamps_ns, [o.stamp_ns for o in ready])
            for got, field in ((s.estimates, "theta"), (s.std_errors, "se"),
                               (s.std_errors_conventional, "se_conventional"), (s.converged, "converged")):
                assert np.array_equal(got, [getattr(o, field)[j, i] for o in ready]), (name, field)
            f = result.final(name)
            last = ready[-1]
            assert (f.estimate, f.std_error, f.std_error_conventional, f.converged, f.stamp_ns) == (
                last.theta[j, i], last.se[j, i], last.se_conventional[j, i], bool(last.converged[j, i]), last.stamp_ns)
    counters = listed.pipeline.counters()
    got = result.counters()
    assert got["samples_used"] == counters["samples_used"] and got["samples_rejected"] == counters["samples_rejected"]
    assert {k: v["received"] for k, v in got["streams"].items()} == {
        k: v["received"] for k, v in counters["streams"].items()}
    assert result.bag_digest and result.n_messages == 4920


def test_overrides_name_parameters_with_dots_or_double_underscores():
    a = replay_bag(BUNDLED, "t2", estimator__lag_span=0.4, models__enabled=["Cm"])
    b = replay_bag(BUNDLED, {**load_parameters_file("t2"), "estimator.lag_span": 0.4, "models.enabled": ["Cm"]})
    assert a.parameters == b.parameters == ("Cm_0", "Cm_alpha", "Cm_q", "Cm_delta_e")
    assert a.final("Cm_q") == b.final("Cm_q") != replay_bag(BUNDLED, "t2").final("Cm_q")
    assert parameters(None, {"rate": 25.0}) == {"rate": 25.0}


@pytest.mark.parametrize("config,overrides,needle", [
    ("t2", {"estimator__lag": 5}, "unknown parameter(s) ['estimator.lag']"),
    ({"estimatr.lags": 5}, {}, "estimatr.lags"),
    ("t2", {"estimator__lag_span": -5}, "estimator.lag_span"),
    ("no_such_file", {}, "no_such_file"),
])
def test_a_bad_parameter_is_refused_before_any_bag_is_read(config, overrides, needle):
    with pytest.raises((ConfigError, OSError)) as exc:
        replay_bag(ROOT / "missing_bag", config, **overrides)
    assert needle in str(exc.value)


def test_a_span_and_leniency_are_the_replays():
    whole = replay_bag(BUNDLED, "t2")
    part = replay_bag(BUNDLED, "t2", start=2.0, end=9.0)
    t0 = read_inputs(BUNDLED)[1]
    s = part.series("CZ_0").stamps_ns
    assert s.min() >= t0 + 2 * 10**9 and s.max() <= t0 + 9 * 10**9 and part.estimates < whole.estimates
    assert replay_bag(BUNDLED, "t2", strict=False).final("Cm_q") == whole.final("Cm_q")
