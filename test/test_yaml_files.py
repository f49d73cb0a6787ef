"""The package's one YAML reader (settings/yaml_files.py): every YAML the package reads goes
through it, with one error policy, one line naming the file, the line and the column; a key
given twice is refused instead of the last one winning in silence; a file that is not a
regular file is refused before it is opened."""

from __future__ import annotations

import ast
import os
from pathlib import Path

import pytest

from rls_uncertainty.campaign.maneuvers import load_maneuvers
from rls_uncertainty.dashboard.settings import load_reference
from rls_uncertainty.errors import BagError, ConfigError
from rls_uncertainty.offline.bags import load_mapping
from rls_uncertainty.settings import load_aircraft
from rls_uncertainty.settings.ros_arguments import read_parameter_file
from rls_uncertainty.settings.yaml_files import load

PACKAGE = Path(__file__).resolve().parents[1] / "rls_uncertainty"

# Each reader, a valid file for it, and the key it may repeat (the duplicate goes after the first line
# that holds that key).
READERS = {
    "parameter file": (read_parameter_file, "rls_estimator:\n  ros__parameters:\n    rate: 50.0\n", "    rate: 5.0\n"),
    "aircraft file": (load_aircraft, "aircraft: {name: x, mass: 1, Ixx: 1, Iyy: 1, Izz: 1, Ixz: 0, S: 1, b: 1, "
                                     "cbar: 1}\n", "aircraft: {name: y}\n"),
    "maneuvers file": (lambda p: load_maneuvers(p, "rec"), "maneuvers:\n  - {name: a, start: 1.0, end: 2.0}\n",
                       "maneuvers: []\n"),
    "mapping file": (load_mapping, "imu:\n  topic: /imu\n", "imu:\n  topic: /other\n"),
    "--reference": (load_reference, "CZ_alpha: -3.9\n", "CZ_alpha: -4.1\n"),
}


@pytest.mark.parametrize("what", list(READERS))
def test_every_reader_refuses_a_key_given_twice_naming_both_places(tmp_path, what):
    read, text, twice = READERS[what]
    path = tmp_path / "f.yaml"
    first = text.splitlines()[-1] if what == "parameter file" else text.splitlines()[0]
    path.write_text(text + twice)
    with pytest.raises((ConfigError, BagError)) as exc:
        read(path)
    message = str(exc.value)
    line = text.count("\n") + 1
    first_line = text.splitlines().index(first) + 1
    assert message.startswith(f"{what} {path}:{line}:") and "given twice (first at line " \
        f"{first_line}, column" in message and "\n" not in message, message


@pytest.mark.parametrize("what", list(READERS))
def test_every_reader_names_file_line_and_column_of_bad_yaml_and_refuses_what_is_not_a_file(tmp_path, what):
    read = READERS[what][0]
    path = tmp_path / "bad.yaml"
    path.write_text("a: [1, 2\n")
    with pytest.raises((ConfigError, BagError), match=rf"^{what} {path}:2:1: not valid YAML: expected ',' or ']'"):
        read(path)
    path.write_bytes(b"a: \xff\n")
    with pytest.raises((ConfigError, BagError), match=rf"^{what} {path}: not UTF-8 text \(byte 3\)"):
        read(path)
    os.mkfifo(tmp_path / "fifo.yaml")  # opening it would block until a writer came
    with pytest.raises((ConfigError, BagError), match=rf"^{what} {tmp_path / 'fifo.yaml'}: not a regular file"):
        read(tmp_path / "fifo.yaml")
    (tmp_path / "dir.yaml").mkdir()
    with pytest.raises((ConfigError, BagError), match=rf"^{what} {tmp_path / 'dir.yaml'}: a directory"):
        read(tmp_path / "dir.yaml")


def test_the_reader_reads_what_yaml_says_and_nothing_more(tmp_path):
    path = tmp_path / "f.yaml"
    path.write_text("a: 1\nb: [x, 'y', 2.5]\nc: {d: null}\ne: &v 3\nf: *v\n")
    assert load(path, "file") == {"a": 1, "b": ["x", "y", 2.5], "c": {"d": None}, "e": 3, "f": 3}
    path.write_text("")
    assert load(path, "file") is None


def _yaml_parses(tree: ast.AST) -> list[str]:
    """Calls of a YAML parser: yaml.safe_load, yaml.load, yaml.compose, ... (not the writers)."""
    parsers = {"safe_load", "load", "full_load", "unsafe_load", "compose", "compose_all", "safe_load_all",
               "load_all", "parse"}
    return [node.func.attr for node in ast.walk(tree) if isinstance(node, ast.Call)
            and isinstance(node.func, ast.Attribute) and isinstance(node.func.value, ast.Name)
            and node.func.value.id == "yaml" and node.func.attr in parsers]


def test_no_module_but_the_reader_parses_yaml():
    found = {str(path.relative_to(PACKAGE)): calls for path in sorted(PACKAGE.rglob("*.py"))
             if "node_modules" not in path.parts and (calls := _yaml_parses(ast.parse(path.read_text())))}
    assert found == {"settings/yaml_files.py": ["compose"]}
    planted = ast.parse("import yaml\nyaml.safe_load(open('x'))\nyaml.safe_dump({})\n")
    assert _yaml_parses(planted) == ["safe_load"]
