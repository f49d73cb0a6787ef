"""The estimator's options (estimator/options.py): validated once, with one error type naming
the option; the resolved defaults against their definitions; the round trip of the state file."""

from __future__ import annotations

import json

import numpy as np
import pytest

from rls_uncertainty.errors import ConfigError
from rls_uncertainty.estimator import EstimatorBank, EstimatorOptions, RecursiveEstimator
from rls_uncertainty.estimator.reference import RecursiveReference


@pytest.mark.parametrize(
    "kwargs, match",
    [
        (dict(lags=-1), r"estimator.lags must be an integer in \[0, 100000\], 'all' or 'auto', got -1"),
        (dict(lags=100_001), r"estimator\.lags must be"),
        (dict(lags=2.5), r"estimator\.lags must be"),
        (dict(lags=True), r"estimator\.lags must be"),
        (dict(lags=None), r"estimator\.lags must be"),
        (dict(lags="automatic"), r"estimator\.lags must be .* got 'automatic'"),
        (dict(window="hann"), r"estimator\.window must be one of \['truncated', 'bartlett'\], got 'hann'"),
        (dict(lags="auto", window="bartlett"), r"estimator\.window must be 'truncated' with automatic lags"),
        (dict(forgetting=0.0), r"estimator\.forgetting must be a number in \[0\.5, 1\], got 0\.0"),
        (dict(forgetting=0.49), r"estimator\.forgetting must be"),
        (dict(forgetting=1.5), r"estimator\.forgetting must be"),
        (dict(forgetting=float("nan")), r"estimator\.forgetting must be"),
        (dict(forgetting="0.99"), r"estimator\.forgetting must be"),
        (dict(residual="both"), r"estimator\.residual must be one of"),
        (dict(max_lags=0), r"estimator\.max_lags must be an integer in \[1, 100000\] samples, got 0"),
        (dict(max_lags=2.5), r"estimator\.max_lags must be"),
        (dict(min_lags=51), r"estimator\.min_lags must be an integer in \[0, max_lags = 50\], got 51"),
        (dict(min_lags=-1), r"estimator\.min_lags must be"),
        (dict(residual_burn_in=-1), r"estimator\.residual_burn_in must be None \(the default"),
        (dict(residual_burn_in=2.5), r"estimator\.residual_burn_in must be"),
        (dict(residual_burn_in="50"), r"estimator\.residual_burn_in must be"),
        (dict(residual_burn_in=True), r"estimator\.residual_burn_in must be"),
        (dict(residual_burn_in=100_001), r"\[0, 100000\], got 100001"),
        (dict(forgetting=0.98, noise_forgetting=0.97), r"estimator\.noise_forgetting must be None or a number in "
                                                       r"\[forgetting, 1\] = \[0\.98, 1\], got 0\.97"),
        (dict(forgetting=0.98, noise_forgetting=1.01), r"estimator\.noise_forgetting must be"),
        (dict(noise_forgetting=0.99), r"estimator\.noise_forgetting must be"),  # f = 1: only f_R = 1
        (dict(init_condition=1.0), r"estimator\.init_condition must be a number > 1"),
        (dict(p0=-1.0), r"estimator\.p0 must be None, a positive number or a sequence of them, got -1\.0"),
        (dict(p0=()), r"estimator\.p0 must be"),
        (dict(p0=(1.0, float("inf"))), r"estimator\.p0 must be"),
        (dict(p0="1"), r"estimator\.p0 must be"),
    ],
)
def test_an_invalid_option_is_refused_once_naming_it(kwargs, match):
    """One error type (ConfigError, a ValueError) with the option's name as the user writes it;
    the bank, the reference and the single estimator take the object and check nothing more."""
    with pytest.raises(ConfigError, match=match):
        EstimatorOptions(**kwargs)


def test_values_are_normalised_and_the_object_is_frozen():
    o = EstimatorOptions(lags=np.int64(7), forgetting=1, max_lags=np.int32(9), p0=[1, 2.5])
    assert (o.lags, o.forgetting, o.max_lags, o.p0) == (7, 1.0, 9, (1.0, 2.5))
    assert type(o.lags) is int and type(o.forgetting) is float and type(o.max_lags) is int
    with pytest.raises(AttributeError):
        o.lags = 5  # type: ignore[misc]
    assert EstimatorOptions(lags=7) == EstimatorOptions(lags=np.int64(7))


