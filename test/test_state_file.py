"""The estimator state file (rls_uncertainty.state_file): a saved bank continues bit for bit,
files of another configuration or format, corrupt or missing files are refused by name, no
pickle is involved, and a failed save leaves the previous file as it was. Crafted files (meta
of the wrong type, missing keys, absurd counters, wrong-length arrays, zip entries that would
inflate) are refused with one StateFileError naming the field, before anything large is
allocated; a refused file can be set aside without overwriting anything."""

import io
import json
import os
import socket
import stat
import subprocess
import sys
import tracemalloc
import zipfile
from datetime import UTC, datetime

import numpy as np
import pytest
from bag_samples import no_hang

from rls_uncertainty.errors import StateFileError
from rls_uncertainty.estimator import EstimatorBank, EstimatorOptions
from rls_uncertainty.estimator.options import MAX_LAGS
from rls_uncertainty.state_file import MAX_ENTRIES, EstimatorState, claim, load_state, save_state, set_aside

FINGERPRINT = {"aircraft": [1.0, 2.0], "models": [["CZ", "1", "alpha", "delta_e"], ["Cm", "1", "q_hat"]], "n_lags": 10}


def fed_bank(n=300, seed=4):
    rng = np.random.default_rng(seed)
    bank = EstimatorBank((3, 2), EstimatorOptions(lags=10))
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


def contents(path):
    """The arrays and the decoded meta of a state file (read by numpy, as a person would)."""
    with np.load(path) as data:
        arrays = {k: data[k] for k in data.files}
    return arrays, json.loads(str(arrays.pop("meta")))


def write(path, meta, arrays, *, meta_array=None):
    np.savez(path, meta=np.array(json.dumps(meta)) if meta_array is None else meta_array, **arrays)
    return path


def npy(arr):
    buf = io.BytesIO()
    np.lib.format.write_array(buf, np.asarray(arr), allow_pickle=True)
    return buf.getvalue()


def refused(path, *needles, fingerprint=FINGERPRINT, **kw):
    with pytest.raises(StateFileError) as info:
        load_state(path, fingerprint, **kw)
    text = str(info.value)
    assert text.startswith(f"{path}: ")
    for needle in needles:
        assert needle in text, text
    assert "\n" not in text and len(text) < 400 + len(str(path))
    return text


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
    assert sorted(meta) == ["bank_counters", "fingerprint", "format", "options", "samples_used", "sizes", "zsq", "zsum"]
    assert meta["sizes"] == [3, 2] and EstimatorOptions.from_dict(meta["options"]) == EstimatorOptions(lags=10)


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


@pytest.mark.parametrize("damage,field", [
    ("drop_array", "field 'arrays.lag_sums' is missing"),
    ("reshape_array", "field 'arrays.lag_sums' has shape (2, 10), the configuration implies (2, 11)"),
    ("short_zsum", "field 'zsum' must be a list of 2 numbers"),
    ("no_samples_used", "field 'samples_used' is missing"),
])
def test_an_inconsistent_state_is_refused_naming_the_field(tmp_path, damage, field):
    path = saved(tmp_path)
    arrays, meta = contents(path)
    if damage == "drop_array":
        arrays.pop("lag_sums")
    elif damage == "reshape_array":
        arrays["lag_sums"] = arrays["lag_sums"][..., :-1]
    elif damage == "short_zsum":
        meta["zsum"] = meta["zsum"][:1]
    else:
        del meta["samples_used"]
    broken = write(tmp_path / "broken.npz", meta, arrays)
    with pytest.raises(StateFileError) as info:
        load_state(broken, FINGERPRINT)
    assert str(info.value) == f"{broken}: {field}" or str(info.value).startswith(f"{broken}: {field}")


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


