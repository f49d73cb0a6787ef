"""What the pipeline hands its consumers beyond estimates and standard errors:
convergence flags computed in the pipeline (equal to an independent ConvergenceMonitor, reset
with the estimator), full covariances on decimated samples (equal to bank.covariance at that
sample), the arrays and messages the node publishes (rls_uncertainty.datapath.outputs) with their
row-major layouts, and the configuration parameters behind them. No ROS."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from rls_uncertainty.datapath.cdr import encode_float64_multiarray_dims, encode_header
from rls_uncertainty.datapath.convergence import ConvergenceMonitor
from rls_uncertainty.datapath.inputs import feed
from rls_uncertainty.datapath.outputs import (
    ARRAY_OUTPUTS,
    MODEL_OUTPUTS,
    OutputLayout,
    dims,
    output_topics,
    parse_stamp_label,
    stamp_label,
)
from rls_uncertainty.datapath.pipeline import Pipeline
from rls_uncertainty.errors import ConfigError
from rls_uncertainty.offline.bags import read_inputs
from rls_uncertainty.settings import PARAMETERS, load_parameters_file, node_config, pipeline_config

from conftest import ROOT

BUNDLED = ROOT / "bags" / "t2_maneuver"


@pytest.fixture(scope="module")
def bag():
    messages, _ = read_inputs(BUNDLED)
    return messages


def t2(**overrides):
    return pipeline_config({**load_parameters_file("t2"), **overrides})


def run(bag, config, *, check_covariance=False):
    """Feed the bag message by message; with ``check_covariance``, compare every decimated
    output that is the last of its feed call (the bank is still at that sample) with
    bank.covariance."""
    pipe = Pipeline(config)
    outs, checked = [], 0
    for kind, _stamp, msg in bag:
        produced = feed(pipe, kind, msg)
        outs += produced
        if check_covariance and produced and produced[-1].covariance is not None:
            out = produced[-1]
            for j, n in enumerate(pipe.sizes):
                if out.ready[j]:
                    for k, kind_ in enumerate(("corrected", "conventional")):
                        want = pipe.bank.covariance(j, kind_)
                        if np.diag(want).min() < 0:  # an exact fit's rounding: published as zero
                            assert kind_ == "conventional" and pipe.bank.k == pipe.bank.ready_at[j]
                            want = np.zeros_like(want)
                        np.testing.assert_allclose(out.covariance[k, j, :n, :n], want, rtol=0,
                                                   atol=1e-9 * np.abs(want).max())
                    checked += 1
    return pipe, outs, checked


def test_convergence_flags_equal_an_independent_monitor(bag):
    config = t2()
    _pipe, outs, _ = run(bag, config)
    monitor = ConvergenceMonitor([3, 4], dataclasses.replace(config.convergence, rate_hz=config.rate))
    for out in outs:
        flags, model = monitor.update(out.stamp_ns, out.theta, out.se, out.ready)
        np.testing.assert_array_equal(out.converged, flags)
        np.testing.assert_array_equal(out.model_converged, model)
        np.testing.assert_array_equal(out.model_converged, [out.converged[j, :n].all() for j, n in enumerate((3, 4))])
    # The bundled maneuver converges: both models flagged at the end, none in the first window.
    assert outs[-1].model_converged.all()
    first = min(o.stamp_ns for o in outs if o.converged.any())
    assert first - outs[0].stamp_ns >= 2e9


def test_convergence_settings_change_the_flags(bag):
    strict = run(bag, t2(**{"convergence.band": 0.05}))[1]
    loose = run(bag, t2())[1]
    assert sum(o.converged.sum() for o in strict) < sum(o.converged.sum() for o in loose)


def test_a_reset_restarts_the_flags_with_the_estimator(bag):
    pipe = Pipeline(t2())
    half = len(bag) // 2
    for kind, _s, msg in bag[:half]:
        feed(pipe, kind, msg)
    conv_before = pipe.convergence(1)
    pipe.reset("service")
    assert pipe.convergence(1) == {"converged": False, "converged_parameters": ""}
    after = [o for kind, _s, msg in bag[half:] for o in feed(pipe, kind, msg)]
    t0 = after[0].stamp_ns
    assert not any(o.converged.any() for o in after if o.stamp_ns - t0 < 2e9)
    assert isinstance(conv_before["converged"], bool)


def test_a_resumed_state_restarts_the_flags(bag, tmp_path):
    pipe = Pipeline(t2())
    for kind, _s, msg in bag:
        feed(pipe, kind, msg)
    assert pipe.convergence(0)["converged"]
    pipe.save_state(tmp_path / "s.npz")
    resumed = Pipeline(t2())
    resumed.load_state(tmp_path / "s.npz")
    assert resumed.convergence(0) == {"converged": False, "converged_parameters": ""}
    assert resumed.model_fit(0) == pipe.model_fit(0)


def test_model_fit_reports_the_lags_in_use(bag):
    pipe = Pipeline(t2(**{"estimator.lag_span": 0.4}))
    for kind, _s, msg in bag[:300]:
        feed(pipe, kind, msg)
    fit = pipe.model_fit(0)
    assert fit["lags"] == min(pipe.bank.k - 1, 20) if fit["ready"] else "lags" not in fit
    for kind, _s, msg in bag[300:]:
        feed(pipe, kind, msg)
    assert pipe.model_fit(0)["lags"] == 20


@pytest.mark.parametrize("every", [1, 10, 7])
def test_covariances_on_decimated_grid_points_equal_the_banks(bag, every):
    config = t2(**{"outputs.covariance_decimation": every})
    pipe, outs, checked = run(bag, config, check_covariance=True)
    period = config.period_ns
    due = [o for o in outs if (o.stamp_ns // period) % every == 0]
    assert [o.covariance is not None for o in outs] == [(o.stamp_ns // period) % every == 0 for o in outs]
    assert checked > len(due)  # both models, most samples
    assert len(outs) == pipe.bank.k  # output i is the bank's sample k = i + 1
    for k, o in enumerate(outs, 1):
        if o.covariance is None:
            continue
        for j, n in enumerate(pipe.sizes):
            cov = o.covariance
            if not o.ready[j]:
                assert np.isnan(cov[:, j]).all()
                continue
            np.testing.assert_allclose(np.sqrt(np.diag(cov[0, j, :n, :n])), o.se[j, :n], rtol=1e-9)
            np.testing.assert_allclose(np.sqrt(np.diag(cov[1, j, :n, :n])), o.se_conventional[j, :n], rtol=1e-9)
            np.testing.assert_array_equal(cov[:, j, :n, :n], cov[:, j, :n, :n].swapaxes(-1, -2))
            # Positive semi-definite but for rounding, where the fit has degrees of freedom: with
            # k = n samples the residuals are rounding, and so is the matrix built from them
            # (its smallest eigenvalue differs in sign between OpenBLAS kernels).
            if k > n:
                assert np.linalg.eigvalsh(cov[0, j, :n, :n]).min() >= -1e-12 * np.abs(cov[0, j, :n, :n]).max()
            assert np.isnan(cov[:, j, n:]).all() and np.isnan(cov[:, j, :, n:]).all()


def test_no_covariance_with_decimation_zero(bag):
    _pipe, outs, _ = run(bag, t2(**{"outputs.covariance_decimation": 0}))
    assert outs and all(o.covariance is None for o in outs)


def test_published_arrays_order_shapes_and_values(bag):
    pipe, outs, _ = run(bag, t2())
    seen_cov = 0
    for out in outs:
        layout = OutputLayout.of(pipe)
        arrays = list(layout.arrays(out))
        rows = list(layout.rows(out))
        per_model = 6 if out.covariance is not None else 4
        assert len(arrays) == per_model * len(rows)
        for i, (j, name, names, theta, se, se_conv) in enumerate(rows):
            mine = arrays[i * per_model:(i + 1) * per_model]
            assert [a.suffix for a in mine] == list(MODEL_OUTPUTS[:per_model])
            assert {a.model for a in mine} == {name} and {a.names for a in mine} == {pipe.labels[j]}
            assert names == pipe.parameter_names[j]
            n = pipe.sizes[j]
            for a, want in zip(mine[:3], (theta, se, se_conv), strict=True):
                assert a.shape == (n,) and a.data.dtype == np.float64
                np.testing.assert_array_equal(a.data, want)
            assert set(mine[3].data.tolist()) <= {0.0, 1.0}
            np.testing.assert_array_equal(mine[3].data, out.converged[j, :n].astype(float))
            if out.covariance is not None:
                seen_cov += 1
                for a, k in zip(mine[4:], (0, 1), strict=True):
                    assert a.shape == (n, n) and a.data.shape == (n * n,)
                    np.testing.assert_array_equal(a.data.reshape(n, n), out.covariance[k, j, :n, :n])
            assert all(np.isfinite(a.data).all() for a in mine)
    assert seen_cov > 0
    assert MODEL_OUTPUTS[:3] == ARRAY_OUTPUTS


def test_layouts_are_row_major_with_the_stamp_last():
    when = stamp_label(1_767_225_600_140_000_000)
    assert dims("CZ_0,CZ_alpha,CZ_delta_e", (3,), when) == [("CZ_0,CZ_alpha,CZ_delta_e", 3, 3), (when, 1, 1)]
    cov = dims("a,b,c,d", (4, 4), when)
    assert cov == [("a,b,c,d", 4, 16), ("a,b,c,d", 4, 4), (when, 1, 1)]
    # ROS MultiArrayLayout: element (i, j) at data[dim[1].stride * i + j]; stamp in the last dim.
    assert cov[0][2] == cov[0][1] * cov[1][2] and cov[1][2] == cov[1][1] * cov[2][2]
    assert parse_stamp_label(cov[-1][0]) == 1_767_225_600_140_000_000


def test_the_new_parameters_reach_their_fields():
    spec = {p.name: p for p in PARAMETERS}
    assert node_config({}).diagnostics_window == 10.0
    for name in ("convergence.window", "convergence.band", "convergence.max_se_rate", "outputs.covariance_decimation",
                 "diagnostics_window"):
        assert spec[name].description and spec[name].low is not None
    cfg = pipeline_config({"convergence.window": 3.0, "convergence.band": 2.0, "convergence.max_se_rate": 0.5,
                           "outputs.covariance_decimation": 4})
    assert (cfg.convergence.window, cfg.convergence.band, cfg.convergence.max_se_rate) == (3.0, 2.0, 0.5)
    assert cfg.outputs.covariance_decimation == 4
    assert node_config({"diagnostics_window": 30.0}).diagnostics_window == 30.0
    # Not part of the fingerprint: a state file stays valid when they change.
    assert cfg.fingerprint() == pipeline_config({}).fingerprint()


@pytest.mark.parametrize("params,match", [
    ({"convergence.window": 0.0}, "convergence.window"),
    ({"convergence.band": -1.0}, "convergence.band"),
    ({"outputs.covariance_decimation": -1}, "outputs.covariance_decimation"),
    ({"outputs.covariance_decimation": 1.5}, "outputs.covariance_decimation"),
    ({"rate": 1000.0, "convergence.window": 10.0}, "at most 4094"),
])
def test_bad_output_settings_are_refused(params, match):
    with pytest.raises(ConfigError, match=match):
        pipeline_config(params)


def test_bad_diagnostics_window_is_refused():
    with pytest.raises(ConfigError, match="diagnostics_window"):
        node_config({"diagnostics_window": 0.0})


def test_each_message_goes_to_its_topic_index_in_publishing_order(bag):
    """OutputLayout.encode: index 0 is the sample_stamp Header (sec, nanosec, frame), then per
    ready model its arrays on the topics output_topics lists for that model and suffix, the
    covariances encoded with the row-major dims (cdr, independently of the index bookkeeping)."""
    pipe, outs, _ = run(bag, t2())
    layout = OutputLayout.of(pipe)
    assert layout.topics == output_topics(["CZ", "Cm"])
    with_cov = next(o for o in outs if o.covariance is not None and o.ready.all())
    messages = layout.encode(with_cov, "body")
    sec, nanosec = divmod(with_cov.stamp_ns, 1_000_000_000)
    assert messages[0] == (0, encode_header(sec, nanosec, "body"))
    topics = [layout.topics[i][0] for i, _ in messages[1:]]
    assert topics == [f"{m}/{s}" for m in ("CZ", "Cm") for s in MODEL_OUTPUTS]
    n, j = 4, 1
    cov = with_cov.covariance[0, j, :n, :n]
    want = encode_float64_multiarray_dims(dims(pipe.labels[j], (n, n), stamp_label(with_cov.stamp_ns)),
                                          cov.ravel().tolist())
    assert dict(messages)[output_topics(["CZ", "Cm"]).index(("Cm/covariance", "std_msgs/msg/Float64MultiArray"))] \
        == want
    # A model not ready publishes nothing; the stamp still goes out.
    half = with_cov._replace(ready=np.array([False, True]))
    assert [layout.topics[i][0].split("/")[0] for i, _ in layout.encode(half, "body")[1:]] == ["Cm"] * 6


# ------------------------------------------------------------------ ~/M/fit and ~/M/identifiability
def test_fit_and_identifiability_arrays_hold_the_figures_of_independent_computations(bag):
    """encode_fit after the bundled bag, decoded with rosbags: per model, ~/M/fit carries R^2 (a
    batch least-squares fit of the recorded regression: the standardized residual makes Eq. 16
    the batch fit-error variance), the samples, 2/sqrt(n) and R(i)/R(0) at the lags in use;
    ~/M/identifiability the correlations of the corrected covariance, the regressors' standard
    deviations (numpy over the recorded regression) with their resolutions, and the flags; both
    labelled as docs/node.md says, with the newest sample's stamp last."""
    from rls_uncertainty.datapath.outputs import FIT_OUTPUTS, fit_topics
    from rls_uncertainty.offline.bags import typestore

    pipe = Pipeline(t2(), record=True)
    for kind, _stamp, msg in bag:
        feed(pipe, kind, msg)
    layout = OutputLayout.of(pipe)
    assert layout.fit_topics == fit_topics(["CZ", "Cm"]) == [("CZ/fit", "std_msgs/msg/Float64MultiArray"),
                                                             ("CZ/identifiability", "std_msgs/msg/Float64MultiArray"),
                                                             ("Cm/fit", "std_msgs/msg/Float64MultiArray"),
                                                             ("Cm/identifiability", "std_msgs/msg/Float64MultiArray")]
    store = typestore()
    messages = {layout.fit_topics[i][0]: store.deserialize_cdr(raw, "std_msgs/msg/Float64MultiArray")
                for i, raw in layout.encode_fit(pipe)}
    assert sorted(messages) == sorted(f"{m}/{s}" for m in ("CZ", "Cm") for s in FIT_OUTPUTS)
    stamp = stamp_label(pipe.regression[-1][0])
    n_samples = len(pipe.regression)
    for j, (model, names) in enumerate(zip(("CZ", "Cm"), pipe.parameter_names, strict=True)):
        n = len(names)
        X = np.array([r[1][j, :n] for r in pipe.regression])
        z = np.array([r[2][j] for r in pipe.regression])
        residual = z - X @ np.linalg.lstsq(X, z, rcond=None)[0]
        fit = messages[f"{model}/fit"]
        L = int(pipe.bank.lags_used[j])
        assert [(d.label, d.size, d.stride) for d in fit.layout.dim] == [
            (f"r_squared,samples,bound_2sigma,rho_1,...,rho_{L}", 3 + L, 3 + L), (stamp, 1, 1)]
        assert fit.data[0] == pytest.approx(1.0 - residual @ residual / np.sum((z - z.mean()) ** 2), rel=1e-9)
        assert fit.data[1] == n_samples and fit.data[2] == pytest.approx(2.0 / np.sqrt(n_samples), rel=1e-15)
        R = pipe.bank.autocorrelation(j)
        np.testing.assert_array_equal(fit.data[3:], R[1 : L + 1] / R[0])
        ident = messages[f"{model}/identifiability"]
        label = ",".join(names)
        assert [(d.label, d.size, d.stride) for d in ident.layout.dim] == [
            (label, n, n * (n + 3)), (f"{label},excitation,resolution,identifiable", n + 3, n + 3), (stamp, 1, 1)]
        table = ident.data.reshape(n, n + 3)
        c = pipe.bank.covariance(j, "corrected")
        np.testing.assert_allclose(table[:, :n], c / np.sqrt(np.outer(np.diag(c), np.diag(c))), rtol=1e-9, atol=1e-12)
        np.testing.assert_allclose(table[1:, n], X[:, 1:].std(axis=0), rtol=1e-9)
        assert table[0, n] == table[0, n + 1] == 0.0  # the bias: not tested
        floors = [1e-6 if name == "q_hat" else 1e-4 for name in pipe.models[j].regressors[1:]]
        assert table[1:, n + 1].tolist() == floors
        assert table[:, n + 2].tolist() == [1.0] * n


