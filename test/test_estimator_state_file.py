"""The estimator state file (rls_uncertainty.estimator.state_file): a saved bank continues bit for bit,
files of another configuration or format, corrupt or missing files are refused by name, no
pickle is involved, and a failed save leaves the previous file as it was."""

import json

import numpy as np
import pytest

from rls_uncertainty.errors import StateFileError
from rls_uncertainty.estimator import EstimatorBank
from rls_uncertainty.estimator.state_file import EstimatorState, load_state, save_state

FINGERPRINT = {"aircraft": [1.0, 2.0], "models": [["CZ", "1", "alpha", "delta_e"], ["Cm", "1", "q_hat"]], "n_lags": 10}


def fed_bank(n=300, seed=4):
    rng = np.random.default_rng(seed)
    bank = EstimatorBank((3, 2), 10)
    X = rng.standard_normal((n, 2, 3))
    X[:, 1, 2] = 0.0  # padding of the two-parameter model
    z = rng.standard_normal((n, 2))
    for k in range(n):
        bank.update(X[k], z[k])
    return bank, z


def saved(tmp_path):
    bank, z = fed_bank()
    path = tmp_path / "state.npz"
    save_state(path, EstimatorState(bank, 300, z.sum(axis=0), (z * z).sum(axis=0)), FINGERPRINT)
    return path


def test_a_saved_state_continues_bit_identically(tmp_path):
    bank, z = fed_bank()
    path = tmp_path / "state.npz"
    save_state(path, EstimatorState(bank, 300, z.sum(axis=0), (z * z).sum(axis=0)), FINGERPRINT)
    state = load_state(path, FINGERPRINT)
    resumed = state.bank
    assert state.samples_used == 300
    np.testing.assert_array_equal(state.output_sum, z.sum(axis=0))
    np.testing.assert_array_equal(state.output_sum_squares, (z * z).sum(axis=0))
    np.testing.assert_array_equal(resumed.theta_all(), bank.theta_all())
    np.testing.assert_array_equal(resumed.standard_errors_all(), bank.standard_errors_all())
    row = np.array([[1.0, 0.01, 0.02], [1.0, 0.5, 0.0]])
    bank.update(row, [0.3, -0.1])
    resumed.update(row, [0.3, -0.1])
    np.testing.assert_array_equal(resumed.theta_all(), bank.theta_all())
    np.testing.assert_array_equal(resumed.standard_errors_all("conventional"), bank.standard_errors_all("conventional"))


def test_the_file_is_numpy_arrays_and_json_without_pickle(tmp_path):
    path = saved(tmp_path)
    with np.load(path, allow_pickle=False) as data:
        assert all(data[k].dtype != object for k in data.files)
        meta = json.loads(str(data["meta"]))
    assert meta["format"] == EstimatorBank.STATE_FORMAT
    assert meta["fingerprint"] == FINGERPRINT
    assert meta["samples_used"] == 300
    assert sorted(meta) == ["bank_config", "bank_counters", "fingerprint", "format", "samples_used", "zsq", "zsum"]


def test_another_configuration_is_refused(tmp_path):
    path = saved(tmp_path)
    with pytest.raises(StateFileError, match="another"):
        load_state(path, {**FINGERPRINT, "n_lags": 11})
    # Tuples (as a configuration builds them) compare as the lists JSON stores.
    as_tuples = {**FINGERPRINT, "models": [tuple(m) for m in FINGERPRINT["models"]]}
    assert load_state(path, as_tuples).samples_used == 300


def test_unreadable_missing_and_foreign_files_are_refused_by_name(tmp_path):
    path = saved(tmp_path)
    bad = tmp_path / "bad.npz"
    bad.write_bytes(b"not a state file")
    with pytest.raises(StateFileError, match="not a readable"):
        load_state(bad, FINGERPRINT)
    with pytest.raises(StateFileError, match="no such"):
        load_state(tmp_path / "missing.npz", FINGERPRINT)
    # A file written by another version of the state layout is refused by name, not misread.
    with np.load(path) as data:
        arrays = {k: data[k] for k in data.files}
    meta = json.loads(str(arrays.pop("meta")))
    meta["format"] = 1
    old = tmp_path / "old.npz"
    np.savez(old, meta=np.array(json.dumps(meta)), **arrays)
    with pytest.raises(StateFileError, match="state format 1"):
        load_state(old, FINGERPRINT)


@pytest.mark.parametrize("damage", ["drop_array", "reshape_array", "short_zsum", "no_samples_used"])
def test_an_inconsistent_state_is_refused(tmp_path, damage):
    path = saved(tmp_path)
    with np.load(path) as data:
        arrays = {k: data[k] for k in data.files}
    meta = json.loads(str(arrays.pop("meta")))
    if damage == "drop_array":
        arrays.pop("dispersion")
    elif damage == "reshape_array":
        arrays["dispersion"] = arrays["dispersion"][..., :-1]
    elif damage == "short_zsum":
        meta["zsum"] = meta["zsum"][:1]
    else:
        del meta["samples_used"]
    broken = tmp_path / "broken.npz"
    np.savez(broken, meta=np.array(json.dumps(meta)), **arrays)
    with pytest.raises(StateFileError, match="inconsistent"):
        load_state(broken, FINGERPRINT)


def test_a_failed_save_leaves_the_previous_file_and_no_temporary(tmp_path):
    path = saved(tmp_path)
    before = path.read_bytes()
    bank, z = fed_bank(seed=9)
    with pytest.raises(TypeError):  # a fingerprint JSON cannot hold
        save_state(path, EstimatorState(bank, 1, z.sum(axis=0), z.sum(axis=0)), {"x": object()})
    assert path.read_bytes() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["state.npz"]
    # A successful save replaces it.
    save_state(path, EstimatorState(bank, 1, z.sum(axis=0), z.sum(axis=0)), FINGERPRINT)
    assert load_state(path, FINGERPRINT).samples_used == 1