# ------------------------------------------------------------------ crafted files
@pytest.mark.parametrize("meta,needle", [
    ([1, 2], "field 'meta' must be a JSON object, found a list of 2 items"),
    ("just text", "field 'meta' must be a JSON object, found str 'just text'"),
    (None, "field 'meta' must be a JSON object"),
    (3, "field 'meta' must be a JSON object"),
    ({}, "field 'format' is missing"),
    ({"format": "3"}, "state format str '3'"),
])
def test_meta_that_is_not_an_object_or_lacks_the_format_is_refused(tmp_path, meta, needle):
    arrays, _ = contents(saved(tmp_path))
    refused(write(tmp_path / "c.npz", meta, arrays), needle)


def _with(meta, dotted, value):
    meta = json.loads(json.dumps(meta))
    *parents, last = dotted.split(".")
    target = meta
    for p in parents:
        target = target[p]
    if value is KeyError:
        del target[last]
    else:
        target[last] = value
    return meta


@pytest.mark.parametrize("dotted,value,needle", [
    ("options", KeyError, "field 'options' is missing"),
    ("bank_counters", "k=3", "field 'bank_counters' must be a JSON object, found str"),
    ("extra", 1, "field 'extra' is not part of a state file"),
    ("sizes", "3,2", "field 'sizes' must be a list"),
    ("sizes", [3, 2.5], "field 'sizes[1]' must be an integer"),
    ("sizes", [3, 10**9], "field 'sizes[1]' must be in [1, 64]"),
    ("sizes", [3], "field 'sizes' is [3], the configuration has [3, 2]"),
    ("options", [10], "field 'options' is not valid (estimator options must be a mapping"),
    ("options.lags", "10", "field 'options' is not valid (estimator.lags must be an integer in [0, 100000], 'all' or "
                           "'auto', got '10')"),
    ("options.lags", 11, "field 'options.lags' is 11, the configuration has 10"),
    ("options.window", "hann", "field 'options' is not valid (estimator.window must be one of"),
    ("options.forgetting", 1.5, "(estimator.forgetting must be a number in [0.5, 1], got 1.5)"),
    ("options.forgetting", None, "(estimator.forgetting must be a number in [0.5, 1], got None)"),
    ("options.init_condition", 0.5, "(estimator.init_condition must be a number > 1, got 0.5)"),
    ("options.residual", KeyError, "field 'options' is not valid (estimator.residual is missing)"),
    ("options.lag", 10, "field 'options' is not valid (estimator.lag is not an estimator option)"),
    ("options.residual_burn_in", -1, "(estimator.residual_burn_in must be None"),
    ("options.residual_burn_in", 2.0, "(estimator.residual_burn_in must be None"),
    ("options.residual_burn_in", 20, "field 'options.residual_burn_in' is 20, the configuration has 0"),
    ("options.p0", "x", "(estimator.p0 must be None, a positive number or a sequence of them, got 'x')"),
    ("bank_counters.k", -1, "field 'bank_counters.k' must be in [0, "),
    ("bank_counters.k", True, "field 'bank_counters.k' must be an integer, found bool"),
    ("bank_counters.n_eff", 1e300, "field 'bank_counters.n_eff' must be in [0, k = 300]"),
    ("bank_counters.cap", 10**12, "field 'bank_counters.cap' is 1000000000000; 10 lags after 300 samples hold 11"),
    ("bank_counters.cap", [], "field 'bank_counters.cap' must be an integer, found a list"),
    ("samples_used", -5, "field 'samples_used' must be in [0, "),
    ("samples_used", 1.0, "field 'samples_used' must be an integer"),
    ("zsum", [1.0, "x"], "field 'zsum[1]' must be a number"),
    ("zsq", [1.0, -2.0], "field 'zsq' must not be negative"),
    ("zsum", {"a": 1}, "field 'zsum' must be a list of 2 numbers"),
])
def test_every_meta_field_is_checked_by_type_and_range(tmp_path, dotted, value, needle):
    arrays, meta = contents(saved(tmp_path))
    expect = ((3, 2), EstimatorOptions(lags=10))  # what the configuration continues with
    refused(write(tmp_path / "c.npz", _with(meta, dotted, value), arrays), needle, expect=expect)


