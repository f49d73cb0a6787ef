"""The instruments' state in the state file (estimator.algorithm iv): an instrument path
restored from its snapshot continues bit for bit (the auxiliary model with its bare fit and
waiting rows, the delayed regressors, the strength sums behind rho_min); a pipeline saved in
the middle of a severe-gust maneuver and loaded into a fresh one holds the saved instruments
exactly and continues as the uninterrupted estimation does; crafted instrument entries are
refused naming the field; a state without iv has none."""

from __future__ import annotations

import json

import numpy as np
import pytest
from scipy.linalg import expm
from state_resume import by_file, contents, in_memory

from rls_uncertainty import cli
from rls_uncertainty.datapath.inputs import feed
from rls_uncertainty.datapath.instrument_path import InstrumentPath
from rls_uncertainty.datapath.pipeline import Pipeline
from rls_uncertainty.errors import StateFileError
from rls_uncertainty.estimator import EstimatorBank
from rls_uncertainty.instruments import InstrumentLayout, short_period_matrices
from rls_uncertainty.offline.bags import read_inputs
from rls_uncertainty.settings.parameters import node_config, pipeline_config
from rls_uncertainty.settings.sources import load_parameters_file
from rls_uncertainty.simulation.t2 import T2_TRUE
from rls_uncertainty.state_file import EstimatorState, load_state, save_state

from source_tree import ROOT

QBAR, V = 1500.0, 40.8
TRUE = np.array([[0.1, T2_TRUE["CZ_alpha"], T2_TRUE["CZ_delta_e"], 0.0],
                 [0.02, T2_TRUE["Cm_alpha"], T2_TRUE["Cm_q"], T2_TRUE["Cm_delta_e"]]])


def iv_config(source="excitation", **params):
    return pipeline_config({**load_parameters_file("t2"), "estimator.algorithm": "iv",
                            "instruments.source": source, **params})