def test_nothing_is_encoded_before_a_sample_or_for_a_model_not_ready(bag):
    pipe = Pipeline(t2())
    layout = OutputLayout.of(pipe)
    assert layout.encode_fit(pipe) == []
    for kind, _stamp, msg in bag:
        feed(pipe, kind, msg)
        if pipe.bank.k > 0:
            break
    assert not pipe.bank.ready.any() and layout.encode_fit(pipe) == []


# ------------------------------------------------------------------ ~/M/frequency/*
def test_the_frequency_domain_arrays_follow_the_time_domain_ones_without_the_bias(bag):
    """estimator.method both: per sample, after every model's time-domain arrays, per model ready
    in the frequency domain its estimates, corrected and conventional SEs and flags on
    ~/M/frequency/..., labelled with the parameters without the bias and stamped with the sample
    (cdr, independently of the index bookkeeping); a model not ready there publishes nothing."""
    from rls_uncertainty.datapath.cdr import encode_float64_multiarray
    from rls_uncertainty.datapath.outputs import FREQUENCY_OUTPUTS

    pipe, outs, _ = run(bag, t2(**{"estimator.method": "both"}))
    layout = OutputLayout.of(pipe)
    topics = output_topics(["CZ", "Cm"], frequency=True)
    assert layout.topics == topics
    assert [t for t, _ in topics[13:]] == [f"{m}/frequency/{s}" for m in ("CZ", "Cm") for s in FREQUENCY_OUTPUTS]
    labels = ("CZ_alpha,CZ_delta_e", "Cm_alpha,Cm_q,Cm_delta_e")
    published = 0
    for out in outs:
        f = out.frequency
        messages = dict(layout.encode(out, "base_link"))
        for j, (model, label) in enumerate(zip(("CZ", "Cm"), labels, strict=True)):
            n = len(label.split(","))
            for suffix, values in zip(FREQUENCY_OUTPUTS, (f.theta, f.se, f.se_conventional,
                                                          f.converged.astype(float)), strict=True):
                index = topics.index((f"{model}/frequency/{suffix}", "std_msgs/msg/Float64MultiArray"))
                if f.ready[j]:
                    assert np.isfinite(values[j, :n]).all()
                    want = encode_float64_multiarray(label, values[j, :n].tolist(), stamp_label(out.stamp_ns))
                    assert messages[index] == want
                    published += 1
                else:
                    assert index not in messages
        names = {a.names for a in layout.arrays(out) if a.suffix.startswith("frequency/")}
        assert names <= set(labels)
        assert [r.names for r in layout.frequency_rows(out)] == [
            tuple(label.split(",")) for j, label in enumerate(labels) if f.ready[j]]
    assert published > 8 * 480  # (8 arrays per sample from the publication rule on: 487 samples)


def test_frequency_only_publishes_no_time_domain_arrays_and_every_n_only_on_its_samples(bag):
    pipe, outs, _ = run(bag, t2(**{"estimator.method": "frequency", "frequency.every": 4}))
    layout = OutputLayout.of(pipe)
    assert layout.topics == output_topics(["CZ", "Cm"], time=False, frequency=True)
    assert not list(layout.rows(outs[-1]))
    for out in outs:
        messages = layout.encode(out, "base_link")
        assert messages[0][0] == 0  # the sample stamp, every sample
        topics = {layout.topics[i][0] for i, _ in messages[1:]}
        assert all("/frequency/" in t for t in topics)
        assert bool(topics) == (out.index % 4 == 0 and out.frequency.ready.any())