def test_json_nan_and_deep_nesting_are_refused(tmp_path):
    arrays, meta = contents(saved(tmp_path))
    meta["zsum"] = [float("nan"), 1.0]
    refused(write(tmp_path / "nan.npz", meta, arrays), "field 'zsum[0]' must be finite")
    deep = "[" * 100_000 + "]" * 100_000
    refused(write(tmp_path / "deep.npz", None, arrays, meta_array=np.array(deep)), "field 'meta' is not valid JSON")
    refused(write(tmp_path / "num.npz", None, arrays, meta_array=np.arange(3.0)), "field 'meta' has shape (3,)")


@pytest.mark.parametrize("name", ["dispersion", "theta", "inv_s", "ready", "ready_at", "repairs", "x", "y", "v",
                                  "lag_sums", "lag_products"])
def test_every_array_of_the_wrong_length_or_dtype_is_refused(tmp_path, name):
    arrays, meta = contents(saved(tmp_path))
    good = arrays[name]
    arrays[name] = good[..., :-1] if good.shape[-1] > 1 else np.concatenate([good, good])
    text = refused(write(tmp_path / "short.npz", meta, arrays), f"field 'arrays.{name}' ")
    # Refused from the entry's declared size when it is too far off, else from its header.
    assert f"has shape {arrays[name].shape}" in text or "declares" in text
    arrays[name] = good.astype(np.float32 if good.dtype != np.float32 else np.float64)
    text = refused(write(tmp_path / "dtype.npz", meta, arrays), f"field 'arrays.{name}' ")
    assert "has dtype" in text or "declares" in text


def test_arrays_of_another_window_count_are_refused(tmp_path):
    """The history windows must hold min(k, cap) samples: a state claiming fewer samples
    (its k lowered) no longer matches its histories, and is refused before from_state."""
    arrays, meta = contents(saved(tmp_path))
    meta["bank_counters"]["k"] = 5
    meta["bank_counters"]["n_eff"] = 5.0
    meta["bank_counters"]["cap"] = 11
    refused(write(tmp_path / "c.npz", meta, arrays), "field 'arrays.v' has shape (2, 11), the configuration "
            "implies (2, 5)")


def test_non_finite_values_and_counters_out_of_range_are_refused(tmp_path):
    arrays, meta = contents(saved(tmp_path))
    q = arrays["lag_products"].copy()
    q[0, 1, 2, 2] = np.nan
    refused(write(tmp_path / "nan.npz", meta, {**arrays, "lag_products": q}),
            "field 'arrays.lag_products' holds NaN or infinite")
    refused(write(tmp_path / "at.npz", meta, {**arrays, "ready_at": np.array([1, 301])}),
            "field 'arrays.ready_at' must hold counts in [0, 300]")
    refused(write(tmp_path / "rep.npz", meta, {**arrays, "repairs": np.array([0, -1])}), "field 'arrays.repairs'")


def test_entries_that_are_not_the_state_are_refused(tmp_path):
    arrays, meta = contents(saved(tmp_path))
    refused(write(tmp_path / "extra.npz", meta, {**arrays, "evil": np.zeros(3)}),
            "field 'arrays.evil' is not part of this configuration's state")
    refused(write(tmp_path / "obj.npz", meta, {**arrays, "lag_sums": np.array([object()] * 22).reshape(2, 11)}),
            "field 'arrays.lag_sums' has dtype |O, not plain numbers")
    path = tmp_path / "names.npz"
    with zipfile.ZipFile(path, "w") as zf:
        zf.writestr("meta.npy", npy(np.array(json.dumps(meta))))
        zf.writestr("../escape.npy", npy(np.zeros(1)))
    refused(path, "entry '../escape.npy' is not a numpy array of a state")
    with zipfile.ZipFile(path, "w") as zf:
        zf.writestr("meta.npy", npy(np.array(json.dumps(meta))))
        for i in range(MAX_ENTRIES):
            zf.writestr(f"a{i}.npy", b"")
    refused(path, f"{MAX_ENTRIES + 1} entries (a state has at most {MAX_ENTRIES})")
    with zipfile.ZipFile(path, "w") as zf:
        zf.writestr("lag_sums.npy", npy(arrays["lag_sums"]))
    refused(path, "field 'meta' is missing (not a state file)")


