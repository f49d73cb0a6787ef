"""campaign/maneuvers.py: maneuvers from replay bags, or from a maneuvers file cutting one
recording; every bad entry is a ConfigError naming the file, the entry and the key. No ROS."""

from __future__ import annotations

import pytest

from rls_uncertainty.campaign import Maneuver, from_bags, load_maneuvers
from rls_uncertainty.errors import ConfigError


def test_bags_are_maneuvers_named_after_their_directory_or_file(tmp_path):
    got = from_bags([tmp_path / "m001", tmp_path / "flight" / "m002.mcap"])
    assert got == [Maneuver("m001", str(tmp_path / "m001")), Maneuver("m002", str(tmp_path / "flight" / "m002.mcap"))]


def test_two_bags_of_one_name_are_refused(tmp_path):
    with pytest.raises(ConfigError, match="two maneuvers are named 'm1'"):
        from_bags([tmp_path / "a" / "m1", tmp_path / "b" / "m1"])
    with pytest.raises(ConfigError, match="at least one"):
        from_bags([])


def test_a_maneuvers_file_cuts_one_recording_into_spans(tmp_path):
    f = tmp_path / "maneuvers.yaml"
    f.write_text("maneuvers:\n  - {name: m01, start: 2, end: 14.5}\n  - {name: 7, start: 20.0, end: 32}\n")
    assert load_maneuvers(f, "flight") == [Maneuver("m01", "flight", 2.0, 14.5), Maneuver("7", "flight", 20.0, 32.0)]


@pytest.mark.parametrize(("text", "needle"), [
    ("maneuvers: []\n", "expected 'maneuvers:'"),
    ("[1, 2]\n", "expected 'maneuvers:'"),
    ("maneuvers: [{name: a, start: 0, end: 1}]\nrecording: x\n", "unknown key 'recording'"),
    ("maneuvers: [{name: a, start: 0}]\n", "maneuver 1: missing 'end'"),
    ("maneuvers: [{name: a, start: 0, end: 1, rate: 50}]\n", "maneuver 1: unknown key 'rate'"),
    ("maneuvers: [{name: a, start: 5, end: 5}]\n", r"maneuver 1 \(a\): end \(5 s\) must be after start"),
    ("maneuvers: [{name: a, start: -1, end: 5}]\n", "maneuver 1: start must be a finite number"),
    ("maneuvers: [{name: a, start: .nan, end: 5}]\n", "maneuver 1: start must be a finite number"),
    ("maneuvers: [{name: '', start: 0, end: 5}]\n", "maneuver 1: name must be a non-empty string"),
    ("maneuvers: [{name: a, start: 0, end: 5}, {name: a, start: 6, end: 9}]\n", "two maneuvers are named 'a'"),
    ("maneuvers: [3]\n", "maneuver 1: expected a mapping"),
    ("maneuvers: [{name: a, start: 0, end: 5}\n", "not valid YAML"),
])
def test_a_bad_maneuvers_file_is_one_error_naming_the_entry(tmp_path, text, needle):
    f = tmp_path / "m.yaml"
    f.write_text(text)
    with pytest.raises(ConfigError, match=needle):
        load_maneuvers(f, "flight")
