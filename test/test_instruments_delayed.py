"""Instruments from the measured surfaces and the delayed regressors
(rls_uncertainty.instruments.delayed, instruments.source delayed): the layout of I3 against
an independent shift of the rows, rows without an earlier row dropped, bad input refused, the
source chosen for the model set, and the lateral Twin Otter recording through the data path
with estimator.algorithm iv equal to batch instrumental variables over the same rows."""

from __future__ import annotations

import numpy as np
import pytest

from rls_uncertainty.aero.models import ModelConfig
from rls_uncertainty.errors import ConfigError, NonFiniteInput
from rls_uncertainty.estimator.reference import batch_iv
from rls_uncertainty.instruments import DelayedRegressors
from rls_uncertainty.offline.bags import convert, read_inputs
from rls_uncertainty.offline.replay import run_pipeline
from rls_uncertainty.settings import load_parameters_file, pipeline_config
from rls_uncertainty.simulation.t2 import T2_MODELS

from conftest import FLIGHT_DATA, ROOT

LATERAL = (ModelConfig("CY", ("1", "beta", "r_hat", "delta_r")),
           ModelConfig("Cl", ("1", "beta", "p_hat", "r_hat", "delta_a", "delta_r")))
PERIOD = 20_000_000  # ns, 50 Hz
SURFACE_OR_BIAS = np.array([[1, 0, 0, 1, 0, 0], [1, 0, 0, 0, 1, 1]], dtype=bool)  # LATERAL's columns


def _rows(n, seed=3):
    rng = np.random.default_rng(seed)
    X = rng.normal(size=(n, 2, 6))
    X[:, :, 0] = 1.0
    X[:, 0, 4:] = 0.0  # CY's padding
    return X, rng.normal(size=(n, 2))


def test_surfaces_and_bias_instrument_themselves_the_rest_is_delayed():
    d = 3
    inst = DelayedRegressors(LATERAL, d, PERIOD)
    X, z = _rows(12)
    got = []
    for k in range(12):
        out = inst.update(X[k], z[k], k * PERIOD)
        assert len(out) == (k >= d)
        got += out
    assert inst.dropped == d and inst.waiting == 0
    for s in got:
        k = s.tag // PERIOD
        expected = np.where(SURFACE_OR_BIAS, X[k], X[k - d])  # built apart from the class
        np.testing.assert_array_equal(s.instruments, expected)
        np.testing.assert_array_equal(s.X, X[k])
        np.testing.assert_array_equal(s.z, z[k])
        assert (s.instruments[0, 4:] == 0).all()  # padding stays 0


def test_a_gap_in_the_stamps_drops_the_rows_without_an_earlier_one():
    d = 2
    inst = DelayedRegressors(LATERAL, d, PERIOD)
    X, z = _rows(10)
    stamps = [0, 1, 2, 3, 7, 8, 9, 10, 11, 12]  # four periods missing after 3
    used = [k for k, t in enumerate(stamps) if inst.update(X[k], z[k], t * PERIOD)]
    assert [stamps[k] for k in used] == [2, 3, 9, 10, 11, 12]
    assert inst.dropped == 4
    inst.update(X[0], z[0], 5 * PERIOD)  # stamps going back start it over
    assert not inst.update(X[1], z[1], 6 * PERIOD) and inst.update(X[2], z[2], 7 * PERIOD)


def test_bad_input_is_refused_and_not_kept():
    inst = DelayedRegressors(LATERAL, 1, PERIOD)
    X, z = _rows(3)
    inst.update(X[0], z[0], 0)
    bad = X[1].copy()
    bad[1, 2] = np.nan
    with pytest.raises(NonFiniteInput):
        inst.update(bad, z[1], PERIOD)
    with pytest.raises(NonFiniteInput):
        inst.update(X[1], [np.inf, 0.0], PERIOD)
    (s,) = inst.update(X[1], z[1], PERIOD)
    np.testing.assert_array_equal(s.instruments, np.where(SURFACE_OR_BIAS, X[1], X[0]))
    with pytest.raises(ConfigError, match=r"instruments\.delay_span"):
        DelayedRegressors(LATERAL, 0, PERIOD)