def test_resolved_values_follow_their_definitions():
    """held: the lags kept in memory; burn_in: 50 with automatic lags, 0 (Eq. 17) otherwise;
    f_R: max(f, 1 - 1/(40 (held + 1))), f itself with f = 1 or all lags."""
    assert [EstimatorOptions(lags=x, max_lags=30).held for x in (5, 0, "auto", "all")] == [5, 0, 30, None]
    assert [EstimatorOptions(lags=x).burn_in for x in ("auto", 5, 0, "all")] == [50, 0, 0, 0]
    assert EstimatorOptions(lags="auto", residual_burn_in=0).burn_in == 0
    assert EstimatorOptions(lags=50, forgetting=0.98).noise_forgetting_used == 1.0 - 1.0 / 2040.0
    assert EstimatorOptions(lags=50, forgetting=0.9999).noise_forgetting_used == 0.9999
    assert EstimatorOptions(lags=0, forgetting=0.98).noise_forgetting_used == 0.98  # 1 - 1/40 < f
    assert EstimatorOptions(lags="all", forgetting=0.98).noise_forgetting_used == 0.98
    assert EstimatorOptions(lags="auto", max_lags=20, forgetting=0.98).noise_forgetting_used == 1.0 - 1.0 / 840.0
    assert EstimatorOptions(lags=50).noise_forgetting_used == 1.0
    assert EstimatorOptions(lags=50, forgetting=0.98, noise_forgetting=0.99).noise_forgetting_used == 0.99
    assert [EstimatorOptions(lags=50, forgetting=f).noise_model for f in (1.0, 0.98)] == [False, True]
    assert not EstimatorOptions(lags=50, forgetting=0.98, noise_forgetting=0.98).noise_model
    np.testing.assert_array_equal(EstimatorOptions(p0=2.0).prior(3), [2.0, 2.0, 2.0])
    np.testing.assert_array_equal(EstimatorOptions(p0=(1.0, 2.0)).prior(2), [1.0, 2.0])
    assert EstimatorOptions().prior(3) is None
    with pytest.raises(ConfigError, match=r"estimator\.p0 must be a number or have 3 entries"):
        EstimatorBank((3, 2), EstimatorOptions(p0=(1.0, 2.0)))


@pytest.mark.parametrize("options", [
    EstimatorOptions(),
    EstimatorOptions(lags="all", window="bartlett", forgetting=0.97, residual="a_priori", p0=(1.0, 2.0, 3.0)),
    EstimatorOptions(lags="auto", max_lags=20, min_lags=2, forgetting=0.99, noise_forgetting=0.995),
    EstimatorOptions(lags=0, residual_burn_in=30, init_condition=1e6, p0=10.0),
])
def test_as_dict_survives_json_and_gives_back_an_equal_object(options):
    """as_dict is what the state file stores; from_dict of its JSON text is an equal object, and
    its resolved form (the defaults filled in) runs the same estimator bit for bit."""
    back = EstimatorOptions.from_dict(json.loads(json.dumps(options.as_dict())))
    assert back == options and back.resolved() == options.resolved()
    assert back.resolved().burn_in == options.burn_in
    assert back.resolved().noise_forgetting_used == options.noise_forgetting_used
    rng = np.random.default_rng(0)
    a, b = EstimatorBank((3,), options), EstimatorBank((3,), back.resolved())
    for _ in range(60):
        x, z = rng.standard_normal((1, 3)), rng.standard_normal(1)
        a.update(x, z)
        b.update(x, z)
    assert a.standard_errors_all().tobytes() == b.standard_errors_all().tobytes()


def test_two_objects_that_run_the_same_estimator_resolve_to_equal_ones():
    assert EstimatorOptions(lags="auto").resolved() == EstimatorOptions(lags="auto", residual_burn_in=50).resolved()
    assert EstimatorOptions(forgetting=0.98).resolved() == EstimatorOptions(
        forgetting=0.98, noise_forgetting=1.0 - 1.0 / 2040.0).resolved()
    assert EstimatorOptions(lags=5).resolved() != EstimatorOptions(lags=5, residual_burn_in=3).resolved()
    assert EstimatorOptions(lags="auto").resolved().residual_burn_in == 50


def test_from_dict_refuses_missing_and_unknown_keys():
    values = EstimatorOptions().as_dict()
    with pytest.raises(ConfigError, match=r"estimator\.window is missing"):
        EstimatorOptions.from_dict({k: v for k, v in values.items() if k != "window"})
    with pytest.raises(ConfigError, match=r"estimator\.lag is not an estimator option"):
        EstimatorOptions.from_dict({**values, "lag": 5})
    with pytest.raises(ConfigError, match="must be a mapping"):
        EstimatorOptions.from_dict([1, 2])  # type: ignore[arg-type]


def test_every_front_end_takes_the_object_and_nothing_else():
    """The bank, the single estimator and the reference take an EstimatorOptions (default
    EstimatorOptions(): 50 lags); the old loose arguments are refused."""
    assert EstimatorBank((2,)).options == EstimatorOptions() and EstimatorOptions().lags == 50
    assert RecursiveEstimator(2).options == RecursiveReference(2).options == EstimatorOptions()
    with pytest.raises(TypeError, match="options must be an EstimatorOptions, got int"):
        EstimatorBank((2,), 50)  # type: ignore[arg-type]
    with pytest.raises(TypeError):
        RecursiveEstimator(2, n_lags=50)  # type: ignore[call-arg]