def maneuver(config, n, seed=0):
    """Rows ``(stamp, X, z, u)`` of the true short-period model (its exact zero-order hold)
    driven by a random staircase input, with sensor noise on the states and the outputs."""
    rng = np.random.default_rng(seed)
    A, B = short_period_matrices(InstrumentLayout(config.models).derivatives(TRUE), QBAR, V, config.aircraft)
    M = np.zeros((3, 3))
    M[:2, :2], M[:2, 2] = A, B
    E = expm(M / config.rate)
    u = np.repeat(rng.normal(0.0, 0.02, n // 5 + 1), 5)[:n]
    s, rows, cbar = np.zeros(2), [], config.aircraft.cbar
    for k in range(n):
        a, q = s + rng.normal(0.0, 1e-3, 2)
        X = np.zeros((2, 4))
        X[0, :3] = 1.0, a, u[k]
        X[1] = 1.0, a, q * cbar / (2 * V), u[k]
        z = np.einsum("mi,mi->m", X, TRUE) + rng.normal(0.0, 1e-3, 2)
        rows.append((k * config.period_ns, X, z, float(u[k])))
        s = E[:2, :2] @ s + E[:2, 2] * u[k]
    return rows


def step(path, bank, row):
    """One row through ``path`` into ``bank`` (as the pipeline does): the rows it gives, with
    the path's rho_min after them."""
    t, X, z, u = row
    estimates = bank.theta_all() if bank.k else None
    out, _dropped = path.update(t, X, z, u, QBAR, V, estimates)
    for r in out:
        bank.update(r.X, r.z, instruments=r.zeta)
    return [(r.stamp_ns, r.X, r.z, r.zeta) for r in out], path.rho_min.copy()


# ------------------------------------------------------------------ (a) the components
@pytest.mark.parametrize("source,cut", [("excitation", 12), ("excitation", 161), ("delayed", 7), ("delayed", 161)],
                         ids=["rows-waiting", "model-running", "delay-filling", "delay-gap"])
def test_a_restored_instrument_path_continues_bit_for_bit(source, cut):
    """At ``cut`` the path's snapshot goes into a fresh path (and the bank's into a fresh
    bank); over the following rows the rows given, their instruments and rho_min equal those
    of the path that went on, bit for bit. The snapshot is a copy: continuing changes none of it.
    With delayed instruments a gap in the stamps just before the cut: rows after the cut whose
    row a delay earlier is missing are dropped by both."""
    config = iv_config(source)
    rows = maneuver(config, 400)
    if source == "delayed":
        rows = rows[: cut - 3] + rows[cut - 2:]  # a gap: the ring holds only the rows after it
    path, bank = InstrumentPath(config), EstimatorBank([3, 4], config.estimator)
    for row in rows[:cut]:
        step(path, bank, row)
    saved, saved_bank = path.snapshot(), bank.state()
    frozen = {k: v.tobytes() for k, v in saved["arrays"].items()}
    if source == "excitation":
        assert (saved["counters"]["waiting"] > 0) == (cut < 50) and saved["counters"]["has_model"] == (cut > 50)
    else:
        assert 0 < saved["counters"]["history"] <= path.aux.delay + 1
    resumed, resumed_bank = InstrumentPath(config), EstimatorBank.from_state(saved_bank)
    resumed.restore(json.loads(json.dumps({"counters": saved["counters"]})) | {"arrays": saved["arrays"]})
    given = 0
    for row in rows[cut:]:
        (a, rho_a), (b, rho_b) = step(path, bank, row), step(resumed, resumed_bank, row)
        assert len(a) == len(b)
        for ra, rb in zip(a, b, strict=True):
            assert ra[0] == rb[0]
            for xa, xb in zip(ra[1:], rb[1:], strict=True):
                np.testing.assert_array_equal(xa, xb)
        np.testing.assert_array_equal(rho_a, rho_b)
        given += len(a)
    assert given > 0.8 * (len(rows) - cut) and np.isfinite(path.rho_min).all()
    np.testing.assert_array_equal(resumed_bank.theta_all(), bank.theta_all())
    assert {k: v.tobytes() for k, v in saved["arrays"].items()} == frozen


def test_the_strength_sums_continue_bit_for_bit():
    """InstrumentStrength alone: restored sums give rho_min equal to the uninterrupted ones
    after every following sample, and a restore of another shape is refused."""
    config = iv_config()
    rng = np.random.default_rng(8)
    a, b = InstrumentPath(config).strength, InstrumentPath(config).strength
    for _ in range(30):
        X = rng.normal(size=(2, 4))
        a.update(X, X + rng.normal(size=(2, 4)))
    b.restore(a.snapshot())
    for _ in range(20):
        X = rng.normal(size=(2, 4))
        Z = X + rng.normal(size=(2, 4))
        a.update(X, Z)
        b.update(X, Z)
        np.testing.assert_array_equal(a.rho_min(), b.rho_min())
    bad = a.snapshot()
    bad["arrays"]["S_zx"] = bad["arrays"]["S_zx"][:, :3]
    with pytest.raises(ValueError, match="S_zx"):
        b.restore(bad)


# ------------------------------------------------------------------ (b) a pipeline resumed
@pytest.fixture(scope="module")
def severe(tmp_path_factory):
    """A simulated maneuver in severe gusts with its injected excitation (make-bag), and the
    configuration that estimates it with instrumental variables."""
    out = tmp_path_factory.mktemp("severe") / "c"
    assert cli.main(["make-bag", "--campaign", "1", "--gust-intensity", "severe", "--seed", "2010",
                     "--out", str(out)]) == 0
    params = load_parameters_file(ROOT / "config" / "t2_turbulence.yaml")
    return pipeline_config(params), read_inputs(out / "m001", dict(node_config(params).topics))[0]


def run(config, messages, cut=None, resume=None):
    """The last output of a pipeline fed ``messages``; at message ``cut`` ``resume(pipe)``
    gives the pipeline that goes on."""
    pipe, last = Pipeline(config), None
    for i, (kind, _stamp, msg) in enumerate(messages):
        if i == cut:
            pipe = resume(pipe)
        for out in feed(pipe, kind, msg):
            last = out
    return last


def identical(a, b):
    return a.keys() == b.keys() and all(a[k].dtype == b[k].dtype and a[k].tobytes() == b[k].tobytes() for k in a)


@pytest.mark.parametrize("fraction", [0.04, 0.5], ids=["rows-waiting", "half"])
def test_a_resumed_iv_pipeline_holds_the_saved_instruments_and_goes_on_as_before(severe, tmp_path, fraction):
    """Saved at ``fraction`` of the maneuver and loaded into a fresh pipeline: saved again at
    once, the file holds the same arrays bit for bit (bank and instruments) and the same meta.
    The final estimates and standard errors equal those of the run whose bank and instrument
    path were handed over in memory (the resume's only other change, the restart of the
    inputs and the differentiator, is the same in both), bit for bit."""
    config, messages = severe
    cut, seen = int(len(messages) * fraction), []
    resumed = run(config, messages, cut, by_file(config, tmp_path / "s.npz", seen))
    reference = run(config, messages, cut, in_memory(config))
    ((arrays, meta), (again, meta_again)), = seen
    assert identical(arrays, again) and meta == meta_again
    assert any(k.startswith("iv_") for k in arrays) and "instruments" in meta
    counters = meta["instruments"]
    assert (counters["waiting"] > 0) == (fraction < 0.1) and counters["has_model"] == (fraction > 0.1)
    np.testing.assert_array_equal(resumed.theta, reference.theta)
    np.testing.assert_array_equal(resumed.se, reference.se)


def test_the_instrument_state_brings_a_resume_closer_to_the_continuous_run(severe, tmp_path):
    """Against the uninterrupted run, the estimates resumed with the saved instruments differ
    less (in standard errors, over every parameter) than those resumed from the same file with
    the instruments' entries replaced by a fresh path's (instruments restarted from nothing)."""
    config, messages = severe
    cut, path, blank = len(messages) // 2, tmp_path / "s.npz", tmp_path / "blank.npz"
    Pipeline(config).save_state(blank)
    fresh_arrays, fresh_meta = contents(blank)

    def without_instruments(pipe):
        pipe.save_state(path)
        arrays, meta = contents(path)
        arrays |= {k: v for k, v in fresh_arrays.items() if k.startswith("iv_")}
        np.savez(path, meta=np.array(json.dumps(meta | {"instruments": fresh_meta["instruments"]})), **arrays)
        fresh = Pipeline(config)
        fresh.load_state(path)
        return fresh

    continuous = run(config, messages)
    resumed = run(config, messages, cut, by_file(config, path, []))
    restarted = run(config, messages, cut, without_instruments)
    real = np.isfinite(continuous.theta)

    def distance(out):
        return float(np.sum(((out.theta - continuous.theta)[real] / continuous.se[real]) ** 2))

    assert real.sum() == 7 and 0 < distance(resumed) < distance(restarted)


# ------------------------------------------------------------------ (c) crafted entries
def saved_file(tmp_path, source="excitation", n=200, name="iv.npz"):
    config = iv_config(source)
    path, bank = InstrumentPath(config), EstimatorBank([3, 4], config.estimator)
    for row in maneuver(config, n):
        step(path, bank, row)
    file = tmp_path / name
    save_state(file, EstimatorState(bank, bank.k, np.zeros(2), np.ones(2), path.snapshot()), config.fingerprint())
    return config, file


def load(config, file):
    return load_state(file, config.fingerprint(), expect=((3, 4), config.estimator), instruments=InstrumentPath(config))


def refused(config, file, needle):
    with pytest.raises(StateFileError) as info:
        load(config, file)
    text = str(info.value)
    assert text.startswith(f"{file}: ") and needle in text and "\n" not in text, text


def unstable(a):
    a["iv_Phi"] = np.array([[1.2, 0.0], [0.0, 0.5]])


def write(file, arrays, meta):
    np.savez(file, meta=np.array(json.dumps(meta)), **arrays)
    return file


@pytest.mark.parametrize("source,n,damage,needle", [
    ("excitation", 200, lambda a, m: a.pop("iv_Phi"), "field 'arrays.iv_Phi' is missing"),
    ("excitation", 200, lambda a, m: a.update(iv_evil=np.zeros(2)), "field 'arrays.iv_evil' is not part of this"),
    ("excitation", 200, lambda a, m: a.update(iv_bare_A=a["iv_bare_A"][:, :3]),
     "field 'arrays.iv_bare_A' has shape (2, 3, 4), the configuration implies (2, 4, 4)"),
    ("excitation", 200, lambda a, m: a["iv_S_zz"].__setitem__((1, 2, 2), np.nan),
     "field 'arrays.iv_S_zz' holds NaN or infinite values"),
    ("excitation", 200, lambda a, m: a["iv_rho_min"].__setitem__(0, 1.5), "field 'arrays.iv_rho_min' must hold"),
    ("excitation", 200, lambda a, m: unstable(a), "field 'arrays.iv_Phi' is not the discrete model of a stable"),
    ("excitation", 200, lambda a, m: a.update(iv_state=a["iv_state"].astype(np.float32)),
     "field 'arrays.iv_state' has dtype <f4, expected <f8"),
    ("excitation", 200, lambda a, m: m["instruments"].update(since_refresh=25),
     "field 'instruments.since_refresh' must be in [0, 24], found 25"),
    ("excitation", 200, lambda a, m: m["instruments"].update(has_model="yes"),
     "field 'instruments.has_model' must be true or false"),
    ("excitation", 200, lambda a, m: m["instruments"].pop("bare_k"), "field 'instruments.bare_k' is missing"),
    ("excitation", 200, lambda a, m: m["instruments"].update(evil=1), "field 'instruments.evil' is not part of"),
    ("excitation", 200, lambda a, m: m.pop("instruments"), "field 'instruments' is missing"),
    ("excitation", 200, lambda a, m: m["instruments"].update(source="delayed"),
     "another aircraft, model or estimator configuration: field 'instruments.source'"),
    ("excitation", 200, lambda a, m: m["instruments"].update(waiting=3), "field 'instruments.waiting' must be 0 once"),
    ("excitation", 200, lambda a, m: m["instruments"].update(strength_k=-1),
     "field 'instruments.strength_k' must be in [0, "),
    ("excitation", 10, lambda a, m: m["instruments"].update(waiting=11),
     "field 'arrays.iv_backlog_V' has shape (10,), the configuration implies (11,)"),
    ("excitation", 10, lambda a, m: m["instruments"].update(waiting=1501), "field 'instruments.waiting' must be in"),
    ("excitation", 10, lambda a, m: a.update(iv_backlog_tag=a["iv_backlog_tag"][::-1].copy()),
     "field 'arrays.iv_backlog_tag' must hold increasing stamps"),
    ("excitation", 10, lambda a, m: a.update(iv_backlog_tag=a["iv_backlog_tag"].astype(float)),
     "field 'arrays.iv_backlog_tag' has dtype <f8, expected <i8"),
    ("excitation", 10, lambda a, m: a["iv_Phi"].__setitem__((0, 0), 0.5),
     "field 'arrays.iv_Phi' must be zero (with the state and Gamma) while there is no model"),
    ("delayed", 200, lambda a, m: a["iv_history_stamp"].__setitem__(0, a["iv_history_stamp"][0] - 20_000_000),
     "field 'arrays.iv_history_stamp' spans more than the delay of 500000000 ns"),
    ("delayed", 200, lambda a, m: a["iv_history_stamp"].__setitem__(1, a["iv_history_stamp"][0]),
     "field 'arrays.iv_history_stamp' must hold increasing stamps"),
    ("delayed", 200, lambda a, m: m["instruments"].update(history=27),
     "field 'instruments.history' must be in [0, 26]"),
], ids=lambda v: v if isinstance(v, str) and not v.startswith("field") else None)
def test_crafted_instrument_entries_are_refused_naming_the_field(tmp_path, source, n, damage, needle):
    config, file = saved_file(tmp_path, source, n)
    arrays, meta = contents(file)
    assert load(config, file).instruments is not None  # undamaged: loaded
    damage(arrays, meta)
    refused(config, write(tmp_path / "crafted.npz", arrays, meta), needle)


def test_a_state_without_iv_has_no_instrument_entries_and_an_iv_state_needs_its_path(tmp_path):
    """An rls pipeline's file has none (one added is refused); an iv state read without the
    instrument path to continue is refused naming the field, and so is a format-7 file."""
    config = pipeline_config(load_parameters_file("t2"))
    file = tmp_path / "rls.npz"
    Pipeline(config).save_state(file)
    arrays, meta = contents(file)
    assert "instruments" not in meta and not [k for k in arrays if k.startswith("iv_")]
    assert load_state(file, config.fingerprint()).instruments is None
    with pytest.raises(StateFileError, match=r"field 'arrays\.iv_Phi' is not part of this configuration's state"):
        load_state(write(tmp_path / "extra.npz", arrays | {"iv_Phi": np.zeros((2, 2))}, meta), config.fingerprint())
    iv, iv_file = saved_file(tmp_path)
    with pytest.raises(StateFileError, match=r"field 'instruments' is not part of a state file"):
        load_state(iv_file, iv.fingerprint())
    arrays, meta = contents(iv_file)
    old = write(tmp_path / "old.npz", arrays, meta | {"format": 7})
    with pytest.raises(StateFileError) as info:
        load(iv, old)
    assert str(info.value) == (f"{old}: state format 7, this version reads {EstimatorBank.STATE_FORMAT} (saved by "
                               "another version; delete it to start afresh)")
