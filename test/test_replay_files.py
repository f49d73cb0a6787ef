"""The offline replay's output files (rls_uncertainty/offline/replay_files.py): the /diagnostics
records and the maneuver history's strings are the bytes the rosbags serializer gives for the
same message; the wide CSV's rows are the same whether it formats every number itself or takes
the long CSV's text of them. No DDS."""

from pathlib import Path

from rls_uncertainty.datapath.cdr import encode_string
from rls_uncertainty.datapath.diagnostics import Status
from rls_uncertainty.datapath.outputs import OutputLayout
from rls_uncertainty.offline.bags import read_inputs, typestore
from rls_uncertainty.offline.replay import run_pipeline
from rls_uncertainty.offline.replay_files import (
    DIAGNOSTIC_ARRAY,
    STRING,
    _Csv,
    _diagnostic_array,
    _WideCsv,
)
from rls_uncertainty.settings import load_parameters_file, pipeline_config

BUNDLED = Path(__file__).resolve().parents[1] / "bags" / "t2_maneuver"


def _rosbags_cdr(stamp_ns, statuses):
    """The same DiagnosticArray built as rosbags message objects and serialized by rosbags."""
    store = typestore()
    types = store.types
    key_value, status_t = types["diagnostic_msgs/msg/KeyValue"], types["diagnostic_msgs/msg/DiagnosticStatus"]
    message = types[DIAGNOSTIC_ARRAY](
        header=types["std_msgs/msg/Header"](
            stamp=types["builtin_interfaces/msg/Time"](sec=stamp_ns // 10**9, nanosec=stamp_ns % 10**9), frame_id=""),
        status=[status_t(level=s.level, name=s.name, message=s.message, hardware_id=s.hardware_id,
                         values=[key_value(key=k, value=v) for k, v in s.values]) for s in statuses])
    return bytes(store.serialize_cdr(message, DIAGNOSTIC_ARRAY))


def test_diagnostic_arrays_are_the_bytes_rosbags_serializes():
    statuses = [
        Status("rls_estimator: inputs", 0, "ok", (("imu rate", "200.0 Hz"), ("a", ""), ("", "xyz"))),
        Status("rls_estimator: CZ", 1, "not converged: CZ_alpha (σ 3 %)", (), hardware_id="node"),
        Status("x", 2, "", (("key of five", "é"),)),
        Status("", 3, "stale", (("k", "v" * 7),), hardware_id=""),
    ]
    for stamp_ns in (0, 1_700_000_000_123_456_789, 2**31 * 10**9 - 1):
        for cut in range(len(statuses) + 1):  # every alignment the strings before a status leave
            assert _diagnostic_array(stamp_ns, statuses[:cut]) == _rosbags_cdr(stamp_ns, statuses[:cut])
            assert _diagnostic_array(stamp_ns, statuses[cut:]) == _rosbags_cdr(stamp_ns, statuses[cut:])


def test_strings_are_the_bytes_rosbags_serializes():
    store = typestore()
    for text in ("", "a", "ab", "abc", "abcd", '[{"name": "m1", "σ": 0.5}]', "x" * 1001):
        assert encode_string(text) == bytes(store.serialize_cdr(store.types[STRING](data=text), STRING))


def test_the_wide_csv_rows_are_the_same_with_the_long_csvs_texts_or_without(tmp_path):
    config = pipeline_config(load_parameters_file("t2"))
    outputs = run_pipeline(read_inputs(BUNDLED)[0], config, record=False).outputs
    long = _Csv(tmp_path / "long.csv", OutputLayout.for_config(config))
    shared, alone = _WideCsv(tmp_path / "shared.csv", config), _WideCsv(tmp_path / "alone.csv", config)
    for out in outputs:
        shared.sample(out, long.sample(out))
        alone.sample(out, {})
    for csv in (long, shared, alone):
        csv.fh.close()
    rows = (tmp_path / "shared.csv").read_text().splitlines()
    assert rows == (tmp_path / "alone.csv").read_text().splitlines()
    assert sum(bool(cell) for cell in rows[-1].split(",")) > 10  # the models' values written