def test_a_compressed_entry_is_never_inflated(tmp_path):
    """256 MB of zeros deflate to about 250 kB; the file is refused from its directory entry,
    without reading (or allocating) any of it."""
    arrays, meta = contents(saved(tmp_path))
    path = tmp_path / "bomb.npz"
    with zipfile.ZipFile(path, "w") as zf:
        zf.writestr("meta.npy", npy(np.array(json.dumps(meta))))
        for name, arr in arrays.items():
            if name != "lag_products":
                zf.writestr(f"{name}.npy", npy(arr))
        with zf.open("lag_products.npy", "w", force_zip64=True) as fh:
            fh.write(npy(np.zeros((2, 3, 11, 3)))[:128])
        info = zipfile.ZipInfo("big.npy")
        info.compress_type = zipfile.ZIP_DEFLATED
        with zf.open(info, "w", force_zip64=True) as fh:
            chunk = bytes(1 << 20)
            for _ in range(256):
                fh.write(chunk)
    assert path.stat().st_size < 1 << 20
    tracemalloc.start()
    try:
        refused(path, "entry 'big.npy' is compressed")
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 2 << 20


def test_declared_sizes_larger_than_the_file_are_refused_before_reading(tmp_path):
    arrays, meta = contents(saved(tmp_path))
    path = write(tmp_path / "lie.npz", meta, arrays)
    data = bytearray(path.read_bytes())
    # Make the central directory declare a 4 GB lag_products entry (uncompressed and compressed size).
    with zipfile.ZipFile(path) as zf:
        q = zf.getinfo("lag_products.npy")
    cd = data.rfind(b"PK\x01\x02" + data[data.find(b"PK\x01\x02") + 4: data.find(b"PK\x01\x02") + 4])
    i = data.find(b"lag_products.npy", data.find(b"PK\x01\x02")) - 46
    assert data[i:i + 4] == b"PK\x01\x02" and cd >= 0
    data[i + 20:i + 28] = (0xFFFF0000).to_bytes(4, "little") * 2
    path.write_bytes(bytes(data))
    tracemalloc.start()
    try:
        refused(path, "its entries declare", f"the file holds {len(data)}")
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 2 << 20 and q.file_size < 10_000


def test_a_header_declaring_a_huge_shape_is_refused_before_reading(tmp_path):
    """An absurd capacity (the most lags the options allow), consistent in meta, implies
    arrays larger than the file: refused from the declared entry sizes; and an entry whose npy
    header lies about its shape is refused from the header, before numpy allocates it."""
    arrays, meta = contents(saved(tmp_path))
    big = _with(meta, "options.lags", MAX_LAGS)
    big["bank_counters"]["cap"] = MAX_LAGS + 1
    fp = {**FINGERPRINT, "n_lags": MAX_LAGS}
    big["fingerprint"] = fp
    tracemalloc.start()
    try:
        # Counters implying far more state than the file holds: refused before anything is
        # allocated for them.
        refused(write(tmp_path / "cap.npz", big, arrays), "bank_counters.cap", "implies about", fingerprint=fp)
        path = tmp_path / "header.npz"
        with zipfile.ZipFile(path, "w") as zf:
            zf.writestr("meta.npy", npy(np.array(json.dumps(meta))))
            for name, arr in arrays.items():
                raw = npy(arr)
                if name == "lag_sums":
                    header = np.lib.format.header_data_from_array_1_0(arr)
                    header["shape"] = (2, 10**12)
                    buf = io.BytesIO()
                    np.lib.format.write_array_header_1_0(buf, header)
                    raw = buf.getvalue() + raw[len(buf.getvalue()):]
                zf.writestr(f"{name}.npy", raw)
        refused(path, "field 'arrays.lag_sums' has shape (2, 1000000000000), the configuration implies (2, 11)")
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 8 << 20


