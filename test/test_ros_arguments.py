"""The ROS 2 command line and parameter files read as rcl reads them
(rls_uncertainty/settings/ros_arguments.py). The oracle is rcl itself: the same arguments are given to
rclpy.init and a node that declares whatever it is given shows what rcl made of them (one
context per case, closed in a finally; no messages are exchanged)."""

import math
import os

import pytest
import rclpy
from rclpy.impl.implementation_singleton import rclpy_implementation
from rclpy.node import Node

from rls_uncertainty.errors import ConfigError
from rls_uncertainty.settings.ros_arguments import (
    ParameterFile,
    ParameterRule,
    in_rcl_order,
    parse_ros_arguments,
    pattern_matches,
    read_parameter_file,
    scalar_value,
)


def _rcl_parameters(argv, node_name="probe"):
    """What rcl gives the node ``node_name`` for ``argv``: its fully qualified name (after the
    remaps) and its parameter overrides by name."""
    context = rclpy.Context()
    rclpy.init(args=argv, context=context)
    node = None
    try:
        node = Node(node_name, context=context, automatically_declare_parameters_from_overrides=True)
        values = {name: p.value for name, p in node._parameters.items()
                  if name not in ("use_sim_time", "start_type_description_service")}
        return node.get_fully_qualified_name(), values
    finally:
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown(context=context)


# Spellings whose rcl type differs from YAML's or is easy to get wrong (each checked against rcl).
SPELLINGS = [
    "yes", "Yes", "YES", "y", "N", "no", "off", "On", "True", "false", "tRue", "1e3", "1E3", "+5", "-5", "+1.5",
    "0x1F", "0X1f", "0o7", "010", "08", "0b1", "1_000", "12abc", "3.0f", "1,5", "0x1.8p1", "Inf", "-inf",
    "NaN", ".nan", ".NaN", "+.nan", ".inf", "-.inf", "infinity", "-nan", "1e400", "1e-310", "1e-400",
    "99999999999999999999", "9223372036854775807", "9223372036854775808", "-9223372036854775809",
    "0x8000000000000000", "07777777777777777777777", "-0", "0.0", "null", "~", "'1'", '"true"', "!!str 5",
    "!!float 5", "a b", "[a, b]", "[1, 2]", "[yes, no]", '[a, "1"]', "[0x10, 8]", "[.nan, 1.5]", "- a",
]


def _same(a, b):
    if isinstance(a, float) and isinstance(b, float) and math.isnan(a) and math.isnan(b):
        return True
    if isinstance(a, list) and isinstance(b, list):
        return len(a) == len(b) and all(_same(x, y) for x, y in zip(a, b, strict=True))
    return type(a) is type(b) and a == b


def test_values_are_typed_as_rcl_types_them():
    argv = ["--ros-args"]
    for i, text in enumerate(SPELLINGS):
        argv += ["-p", f"v{i}:={text}"]
    _fqn, rcl = _rcl_parameters(argv)
    ours = {rule.name: rule.value for rule in parse_ros_arguments(argv, "probe").sources}
    for i, text in enumerate(SPELLINGS):
        assert _same(ours[f"v{i}"], rcl[f"v{i}"]), (text, ours[f"v{i}"], rcl[f"v{i}"])


@pytest.mark.parametrize("text", ["[1, 2.5]", "[1, yes]", "[1, '2']", "{a: 1}"])
def test_values_rcl_refuses_are_refused(text):
    argv = ["--ros-args", "-p", f"v:={text}"]
    with pytest.raises(rclpy_implementation.RCLError, match="v:="):
        _rcl_parameters(argv)
    with pytest.raises(ConfigError, match=r"-p v:="):
        parse_ros_arguments(argv, "probe")


def test_a_nested_list_is_refused_where_rcl_would_take_part_of_it():
    """rcl reads [a, [b]] as some flat list; no parameter of the node is a list of lists, so it is refused."""
    _fqn, rcl = _rcl_parameters(["--ros-args", "-p", "v:=[a, [b]]"])
    assert rcl["v"] != ["a", ["b"]]
    with pytest.raises(ConfigError, match="a list holds values, not lists or mappings"):
        parse_ros_arguments(["--ros-args", "-p", "v:=[a, [b]]"], "probe")


