"""estimator.algorithm iv in the one data path (rls_uncertainty.datapath.instrument_path):
the injected excitation travels with its sample through the delay line, every formed sample
ends used, rejected or pending, the estimates equal the estimator fed directly with the
rows and the auxiliary model's instruments, and misconfigurations are one ConfigError line."""

from __future__ import annotations

import copy

import numpy as np
import pytest

from rls_uncertainty.errors import ConfigError
from rls_uncertainty.estimator.reference import batch_iv
from rls_uncertainty.frequency import frequency_reference
from rls_uncertainty.offline.bags import read_inputs
from rls_uncertainty.offline.replay import run_pipeline
from rls_uncertainty.settings.parameters import pipeline_config
from rls_uncertainty.settings.sources import load_parameters_file

from source_tree import ROOT

BUNDLED = ROOT / "bags" / "t2_maneuver"


def _config(**params):
    return pipeline_config({**load_parameters_file("t2"), "estimator.algorithm": "iv", **params})


@pytest.fixture(scope="module")
def with_excitation():
    """The bundled bag with its measured surfaces repeated on the excitation input (open loop:
    the surfaces are the injected input plus sensor noise)."""
    out = []
    for kind, stamp, msg in read_inputs(BUNDLED)[0]:
        out.append((kind, stamp, msg))
        if kind == "control_surfaces":
            out.append(("excitation", stamp, msg))
    return out


@pytest.fixture(scope="module")
def iv_run(with_excitation):
    return run_pipeline(with_excitation, _config())


def test_the_excitation_stays_aligned_with_its_row(iv_run):
    """The instrument of delta_e is the excitation itself; with the surfaces as the
    excitation it equals the row's delta_e regressor exactly, for every row the estimator
    took (a sample's excitation shifted by one in the delay line would differ)."""
    pipe = iv_run.pipeline
    rows, zetas = pipe.regression, pipe.instruments
    assert len(rows) == len(zetas) == pipe.samples_used > 500
    for (_t, X, _z), zeta in zip(rows, zetas, strict=True):
        assert zeta[0, 2] == X[0, 2] and zeta[1, 3] == X[1, 3]  # CZ's and Cm's delta_e slots
        assert zeta[0, 0] == zeta[1, 0] == 1.0 and zeta[0, 1] != X[0, 1]  # bias; alpha from the model


def test_estimates_equal_batch_instrumental_variables(iv_run):
    """The final estimates and both covariances are the batch IV formulas (theta = (Z'X)^-1
    Z'z and its sandwich) over the rows and instruments the estimator took; every formed
    sample is used or rejected with a reason (nothing waits at the end)."""
    pipe = iv_run.pipeline
    Zeta = np.array(pipe.instruments)
    X = np.array([r[1] for r in pipe.regression])
    z = np.array([r[2] for r in pipe.regression])
    assert Zeta.shape == X.shape and len(Zeta) == pipe.samples_used
    c = pipe.counters()
    assert c["samples_pending"] == 0
    assert c["samples_formed"] == c["samples_used"] + sum(c["samples_rejected"].values())
    for j, n in enumerate(pipe.sizes):
        theta, _conv, _corr = batch_iv(X[:, j, :n], Zeta[:, j, :n], z[:, j])
        np.testing.assert_allclose(pipe.bank.theta(j), theta, rtol=1e-8, atol=1e-10)


def test_the_frequency_domain_takes_every_row_with_its_instruments(with_excitation):
    """With estimator.method both, the frequency-domain estimates and covariances are the batch
    frequency-domain IV (the literal oracle) over the rows and instruments the time-domain
    estimator took, the backlog of the first auxiliary model included, in their order; the
    time-domain numbers are those of the time method."""
    result = run_pipeline(with_excitation, _config(**{"estimator.method": "both"}))
    pipe = result.pipeline
    freq = pipe.frequency
    assert freq is not None and freq.bank.n_samples == pipe.samples_used == len(pipe.instruments) > 500
    Zeta = np.array(pipe.instruments)
    X = np.array([r[1] for r in pipe.regression])
    z = np.array([r[2] for r in pipe.regression])
    options = pipe.config.frequency
    assert options is not None and options.every == 1
    for j, model in enumerate(pipe.config.models):
        cols = [i for i, r in enumerate(model.regressors) if r != "1"]
        ref = frequency_reference(X[:, j, cols], z[:, j], options, Zeta[:, j, cols])
        np.testing.assert_allclose(freq.bank.theta(j), ref.theta, rtol=1e-10)
        for kind, expected in (("corrected", ref.cov_corrected), ("conventional", ref.cov_conventional)):
            np.testing.assert_allclose(freq.bank.covariance(j, kind), expected, rtol=1e-9,
                                       atol=1e-10 * np.abs(expected).max())
    time_only = run_pipeline(with_excitation, _config(), record=False).pipeline
    np.testing.assert_array_equal(pipe.bank.theta_all(), time_only.bank.theta_all())