@pytest.mark.parametrize("content,needle", [
    (b"", "not a zip archive"),
    (b"PK\x03\x04" + bytes(100), "not a zip archive"),
])
def test_garbage_is_refused_as_unreadable(tmp_path, content, needle):
    path = tmp_path / "g.npz"
    path.write_bytes(content)
    refused(path, "not a readable state file", needle)
    refused(tmp_path, "not a readable state file")


def test_a_corrupted_byte_in_an_array_fails_the_crc(tmp_path):
    path = saved(tmp_path)
    data = bytearray(path.read_bytes())
    with zipfile.ZipFile(path) as zf:
        info = zf.getinfo("lag_products.npy")
    data[info.header_offset + 30 + len("lag_products.npy") + 200] ^= 0xFF
    path.write_bytes(bytes(data))
    refused(path, "not a readable state file", "CRC")


def test_expect_must_match_the_files_sizes_and_options(tmp_path):
    path = saved(tmp_path)
    assert load_state(path, FINGERPRINT, expect=((3, 2), EstimatorOptions(lags=10))).bank.k == 300
    refused(path, "field 'options.window' is 'truncated', the configuration has 'bartlett'",
            expect=((3, 2), EstimatorOptions(lags=10, window="bartlett")))
    refused(path, "field 'sizes' is [3, 2], the configuration has [3, 3]", expect=((3, 3), EstimatorOptions(lags=10)))


def test_a_state_saved_with_another_residual_burn_in_is_refused(tmp_path):
    """The lag sums of a state with a burn-in are those of the samples after it: a state saved
    with one burn-in is refused under another (the pipeline expects its resolved value)."""
    rng = np.random.default_rng(3)
    bank = EstimatorBank((3, 2), EstimatorOptions(lags=10, residual_burn_in=20))
    for _ in range(100):
        bank.update(rng.standard_normal((2, 3)), rng.standard_normal(2))
    path = tmp_path / "burn.npz"
    save_state(path, EstimatorState(bank, 100, np.zeros(2), np.ones(2)), FINGERPRINT)
    refused(path, "field 'options.residual_burn_in' is 20, the configuration has 0",
            expect=((3, 2), EstimatorOptions(lags=10)))
    state = load_state(path, FINGERPRINT, expect=((3, 2), EstimatorOptions(lags=10, residual_burn_in=20)))
    assert state.bank.options.burn_in == 20
    np.testing.assert_array_equal(state.bank.standard_errors_all(), bank.standard_errors_all())


def test_big_endian_arrays_load_and_continue_identically(tmp_path):
    bank, _z = fed_bank()
    path = saved(tmp_path)
    arrays, meta = contents(path)
    swapped = {k: v.astype(v.dtype.newbyteorder(">")) for k, v in arrays.items()}
    state = load_state(write(tmp_path / "be.npz", meta, swapped), FINGERPRINT)
    np.testing.assert_array_equal(state.bank.theta_all(), bank.theta_all())
    np.testing.assert_array_equal(state.bank.standard_errors_all(), bank.standard_errors_all())


@pytest.mark.parametrize("n,cap", [(150, 256), (64, 64), (128, 128)])
def test_a_state_with_all_lags_round_trips(tmp_path, n, cap):
    """Also when the buffer is exactly full (64, 128 samples): the capacity grows with the
    next sample, so the state holds the capacity its sample count implies, and the restored
    bank continues bit for bit through the growth."""
    rng = np.random.default_rng(2)
    options = EstimatorOptions(lags="all", forgetting=0.99)
    bank = EstimatorBank((3, 2), options)
    X, z = rng.standard_normal((n + 20, 2, 3)), rng.standard_normal((n + 20, 2))
    for k in range(n):
        bank.update(X[k], z[k])
    path = tmp_path / "all.npz"
    save_state(path, EstimatorState(bank, n, np.zeros(2), np.ones(2)), FINGERPRINT)
    state = load_state(path, FINGERPRINT, expect=((3, 2), options))
    assert state.bank.state()["counters"] == bank.state()["counters"]
    assert state.bank.state()["counters"]["cap"] == cap
    np.testing.assert_array_equal(state.bank.standard_errors_all(), bank.standard_errors_all())
    for k in range(n, n + 20):
        bank.update(X[k], z[k])
        state.bank.update(X[k], z[k])
    np.testing.assert_array_equal(state.bank.covariance_all(), bank.covariance_all())