SECTION_CASES = [
    ("probe", []), ("/probe", []), ("/**", []), ("/**", ["-r", "__ns:=/x/y"]), ("/*", []), ("/*", ["-r", "__ns:=/x"]),
    ("/x/*", ["-r", "__ns:=/x"]), ("/x/**", ["-r", "__ns:=/x/y/z"]), ("/**/probe", ["-r", "__ns:=/x/y"]),
    ("/**/probe", []), ("probe", ["-r", "__ns:=/x"]), ("x/probe", ["-r", "__ns:=/x"]), ("other", []),
    ("renamed", ["-r", "__node:=renamed"]), ("renamed", ["-r", "probe:__node:=renamed"]),
    ("renamed", ["-r", "other:__node:=renamed"]), ("first", ["-r", "__node:=first", "-r", "__node:=second"]),
    ("/a/probe", ["-r", "__ns:=/a", "--ros-args", "-r", "__ns:=/b"]),
]


@pytest.mark.parametrize("key,remaps", SECTION_CASES, ids=[f"{k} {' '.join(r)}" for k, r in SECTION_CASES])
def test_a_section_applies_to_the_node_as_rcl_decides(tmp_path, key, remaps):
    path = tmp_path / "p.yaml"
    path.write_text(f"{key}:\n  ros__parameters:\n    marker: 1\n")
    argv = ["prog", "--ros-args", "--params-file", str(path), *remaps]
    fqn, rcl = _rcl_parameters(argv)
    args = parse_ros_arguments(argv, "probe")
    assert args.fqn == fqn
    (file,) = args.sources
    (section,) = file.sections
    assert section.matches(args.fqn) == ("marker" in rcl)


def test_nested_namespaces_and_dotted_names_are_one_section(tmp_path):
    path = tmp_path / "p.yaml"
    path.write_text("x:\n  probe:\n    ros__parameters:\n      a: {b: 1, c: [p, q]}\n      d: '5'\n")
    fqn, rcl = _rcl_parameters(["--ros-args", "-r", "__ns:=/x", "--params-file", str(path)])
    (section,) = read_parameter_file(path).sections
    assert (section.pattern, section.matches(fqn)) == ("/x/probe", True)
    values = {name: value for name, value, _line, _column in section.parameters}
    assert values == rcl == {"a.b": 1, "a.c": ["p", "q"], "d": "5"}


ORDER_FILES = {
    "first": "/**:\n  ros__parameters:\n    a: 1\n    b: 1\nprobe:\n  ros__parameters:\n    a: 2\n",
    "second": "probe:\n  ros__parameters:\n    b: 3\n    c: 3\n",
    "both": "probe:\n  ros__parameters:\n    a: 1\n/**:\n  ros__parameters:\n    a: 2\n/probe:\n  ros__parameters:\n"
            "    b: 1\n",
    "ns": "/x/probe:\n  ros__parameters:\n    a: 7\n",
}
ORDER_CASES = [
    ["-p", "c:=4", "--params-file", "first", "--params-file", "second", "-p", "a:=5"],
    ["--params-file", "both", "-p", "a:=9"],
    ["-p", "probe:a:=1", "--params-file", "second"],
    ["--params-file", "second", "-p", "probe:c:=1"],
    ["-p", "probe:a:=1", "-p", "a:=3"],
    ["-p", "a:=3", "-p", "probe:a:=1"],
    ["-r", "__ns:=/x", "-p", "probe:a:=1", "--params-file", "ns"],
    ["-r", "__ns:=/x", "-p", "a:=1", "--params-file", "ns", "-p", "a:=2"],
]


@pytest.mark.parametrize("args", ORDER_CASES, ids=[" ".join(c) for c in ORDER_CASES])
def test_the_value_that_wins_is_rcls(tmp_path, args):
    """Where several sources set one parameter, the node gets what rcl gives it (a later -p
    does not always win: see in_rcl_order)."""
    for name, text in ORDER_FILES.items():
        (tmp_path / name).write_text(text)
    argv = ["--ros-args", *(str(tmp_path / a) if a in ORDER_FILES else a for a in args)]
    fqn, rcl = _rcl_parameters(argv)
    parsed = parse_ros_arguments(argv, "probe")
    ours = {a.name: a.value for a in in_rcl_order(parsed.sources, lambda p: pattern_matches(p, fqn))}
    assert ours == rcl