def test_instrumental_variables_move_the_estimates_toward_the_truth(iv_run, with_excitation):
    """The bundled maneuver carries band-limited noise on all four measured signals (errors in
    variables): RLS pulls C_m_q toward zero, instrumental variables do not (the simulation's
    C_m_q is -53.25, Table 3); the corrected SE covers the difference honestly."""
    rls = run_pipeline(with_excitation, _config(**{"estimator.algorithm": "rls"}), record=False)
    truth = -53.25
    cm = [m.output for m in iv_run.pipeline.models].index("Cm")
    i = iv_run.pipeline.models[cm].regressors.index("q_hat")
    iv_theta = iv_run.pipeline.last.theta[cm, i]
    rls_theta = rls.pipeline.last.theta[cm, i]
    assert abs(iv_theta - truth) < abs(rls_theta - truth)
    assert abs(iv_theta - truth) < 2 * iv_run.pipeline.last.se[cm, i]


def test_without_excitation_no_sample_is_formed_and_the_input_is_named(with_excitation):
    """estimator.algorithm iv requires the excitation input: a bag without it forms no sample,
    and the excitation stream is among the required streams (the node's silent-input line
    names topics.excitation)."""
    bare = [m for m in with_excitation if m[0] != "excitation"]
    result = run_pipeline(bare, _config(), record=False)
    assert "excitation" in result.pipeline.required
    assert result.pipeline.samples_used == 0 and not result.outputs


def test_weak_instruments_are_never_flagged_and_say_why(with_excitation):
    """An excitation topic that carries noise unrelated to the maneuver (the input was not
    injected) gives instruments uncorrelated with the regressors: the models are held back
    with the reason, and nothing non-finite is published."""
    rng = np.random.default_rng(7)
    flat = []
    for kind, stamp, msg in with_excitation:
        if kind == "excitation":
            noise = copy.deepcopy(msg)
            noise.position = rng.normal(0.0, 1e-3, len(msg.position))
            flat.append((kind, stamp, noise))
        else:
            flat.append((kind, stamp, msg))
    result = run_pipeline(flat, _config(), record=False)
    pipe = result.pipeline
    for out in result.outputs:
        assert not out.converged[out.ready].any() if out.ready.any() else True
        assert np.isfinite(out.theta[out.ready & pipe._real.any(axis=1)][:, :1]).all()
    reasons = [pipe.weak_instruments(j) for j in range(len(pipe.sizes))]
    assert any(r.startswith("weak instruments") for r in reasons), reasons


@pytest.mark.parametrize(("params", "words"), [
    ({"models.enabled": ["CZ", "Cm", "Cl"], "instruments.source": "excitation"}, "cannot instrument model Cl"),
    ({"models.enabled": ["CZ", "Cm", "Cl"], "instruments.source": "excitation", "estimator.method": "both"},
     "cannot instrument model Cl"),
])
def test_a_configuration_iv_cannot_serve_is_one_line(params, words):
    with pytest.raises(ConfigError) as err:
        _config(**params)
    text = str(err.value)
    assert words in text and "estimator.algorithm" in text and "\n" not in text


def test_instruments_from_the_measured_surfaces_are_warned_once():
    """Pointing topics.excitation at the surfaces' own topic (no injected excitation known) is
    said in one line naming topics.excitation; the injected excitation's own topic is not."""
    from rls_uncertainty.datapath.feasibility import configuration_warnings
    from rls_uncertainty.settings.parameters import node_config

    cfg = _config()
    same = node_config({"topics.excitation": "control_surfaces"}).topics
    apart = node_config({"topics.excitation": "/fcc/excitation"}).topics
    lines = [w for w in configuration_warnings(cfg, same) if "topics.excitation" in w]
    assert len(lines) == 1 and "\n" not in lines[0] and "biased" in lines[0]
    assert not [w for w in configuration_warnings(cfg, apart) if "topics.excitation" in w]
    assert not [w for w in configuration_warnings(_config(**{"estimator.algorithm": "rls"}), same)
                if "topics.excitation" in w]


def test_one_topic_can_feed_the_surfaces_and_the_excitation(tmp_path, capsys):
    """topics.excitation may name the surfaces' own topic (no injected excitation recorded):
    the replay feeds each of its messages to both inputs, the estimator runs, and the one-line
    warning says why such instruments stay biased."""
    from rls_uncertainty.offline.replay import replay

    params = {**load_parameters_file("t2"), "estimator.algorithm": "iv", "topics.excitation": "control_surfaces"}
    result = replay(BUNDLED, params, tmp_path / "out")
    c = result.pipeline.counters()["streams"]
    assert c["excitation"]["received"] == c["control_surfaces"]["received"] > 0
    assert result.pipeline.samples_used > 500
    err = capsys.readouterr().err
    assert err.count("topics.excitation is topics.control_surfaces") == 1


def test_a_mapping_file_may_give_the_excitation_joint_by_joint(tmp_path):
    """convert's mapping takes an excitation input like the surfaces (joints to fields), and
    refuses one without joints in one line naming it."""
    from rls_uncertainty.errors import BagError
    from rls_uncertainty.offline.bags import load_mapping

    base = ("imu: {topic: /imu}\nairspeed: {topic: /air}\n"
            "control_surfaces: {topic: /srf, joints: {elevator: de}}\n")
    good = tmp_path / "good.yaml"
    good.write_text(base + "excitation: {topic: /fcc, joints: {elevator: de_cmd}}\n")
    assert load_mapping(good)["excitation"]["joints"] == {"elevator": "de_cmd"}
    bad = tmp_path / "bad.yaml"
    bad.write_text(base + "excitation: {topic: /fcc}\n")
    with pytest.raises(BagError, match="excitation") as err:
        load_mapping(bad)
    assert "joints" in str(err.value) and "\n" not in str(err.value)