# ------------------------------------------------------------------ writing safely, setting aside
def test_a_planted_temporary_symlink_is_never_written_through(tmp_path):
    victim = tmp_path / "victim.txt"
    victim.write_text("precious")
    path = tmp_path / "state.npz"
    for planted in ("state.npz.tmp", ".state.npz.tmp", "state.npz.partial"):
        os.symlink(victim, tmp_path / planted)
    bank, z = fed_bank()
    save_state(path, EstimatorState(bank, 300, z.sum(axis=0), (z * z).sum(axis=0)), FINGERPRINT)
    assert victim.read_text() == "precious"
    assert load_state(path, FINGERPRINT).samples_used == 300
    # A symlink at the state path itself is replaced by the new file, its target untouched.
    link = tmp_path / "linked.npz"
    os.symlink(victim, link)
    save_state(link, EstimatorState(bank, 300, z.sum(axis=0), (z * z).sum(axis=0)), FINGERPRINT)
    assert victim.read_text() == "precious" and not link.is_symlink()


def test_the_new_file_is_fsynced_before_the_rename(tmp_path, monkeypatch):
    calls = []
    real_fsync, real_replace = os.fsync, os.replace
    monkeypatch.setattr(os, "fsync", lambda fd: (calls.append(("fsync", os.path.realpath(f"/proc/self/fd/{fd}"))),
                                                 real_fsync(fd))[1])
    monkeypatch.setattr(os, "replace", lambda a, b: (calls.append(("replace", str(a), str(b))), real_replace(a, b))[1])
    bank, z = fed_bank()
    path = tmp_path / "state.npz"
    save_state(path, EstimatorState(bank, 1, z.sum(axis=0), z.sum(axis=0)), FINGERPRINT)
    kinds = [c[0] for c in calls]
    assert kinds[:2] == ["fsync", "replace"], calls
    tmp = calls[1][1]
    assert calls[0][1] == tmp and calls[1][2] == str(path)
    assert os.path.dirname(tmp) == str(tmp_path) and os.path.basename(tmp).startswith(".state.npz.")


def test_set_aside_never_overwrites(tmp_path):
    now = datetime(2026, 3, 4, 5, 6, 7, tzinfo=UTC)
    path = tmp_path / "state.npz"
    taken = tmp_path / "state.npz.rejected-20260304T050607Z"
    taken.write_text("an earlier rejected file")
    path.write_text("rejected now")
    moved = set_aside(path, now)
    assert moved == tmp_path / "state.npz.rejected-20260304T050607Z-1"
    assert moved.read_text() == "rejected now" and taken.read_text() == "an earlier rejected file"
    assert not path.exists()
    # A symlink is moved as the link; its target stays where it is.
    target = tmp_path / "elsewhere.npz"
    target.write_text("target")
    os.symlink(target, path)
    moved = set_aside(path, now)
    assert moved.is_symlink() and os.readlink(moved) == str(target) and target.read_text() == "target"


def test_set_aside_without_hard_links_still_keeps_every_file(tmp_path, monkeypatch):
    def no_links(*a, **k):
        raise PermissionError(1, "Operation not permitted")

    monkeypatch.setattr(os, "link", no_links)
    now = datetime(2026, 3, 4, 5, 6, 7, tzinfo=UTC)
    path = tmp_path / "state.npz"
    (tmp_path / "state.npz.rejected-20260304T050607Z").write_text("old")
    path.write_text("new")
    moved = set_aside(path, now)
    assert moved.name.endswith("-1") and moved.read_text() == "new"
    assert (tmp_path / "state.npz.rejected-20260304T050607Z").read_text() == "old"


