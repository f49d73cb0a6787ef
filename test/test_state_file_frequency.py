"""The frequency-domain record in the state file (estimator.method frequency or both): a bank
restored from its snapshot continues bit for bit as the uninterrupted bank does; a pipeline
saved in the middle of a maneuver and loaded into a fresh one holds the saved record exactly
and publishes what the uninterrupted estimation publishes; crafted record entries are refused in
one line naming the field; a time-domain state has none."""

from __future__ import annotations

import json

import numpy as np
import pytest
from state_resume import by_file, contents, in_memory

from rls_uncertainty import cli
from rls_uncertainty.datapath.frequency_path import FrequencyPath
from rls_uncertainty.datapath.inputs import feed
from rls_uncertainty.datapath.instrument_path import InstrumentPath
from rls_uncertainty.datapath.pipeline import Pipeline
from rls_uncertainty.errors import StateFileError
from rls_uncertainty.frequency import FrequencyBank, FrequencyOptions
from rls_uncertainty.frequency import state as record
from rls_uncertainty.frequency.state import RESULTS
from rls_uncertainty.offline.bags import read_inputs
from rls_uncertainty.settings.parameters import node_config, pipeline_config
from rls_uncertainty.settings.sources import load_parameters_file
from rls_uncertainty.state_file import load_state

from source_tree import ROOT

KINDS = ("corrected", "conventional")


