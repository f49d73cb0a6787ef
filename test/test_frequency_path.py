"""The frequency-domain estimator in the pipeline (rls_uncertainty/datapath/frequency_path.py): it takes
the time-domain estimator's rows without the bias columns (any order of the regressors), gives
exactly what a FrequencyBank fed those rows gives, publishes every `frequency.every` samples
with that sample's stamp, leaves the time-domain numbers untouched, refuses a row for both
estimators or neither, withholds and counts non-finite results, runs the convergence criterion
on its own estimates held back by identifiability, and restarts with the estimator. No DDS."""

from __future__ import annotations

from collections import Counter
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from rls_uncertainty.datapath.convergence import ConvergenceMonitor
from rls_uncertainty.datapath.frequency_path import FrequencyPath
from rls_uncertainty.datapath.inputs import feed
from rls_uncertainty.datapath.pipeline import Pipeline
from rls_uncertainty.errors import NonFiniteInput
from rls_uncertainty.frequency import FrequencyBank
from rls_uncertainty.offline.bags import read_inputs
from rls_uncertainty.offline.replay import run_pipeline
from rls_uncertainty.settings import load_parameters_file, pipeline_config

ROOT = Path(__file__).resolve().parents[1]
BUNDLED = ROOT / "bags" / "t2_maneuver"


@pytest.fixture(scope="module")
def messages():
    return read_inputs(BUNDLED)[0]


def _params(**overrides):
    return {**load_parameters_file("t2"), "estimator.method": "both", **overrides}


def _run(messages, **overrides):
    return run_pipeline(messages, pipeline_config(_params(**overrides)), record=True)


# CZ with the bias in the middle, Cm without a bias: the path picks the columns by name.
REORDERED = {"models.CZ": ["alpha", "1", "delta_e"], "models.Cm": ["alpha", "q_hat", "delta_e"]}


@pytest.mark.parametrize("overrides", [{}, REORDERED], ids=["t2", "bias_elsewhere"])
def test_the_path_gives_what_a_frequency_bank_gives_on_the_pipelines_rows_without_the_bias(messages, overrides):
    result = _run(messages, **overrides)
    pipe = result.pipeline
    config = pipe.config
    keep = [[i for i, r in enumerate(m.regressors) if r != "1"] for m in config.models]
    assert [m.frequency_parameter_names for m in config.models] == [
        tuple(m.parameter_names[i] for i in cols) for m, cols in zip(config.models, keep, strict=True)]
    bank = FrequencyBank([len(c) for c in keep], config.frequency)
    q = max(map(len, keep))
    assert len(pipe.regression) == len(result.outputs) > 500
    ready_seen = 0
    for (t, X, z), out in zip(pipe.regression, result.outputs, strict=True):
        Xf = np.zeros((len(keep), q))
        for j, cols in enumerate(keep):
            Xf[j, : len(cols)] = X[j, cols]
        bank.update(Xf, z)
        f = out.frequency
        assert f is not None and out.stamp_ns == t  # every sample with every: 1
        # Bit for bit: the same operations on the same numbers in one process.
        np.testing.assert_array_equal(f.theta, bank.theta_all())
        np.testing.assert_array_equal(f.se, bank.standard_errors_all("corrected"))
        np.testing.assert_array_equal(f.se_conventional, bank.standard_errors_all("conventional"))
        np.testing.assert_array_equal(f.ready, bank.ready)
        np.testing.assert_array_equal(f.lags, np.where(bank.ready, min(50, bank.n_samples - 1), 0))
        ready_seen += int(f.ready.all())
    assert ready_seen >= len(result.outputs) - 104  # every sample from the publication rule's on


def test_the_time_domain_numbers_do_not_depend_on_the_method(messages):
    both, time = _run(messages), _run(messages, **{"estimator.method": "time"})
    assert [o.stamp_ns for o in both.outputs] == [o.stamp_ns for o in time.outputs]
    for a, b in zip(both.outputs, time.outputs, strict=True):
        for field in ("theta", "se", "se_conventional", "ready", "converged", "lags"):
            np.testing.assert_array_equal(getattr(a, field), getattr(b, field), err_msg=field)
        assert b.frequency is None
    assert both.counters() == time.counters()