def test_arguments_outside_ros_args_and_node_prefixes_are_kept_apart():
    args = parse_ros_arguments(["prog", "x", "--ros-args", "-p", "other:a:=1", "--log-level", "debug",
                                "--disable-rosout-logs", "-e", "/enc", "--", "y"], "probe")
    assert args.other_arguments == ("prog", "x", "y")
    assert args.sources == (ParameterRule("other", "a", 1, "-p other:a:=1"),)
    assert args.fqn == "/probe"


@pytest.mark.parametrize("argv,needle", [
    (["--ros-args", "-p"], "-p at the end"),
    (["--ros-args", "--params-file"], "--params-file at the end"),
    (["--ros-args", "-p", "a"], "expected [NODE:]NAME:=VALUE"),
    (["--ros-args", "-p", "a:="], "no value"),
    (["--ros-args", "-p", "a b:=1"], "not a parameter name"),
    (["--ros-args", "-p", "a:=[1"], "not valid YAML"),
    (["--ros-args", "-r", "foo"], "expected [NODE:]NAME:=VALUE"),
    (["--ros-args", "-r", "__ns:=x"], "a namespace starts with '/'"),
    (["--ros-args", "-r", "__node:=a-b"], "a node name holds"),
    (["--ros-args", "--foo"], "unknown ROS argument '--foo'"),
    (["--ros-args", "bar"], "unknown ROS argument 'bar'"),
])
def test_a_malformed_argument_is_named(argv, needle):
    with pytest.raises(ConfigError) as exc:
        parse_ros_arguments(argv, "probe")
    assert needle in str(exc.value)


@pytest.mark.parametrize("text,needle", [
    ("probe:\n  ros__parameters:\n    a: [1\n", "p.yaml:4:1: not valid YAML: expected ',' or ']'"),
    ("probe:\n  ros__parameters:\n", "'ros__parameters' must be a mapping"),
    ("probe:\n  ros__parameters:\n    a: 1\n  other: 3\n", "p.yaml:4:10: expected a mapping of node names to "
                                                       "'ros__parameters:'"),
    ("- probe\n", "expected a mapping of node names"),
    ("ros__parameters:\n  a: 1\n", "needs a node name above it"),
    ("rls_est*:\n  ros__parameters:\n    a: 1\n", "p.yaml:1:1: 'rls_est*' is not a node name"),
    ("probe:\n  ros__parameters:\n    a: [1, x]\n", "p.yaml:3:8: a: a list holds values of one type"),
    ("probe:\n  ros__parameters:\n    a: [{b: 1}]\n", "p.yaml:3:9: a: a list holds values, not lists or mappings"),
    ("probe:\n  ros__parameters:\n    a: 1\n    a: 2\n", "p.yaml:4:5: not valid YAML: key 'a' given twice (first at "
                                                        "line 3, column 5)"),
    ("probe:\n  ros__parameters:\n    a.b: 1\n    a:\n      b: 2\n", "p.yaml:5:7: parameter a.b given twice in "
                                                                  "section /probe (first at line 3, column 5)"),
])
def test_a_malformed_parameter_file_is_one_error_naming_the_file(tmp_path, text, needle):
    path = tmp_path / "p.yaml"
    path.write_text(text)
    with pytest.raises(ConfigError) as exc:
        read_parameter_file(path)
    message = str(exc.value)
    assert str(path) in message and needle in message and "\n" not in message


def test_a_missing_or_binary_parameter_file_is_named(tmp_path):
    with pytest.raises(ConfigError, match=r"missing\.yaml: no such file"):
        parse_ros_arguments(["--ros-args", "--params-file", str(tmp_path / "missing.yaml")], "probe")
    (tmp_path / "b.yaml").write_bytes(b"\xff\xfe")
    with pytest.raises(ConfigError, match=r"b\.yaml: not UTF-8 text"):
        read_parameter_file(tmp_path / "b.yaml")
    with pytest.raises(ConfigError, match="a directory; give a YAML file"):
        read_parameter_file(tmp_path)
    os.mkfifo(tmp_path / "fifo.yaml")  # never opened: reading it would wait for a writer
    with pytest.raises(ConfigError, match=r"fifo\.yaml: not a regular file"):
        read_parameter_file(tmp_path / "fifo.yaml")


def test_an_empty_file_has_no_sections(tmp_path):
    (tmp_path / "e.yaml").write_text("# nothing\n")
    assert read_parameter_file(tmp_path / "e.yaml") == ParameterFile(tmp_path / "e.yaml", ())


def test_scalar_value_text_flag_keeps_text():
    assert scalar_value("5", string=True) == "5" and scalar_value("5") == 5