# ----------------------------------------------------------------------------- claim
def tree(root):
    """Every entry of a flat directory without opening anything but regular files: name ->
    (file type, inode, bytes of a regular file)."""
    out = {}
    for p in sorted(root.iterdir()):
        st = os.lstat(p)
        out[p.name] = (stat.S_IFMT(st.st_mode), st.st_ino, p.read_bytes() if stat.S_ISREG(st.st_mode) else None)
    return out


def _special(tmp_path, kind):
    """A state_file path that is not a regular file (a character device where mknod is allowed)."""
    path = tmp_path / "state.npz"
    if kind == "fifo":
        os.mkfifo(path)
    elif kind == "directory":
        path.mkdir()
    elif kind == "socket":
        sock = socket.socket(socket.AF_UNIX)
        sock.bind(str(path))
        sock.close()
    else:
        try:
            os.mknod(path, 0o600 | 0o020000, os.makedev(1, 3))  # a copy of /dev/null, never the real one
        except PermissionError:
            pytest.skip("creating a device needs privileges this run does not have")
    return path


@pytest.mark.parametrize("kind,named", [("fifo", "a FIFO"), ("directory", "a directory"), ("socket", "a socket"),
                                        ("device", "a character device")])
def test_a_state_file_that_is_not_a_regular_file_is_refused_at_once_and_left_alone(tmp_path, kind, named):
    path = _special(tmp_path, kind)
    before = tree(tmp_path)
    with no_hang(10), pytest.raises(StateFileError) as err:
        claim(path)
    assert str(err.value) == (f"{path}: is {named}, not a regular file (it is not opened, renamed or replaced); "
                              "set state_file to a file's path")
    with no_hang(10), pytest.raises(StateFileError, match="not a readable state file"):
        load_state(path, FINGERPRINT)  # reading never waits either (a FIFO swapped in after the claim)
    assert tree(tmp_path) == before  # no lock file, nothing renamed


_CLAIM = """
import sys, time
from rls_uncertainty.state_file import claim
c = claim(sys.argv[1])
print(len(c.removed), flush=True)
time.sleep(120)
"""


def test_a_state_file_in_use_is_refused_and_its_temporaries_kept_until_its_user_stops(tmp_path):
    path = saved(tmp_path)
    temporary = tmp_path / f".{path.name}.{'e' * 16}.tmp"
    holder = subprocess.Popen([sys.executable, "-c", _CLAIM, str(path)], stdout=subprocess.PIPE, text=True)
    try:
        assert holder.stdout.readline() == "0\n"
        temporary.write_bytes(b"the live user's save in progress")
        before = tree(tmp_path)
        with pytest.raises(StateFileError) as err:
            claim(path)
        assert str(err.value) == (f"{path}: in use: its lock {tmp_path / ('.' + path.name + '.lock')} is held by "
                                  f"process {holder.pid} (another node estimating with it); give each node its own "
                                  "state_file")
        assert tree(tmp_path) == before  # nothing renamed, removed or written
    finally:
        holder.kill()
        holder.wait(60)
        holder.stdout.close()
    mine = claim(path)  # the user is gone: its temporary is a leftover
    assert mine.removed == [temporary] and not temporary.exists()
    assert load_state(path, FINGERPRINT).samples_used == 300
    mine.release()
    assert sorted(p.name for p in tmp_path.iterdir()) == [path.name]


def test_a_state_file_whose_lock_cannot_be_made_is_refused_in_one_line(tmp_path):
    path = tmp_path / "missing" / "state.npz"
    with pytest.raises(StateFileError) as err:
        claim(path)
    lock = path.parent / ".state.npz.lock"
    assert str(err.value) == f"{path}: cannot take its lock {lock} (No such file or directory)"
    assert not path.parent.exists()