def test_with_every_n_the_results_come_on_every_nth_sample_with_that_samples_stamp(messages):
    every1, every5 = _run(messages), _run(messages, **{"frequency.every": 5})
    published = [i for i, o in enumerate(every5.outputs) if o.frequency is not None]
    assert published == list(range(4, len(every5.outputs), 5))  # sample counts 5, 10, ...
    for i in published:
        a, b = every5.outputs[i].frequency, every1.outputs[i].frequency
        for field in ("theta", "se", "se_conventional", "ready"):
            np.testing.assert_array_equal(getattr(a, field), getattr(b, field), err_msg=field)
    # The time-domain outputs still come every sample.
    assert len(every5.outputs) == len(every1.outputs)


def test_the_frequency_convergence_flags_are_the_criterion_on_the_frequency_estimates(messages):
    """A monitor fed the published frequency-domain estimates and corrected SEs at their stamps
    flags what the pipeline flags (every parameter of the bundled maneuver is identifiable and
    flagged by the end); with a fit threshold the data cannot meet (identifiability.
    min_r_squared 0.99), nothing is flagged although the same monitor flags."""
    for min_r2, held_back in ((0.5, False), (0.99, True)):
        result = _run(messages, **{"identifiability.min_r_squared": min_r2})
        path = result.pipeline.frequency
        config = result.pipeline.config
        monitor = ConvergenceMonitor(path.sizes, replace(config.convergence, rate_hz=config.rate))
        flagged = 0
        for out in result.outputs:
            f = out.frequency
            flags, model_flags = monitor.update(out.stamp_ns, f.theta, f.se, f.ready)
            flagged += int(flags.any())
            if held_back:
                assert not f.converged.any() and not f.model_converged.any()
            else:
                np.testing.assert_array_equal(f.converged, flags)
                np.testing.assert_array_equal(f.model_converged, model_flags)
        assert flagged > 100
        assert result.outputs[-1].frequency.model_converged.all() != held_back


def test_a_row_the_frequency_domain_refuses_is_used_by_neither_estimator(messages, monkeypatch):
    pipe = Pipeline(pipeline_config(_params()))
    calls = Counter()
    check = FrequencyPath.check

    def refuse_the_tenth(self, X, z):
        calls["rows"] += 1
        if calls["rows"] == 10:
            raise NonFiniteInput("test: refused")
        check(self, X, z)

    monkeypatch.setattr(FrequencyPath, "check", refuse_the_tenth)
    outputs = [out for kind, _s, msg in messages for out in feed(pipe, kind, msg)]
    book = pipe.bookkeeping
    assert book.samples_rejected["non_finite_regression"] == 1
    assert pipe.bank.k == pipe.frequency.bank.n_samples == book.samples_used == len(outputs) == calls["rows"] - 1
    with pytest.raises(RuntimeError, match="without a checked row"):
        pipe.frequency.add(0, Counter(), pipe.identifiability)
    X, z = np.zeros((2, 4)), np.zeros(2)
    X[1, 2] = np.inf
    with pytest.raises(NonFiniteInput, match=r"models \[1\]"):
        check(pipe.frequency, X, z)


def test_a_non_finite_frequency_result_is_withheld_and_counted(messages, monkeypatch):
    pipe = Pipeline(pipeline_config(_params()))
    standard_errors = FrequencyBank.standard_errors_all

    def infinite_cz(self, kind="corrected"):
        se = standard_errors(self, kind)
        if self.n_samples > 300 and kind == "conventional":
            se[0, 0] = np.inf
        return se

    monkeypatch.setattr(FrequencyBank, "standard_errors_all", infinite_cz)
    outputs = [out for kind, _s, msg in messages for out in feed(pipe, kind, msg)]
    late = [o.frequency for o in outputs if o.index > 300]
    assert late and not any(f.ready[0] for f in late) and all(f.ready[1] for f in late)
    assert pipe.bookkeeping.outputs_withheld["CZ/frequency"] == len(late)
    assert pipe.bookkeeping.outputs_withheld["CZ"] == 0
    assert not any(f.converged[0].any() for f in late)


def test_a_reset_starts_a_new_frequency_record(messages):
    pipe = Pipeline(pipeline_config(_params()))
    half = len(messages) // 2
    for kind, _s, msg in messages[:half]:
        feed(pipe, kind, msg)
    old = pipe.frequency
    assert old.bank.n_samples > 100 and old.bank.ready.all()
    pipe.reset("service", clear_inputs=False)
    assert pipe.frequency is not old and pipe.frequency.bank.n_samples == 0
    after = [out for kind, _s, msg in messages[half:] for out in feed(pipe, kind, msg)]
    assert pipe.frequency.bank.n_samples == pipe.bank.k == len(after)
    assert not after[0].frequency.ready.any()  # one sample: not ready