def test_the_source_follows_the_models():
    """auto: the short-period auxiliary model for the T-2's CZ and Cm, the delayed regressors
    for lateral models; excitation chosen for lateral models is one line naming the way out."""
    base = {**load_parameters_file("twin_otter_lateral"), "estimator.algorithm": "iv"}
    assert pipeline_config(base).instruments.resolved_source(LATERAL) == "delayed"
    assert pipeline_config(base).instruments.resolved_source(T2_MODELS) == "excitation"
    with pytest.raises(ConfigError) as err:
        pipeline_config({**base, "instruments.source": "excitation"})
    text = str(err.value)
    assert "cannot instrument model CY" in text and "instruments.source delayed" in text and "\n" not in text
    t2 = {**load_parameters_file("t2"), "estimator.algorithm": "iv", "instruments.source": "delayed"}
    assert pipeline_config(t2).instruments.resolved_source(T2_MODELS) == "delayed"


def test_delayed_instruments_are_warned_once_and_rls_is_not():
    from rls_uncertainty.datapath.feasibility import configuration_warnings

    base = load_parameters_file("twin_otter_lateral")
    lines = [w for w in configuration_warnings(pipeline_config({**base, "estimator.algorithm": "iv"}))
             if "instruments.source delayed" in w]
    assert len(lines) == 1 and "open loop" in lines[0] and "\n" not in lines[0]
    assert not [w for w in configuration_warnings(pipeline_config(base)) if "instruments.source" in w]


@pytest.fixture(scope="module")
def lateral_iv(tmp_path_factory):
    bag = tmp_path_factory.mktemp("delayed") / "totter_f1_017"
    convert(FLIGHT_DATA / "totter_f1_017", ROOT / "msg_schemas" / "fti_msgs" / "mapping.yaml", bag)
    messages, _ = read_inputs(bag)
    params = {**load_parameters_file("twin_otter_lateral"), "estimator.algorithm": "iv"}
    return run_pipeline(messages, pipeline_config(params))


def test_the_lateral_recording_runs_without_excitation_and_equals_batch_iv(lateral_iv):
    """No excitation stream is needed; every formed sample is used or rejected with a reason;
    each row's instruments are its surfaces and its other regressors delay_span earlier (found by
    stamp among the rows kept); the recursive estimates are batch IV (Z'X)^-1 Z'z over them."""
    pipe = lateral_iv.pipeline
    assert "excitation" not in pipe.required
    c = pipe.counters()
    assert c["samples_pending"] == 0
    assert c["samples_formed"] == c["samples_used"] + sum(c["samples_rejected"].values())
    d = round(pipe.config.instruments.delay_span * pipe.config.rate)
    assert c["samples_rejected"]["instruments_not_ready"] == d  # the recording has no gap
    stamps = [t for t, _, _ in pipe.regression]
    X = np.array([r[1] for r in pipe.regression])
    z = np.array([r[2] for r in pipe.regression])
    Zeta = np.array(pipe.instruments)
    assert Zeta.shape == X.shape and len(X) == pipe.samples_used > 900
    # The rows rejected for want of instruments are not kept: rebuild the earlier ones from
    # the instruments' own delayed columns only where the earlier row is among those kept.
    index = {t: i for i, t in enumerate(stamps)}
    for j, model in enumerate(pipe.config.models):
        keep = [i for i, r in enumerate(model.regressors) if r == "1" or r.startswith("delta_")]
        lag = [i for i in range(len(model.regressors)) if i not in keep]
        for i, t in enumerate(stamps):
            np.testing.assert_array_equal(Zeta[i, j, keep], X[i, j, keep])
            earlier = index.get(t - d * pipe.config.period_ns)
            if earlier is not None:
                np.testing.assert_array_equal(Zeta[i, j, lag], X[earlier, j, lag])
        n = len(model.regressors)
        theta, _conv, _corr = batch_iv(X[:, j, :n], Zeta[:, j, :n], z[:, j])
        np.testing.assert_allclose(pipe.bank.theta(j), theta, rtol=1e-8, atol=1e-10)
        assert not np.allclose(theta, np.linalg.lstsq(X[:, j, :n], z[:, j], rcond=None)[0])


def test_the_lateral_instruments_are_strong_and_the_flags_come(lateral_iv):
    """On the recording the delayed instruments are not weak (rho_min above the threshold) and
    the parameters are flagged converged at the end."""
    pipe = lateral_iv.pipeline
    assert (pipe._iv.rho_min > pipe.config.instruments.weak_below).all()
    assert lateral_iv.outputs[-1].converged[pipe._real].all()