# ------------------------------------------------------------------ (a) the bank
def rows(n, instruments, seed=3):
    """Two models (2 and 3 regressors) of a noisy staircase maneuver with colored output noise;
    with ``instruments``, noisy copies of the regressors as instruments."""
    rng = np.random.default_rng(seed)
    u = np.repeat(rng.normal(0.0, 1.0, n // 7 + 1), 7)[:n]
    x = np.convolve(u, np.exp(-np.arange(20) / 5.0))[:n]
    X = np.zeros((n, 2, 3))
    X[:, 0, :2] = np.c_[x, u]
    X[:, 1] = np.c_[x, np.gradient(x), u]
    noise = np.convolve(rng.normal(0.0, 0.05, n + 10), np.ones(4) / 4)[:n]
    z = np.c_[X[:, 0] @ [-4.0, -0.3, 0.0], X[:, 1] @ [-0.8, -9.0, -1.2]] + noise[:, None] + 0.2
    W = X + rng.normal(0.0, 0.01, X.shape) if instruments else None
    return X, z, W


def results(bank):
    out = [bank.theta_all(), bank.ready, bank.withheld, bank.solved, *bank.fit(), np.array(bank.evaluated_at),
           np.array(bank.repairs)]
    return out + [bank.standard_errors_all(k) for k in KINDS]


def feed_bank(bank, X, z, W, start, stop, every):
    seen = []
    for i in range(start, stop):
        bank.update(X[i], z[i], None if W is None else W[i])
        if bank.n_samples % every == 0:
            seen.append(results(bank))
    return seen


@pytest.mark.parametrize("instruments", [False, True], ids=["ls", "iv"])
@pytest.mark.parametrize("every,trim,cut", [(1, 1, 0), (1, 1, 1), (1, 5, 3), (1, 5, 173), (4, 5, 170),
                                            (4, 5, 171), (4, 1, 172)])
def test_a_restored_bank_continues_bit_for_bit(instruments, every, trim, cut):
    """A bank fed the first ``cut`` rows, its snapshot restored into a fresh bank fed the rest:
    every published result after the cut, and the final record, equal the uninterrupted bank's
    bit for bit (cut before, inside and after the trim, on and between evaluations)."""
    options = FrequencyOptions(rate_hz=50.0, f_min=0.1, f_max=2.0, f_step=0.05, trim_samples=trim, n_lags=6,
                               every=every)
    X, z, W = rows(400, instruments)
    whole = FrequencyBank([2, 3], options, instruments=instruments)
    feed_bank(whole, X, z, W, 0, cut, every)
    first = FrequencyBank([2, 3], options, instruments=instruments)
    feed_bank(first, X, z, W, 0, cut, every)
    saved = record.snapshot(first)
    resumed = FrequencyBank([2, 3], options, instruments=instruments)
    record.restore(resumed, {**saved, "counters": json.loads(json.dumps(saved["counters"]))})
    if cut and cut % every == 0:  # the last evaluation's results are there again
        for a, b in zip(results(resumed), results(whole), strict=True):
            assert a.tobytes() == b.tobytes()
    after, expected = (feed_bank(b, X, z, W, cut, len(z), every) for b in (resumed, whole))
    assert len(after) == len(expected) > 50 and any(r[1].all() for r in expected)
    for got, want in zip(after, expected, strict=True):
        for a, b in zip(got, want, strict=True):
            assert a.dtype == b.dtype and a.tobytes() == b.tobytes()
    ends = record.snapshot(resumed), record.snapshot(whole)
    assert ends[0]["counters"] == ends[1]["counters"]
    assert all(ends[0]["arrays"][k].tobytes() == v.tobytes() for k, v in ends[1]["arrays"].items())


def test_a_snapshot_is_a_copy_and_restore_checks_shapes():
    options = FrequencyOptions(rate_hz=50.0, n_lags=4)
    X, z, _ = rows(60, False)
    bank = FrequencyBank([2, 3], options)
    feed_bank(bank, X, z, None, 0, 60, 1)
    saved = record.snapshot(bank)
    frozen = {k: v.tobytes() for k, v in saved["arrays"].items()}
    feed_bank(bank, X, z, None, 0, 10, 1)
    assert {k: v.tobytes() for k, v in saved["arrays"].items()} == frozen
    assert set(frozen) == {"fq_transform", "fq_first", "fq_trim_sum", "fq_lag_sums", "fq_lag_buffer"} | set(RESULTS)
    bad = {**saved, "arrays": {**saved["arrays"], "fq_lag_sums": np.zeros((2, 3))}}
    with pytest.raises(ValueError, match="fq_lag_sums"):
        record.restore(FrequencyBank([2, 3], options), bad)
    with pytest.raises(ValueError, match="counters"):
        record.restore(FrequencyBank([2, 3], options), {**saved, "counters": {**saved["counters"], "evaluated_at": 61}})


# ------------------------------------------------------------------ (b) a pipeline resumed
def run(config, messages, cut=None, resume=None):
    """Every output of a pipeline fed ``messages`` from message ``cut`` on; at message ``cut``
    ``resume(pipe)`` gives the pipeline that goes on."""
    pipe, outs = Pipeline(config), []
    for i, (kind, _stamp, msg) in enumerate(messages):
        if i == cut:
            pipe = resume(pipe)
        outs.extend(out for out in feed(pipe, kind, msg) if cut is None or i >= cut)
    return outs


def t2(method, **extra):
    params = {**load_parameters_file(ROOT / "config" / "t2.yaml"), "estimator.method": method, **extra}
    return pipeline_config(params), read_inputs(ROOT / "bags" / "t2_maneuver", dict(node_config(params).topics))[0]


@pytest.fixture(scope="module")
def severe_iv(tmp_path_factory):
    """A simulated maneuver in severe gusts with its injected excitation (make-bag), estimated
    with instrumental variables by both methods."""
    out = tmp_path_factory.mktemp("severe") / "c"
    assert cli.main(["make-bag", "--campaign", "1", "--gust-intensity", "severe", "--seed", "5",
                     "--out", str(out)]) == 0
    params = {**load_parameters_file(ROOT / "config" / "t2_turbulence.yaml"), "estimator.method": "both"}
    assert params["estimator.algorithm"] == "iv"
    return pipeline_config(params), read_inputs(out / "m001", dict(node_config(params).topics))[0]


def same(a, b):
    return a.dtype == b.dtype and a.tobytes() == b.tobytes()


def check_resume(config, messages, tmp_path, fraction=0.5):
    cut, seen = round(len(messages) * fraction), []
    resumed = run(config, messages, cut, by_file(config, tmp_path / "s.npz", seen))
    reference = run(config, messages, cut, in_memory(config))
    ((arrays, meta), (again, meta_again)), = seen
    assert arrays.keys() == again.keys() and all(same(arrays[k], again[k]) for k in arrays)
    assert meta == meta_again and meta["frequency"]["n"] > 100
    assert {k for k in arrays if k.startswith("fq_")} >= {"fq_transform", "fq_lag_sums"}
    published = [o for o in reference if o.frequency is not None]
    assert len(resumed) == len(reference) and len(published) > 90 and published[-1].frequency.ready.any()
    for got, want in zip(resumed, reference, strict=True):
        assert got.stamp_ns == want.stamp_ns and same(got.theta, want.theta) and same(got.se, want.se)
        assert (got.frequency is None) == (want.frequency is None)
        if want.frequency is not None:
            assert all(same(a, b) for a, b in zip(got.frequency, want.frequency, strict=True))
    return meta


@pytest.mark.parametrize("method,extra", [("both", {}), ("frequency", {}), ("both", {"frequency.every": 3})],
                         ids=["both", "frequency", "both-every-3"])
def test_a_resumed_pipeline_continues_the_frequency_record(method, extra, tmp_path):
    """Saved half way through the T-2 maneuver and loaded into a fresh pipeline: saved again
    at once, the file holds the same arrays and meta; every output after the resume, time and
    frequency domain, equals that of the run whose banks were handed over in memory (the
    resume's only other change, the restart of the inputs and the differentiator, is the same in
    both), bit for bit; with ``frequency.every: 3`` too, whether saved on an evaluation or
    between two."""
    config, messages = t2(method, **extra)
    meta = check_resume(config, messages, tmp_path)
    if extra:  # cuts a message apart until one was saved on an evaluation and one between two
        kinds = {meta["frequency"]["n"] % 3 == 0}
        for d in range(1, 20):
            if len(kinds) == 2:
                break
            later = check_resume(config, messages, tmp_path, fraction=0.5 + d / len(messages))
            kinds.add(later["frequency"]["n"] % 3 == 0)
        assert kinds == {True, False}
    assert "instruments" not in meta and meta["fingerprint"]["frequency"]["every"] == config.frequency.every


def test_a_resumed_iv_pipeline_continues_the_instrumented_frequency_record(severe_iv, tmp_path):
    config, messages = severe_iv
    meta = check_resume(config, messages, tmp_path)
    assert "instruments" in meta
    arrays, _ = contents(tmp_path / "s.npz")
    assert arrays["fq_cross"].any()


def test_the_resumed_record_is_not_a_new_one(tmp_path):
    """Without the record (the file's ``fq_`` entries and counters replaced by a fresh
    path's), the frequency-domain estimates after the resume differ from the handed-over run's."""
    config, messages = t2("both")
    cut, path = len(messages) // 2, tmp_path / "s.npz"
    fresh = FrequencyPath(config).snapshot()

    def blank(pipe):
        pipe.save_state(path)
        arrays, meta = contents(path)
        arrays |= fresh["arrays"]
        np.savez(path, meta=np.array(json.dumps(meta | {"frequency": fresh["counters"]})), **arrays)
        p = Pipeline(config)
        p.load_state(path)
        return p

    restarted = [o.frequency for o in run(config, messages, cut, blank) if o.frequency is not None]
    reference = [o.frequency for o in run(config, messages, cut, in_memory(config)) if o.frequency is not None]
    assert len(restarted) < len(reference) or not np.array_equal(restarted[-1].theta, reference[-1].theta,
                                                                  equal_nan=True)


# ------------------------------------------------------------------ (c) crafted entries
@pytest.fixture(scope="module")
def saved(tmp_path_factory):
    config, messages = t2("both")
    pipe = Pipeline(config)
    for kind, _stamp, msg in messages[: len(messages) // 2]:
        list(feed(pipe, kind, msg))
    path = tmp_path_factory.mktemp("saved") / "both.npz"
    pipe.save_state(path)
    return config, path


def tampered(tmp_path, path, change_arrays=None, change_meta=None):
    arrays, meta = contents(path)
    if change_arrays:
        change_arrays(arrays)
    if change_meta:
        change_meta(meta)
    out = tmp_path / "tampered.npz"
    np.savez(out, meta=np.array(json.dumps(meta)), **arrays)
    return out


def refused(config, file, needle):
    with pytest.raises(StateFileError) as info:
        Pipeline(config).load_state(file)
    text = str(info.value)
    assert text.startswith(f"{file}: ") and needle in text and "\n" not in text, text


def test_the_saved_file_loads(saved):
    config, path = saved
    pipe = Pipeline(config)
    pipe.load_state(path)
    assert pipe.frequency.bank.n_samples == contents(path)[1]["frequency"]["n"] > 0


@pytest.mark.parametrize("name", ["fq_transform", "fq_first", "fq_trim_sum", "fq_lag_sums", "fq_lag_buffer",
                                  *RESULTS])
def test_a_frequency_entry_of_the_wrong_shape_non_finite_or_missing_is_refused(saved, tmp_path, name):
    """Every entry of the wrong shape, or missing, is refused naming it; a NaN in the record
    (an infinity in the results, which hold NaN where a model has none) too."""
    config, path = saved

    def shorter(a):
        a[name] = a[name][..., :-1]

    def bad_value(a):
        a[name] = a[name].copy()
        if a[name].dtype == bool:  # a model ready that is not solved
            a[name][:] = [[True, True], [False, False], [False, False]]
        else:
            a[name].flat[-1] = np.inf if name in RESULTS else np.nan

    def missing(a):
        del a[name]

    refused(config, tampered(tmp_path, path, shorter), f"arrays.{name}")
    refused(config, tampered(tmp_path, path, bad_value), f"arrays.{name}")
    refused(config, tampered(tmp_path, path, missing), f"arrays.{name}' is missing")


def test_negative_standard_errors_are_refused(saved, tmp_path):
    config, path = saved
    refused(config, tampered(tmp_path, path, lambda a: a.update(fq_se=-np.abs(a["fq_se"]) - 1.0)),
            "arrays.fq_se' must not be negative")


@pytest.mark.parametrize("key,value,needle", [
    ("n", -1, "frequency.n"), ("n", 1.5, "frequency.n"), ("evaluated_at", 10**9, "frequency.evaluated_at"),
    ("repairs", "x", "frequency.repairs"), ("due", 1, "frequency.due"), ("due", True, "frequency.due"),
])
def test_frequency_counters_out_of_range_are_refused(saved, tmp_path, key, value, needle):
    config, path = saved

    def change(meta):
        meta["frequency"][key] = value
    refused(config, tampered(tmp_path, path, change_meta=change), needle)


def test_a_record_before_the_first_sample_must_be_zeros(saved, tmp_path):
    config, path = saved

    def change(meta):
        meta["frequency"].update(n=0, evaluated_at=0, due=False)
    refused(config, tampered(tmp_path, path, change_meta=change), "arrays.fq_")


def test_records_of_other_methods_and_settings_are_refused(saved, tmp_path):
    """A ``both`` state is refused by a time-domain configuration (its record is no part of
    that state) and by one with other ``frequency.*`` settings; a time-domain state by a
    ``both`` configuration (the record is missing)."""
    config, path = saved
    time_config, _ = t2("time")
    with pytest.raises(StateFileError, match="frequency"):
        Pipeline(time_config).load_state(path)
    other = pipeline_config({**load_parameters_file(ROOT / "config" / "t2.yaml"), "estimator.method": "both",
                             "frequency.every": config.frequency.every + 1})
    with pytest.raises(StateFileError, match="saved with another"):
        Pipeline(other).load_state(path)
    Pipeline(time_config).save_state(tmp_path / "time.npz")
    fingerprint_both = config.fingerprint()
    with pytest.raises(StateFileError):
        load_state(tmp_path / "time.npz", fingerprint_both, frequency=FrequencyPath(config))
    refused(config, tampered(tmp_path, tmp_path / "time.npz",
                             change_meta=lambda m: m.update(fingerprint=fingerprint_both)), "frequency")


def test_a_format_8_file_is_refused_by_name(saved, tmp_path):
    config, path = saved
    refused(config, tampered(tmp_path, path, change_meta=lambda m: m.update(format=8)),
            "state format 8, this version reads 9")


def test_instruments_and_record_are_checked_together(severe_iv, tmp_path):
    """With iv and both, the file holds both prefixes; a NaN in the instruments' cross sums of
    the record is refused naming it."""
    config, messages = severe_iv
    pipe = Pipeline(config)
    for kind, _stamp, msg in messages[: len(messages) // 2]:
        list(feed(pipe, kind, msg))
    path = tmp_path / "iv.npz"
    pipe.save_state(path)
    arrays, _ = contents(path)
    assert any(k.startswith("iv_") for k in arrays) and "fq_cross" in arrays
    assert isinstance(pipe._iv, InstrumentPath)

    def nan(a):
        a["fq_cross"] = a["fq_cross"].copy()
        a["fq_cross"].flat[0] = np.inf
    refused(config, tampered(tmp_path, path, nan), "arrays.fq_cross")
