"""The ROS 2 command line (``--ros-args``) and parameter files, read as rcl reads them, without
rclpy: so that the node can check its own settings before rcl sees them, and the offline replay
reads a parameter file exactly as the node does.

What rcl does, and this module reproduces (checked against rcl itself in
``test/test_ros_arguments.py``):

* ``--ros-args`` opens a section of ROS arguments, ``--`` closes it; there may be several.
  Inside one: ``-p``/``--param [NODE:]NAME:=VALUE``, ``--params-file FILE``,
  ``-r``/``--remap [NODE:]FROM:=TO`` (``__node`` and ``__ns`` rename the node and set its
  namespace: the first rule that applies wins), ``--log-level``, ``--log-config-file``,
  ``--log-file-name``, ``-e``/``--enclave`` (each with one value) and the
  ``--enable-``/``--disable-`` ``rosout-logs``, ``stdout-logs``, ``external-lib-logs`` flags.
* A value (of ``-p`` or in a file) is YAML, typed by rcl's rules rather than YAML's: quoted or
  ``!!str`` scalars are text; ``true/yes/on/y`` and ``false/no/off/n`` (three capitalisations)
  are booleans; then an integer as C's ``strtol`` reads it (``0x1F``, octal ``010``) within 64
  bits; then a number as ``strtod`` reads it (``1e3``, ``inf``, ``nan``, ``.inf``, hex floats;
  not out of range); anything else is text (``null`` and ``~`` included). A sequence holds
  values of one type.
* A parameter file maps node names to ``ros__parameters``, possibly nested in namespaces
  (``ns: {node: {ros__parameters: ...}}`` is ``/ns/node``); a name without a leading ``/`` is
  absolute; ``*`` stands for one name component and ``**`` for any number. Nested mappings
  under ``ros__parameters`` are dotted names. Which value wins when several apply is
  :func:`in_rcl_order`'s.
"""

from __future__ import annotations

import math
import re
import sys
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import yaml

from ..errors import ConfigError
from .yaml_files import compose, position, read_text

__all__ = [
    "Assignment",
    "ParameterRule",
    "Section",
    "ParameterFile",
    "RosArguments",
    "assignments",
    "in_rcl_order",
    "parse_ros_arguments",
    "pattern_matches",
    "read_parameter_file",
    "yaml_value",
]

_TRUE = frozenset(("y", "Y", "yes", "Yes", "YES", "true", "True", "TRUE", "on", "On", "ON"))
_FALSE = frozenset(("n", "N", "no", "No", "NO", "false", "False", "FALSE", "off", "Off", "OFF"))
# C's strtol with base 0: hexadecimal, octal (a leading 0) or decimal.
_C_INTEGER = re.compile(r"([+-]?)(0[xX][0-9a-fA-F]+|0[0-7]*|[1-9][0-9]*)")
# C's strtod: decimal and hexadecimal numbers, inf/infinity/nan; and YAML's .inf/.nan, which
# rcl reads itself.
_C_DECIMAL = re.compile(r"[+-]?(\d+\.?\d*|\.\d+)([eE][+-]?\d+)?")
_C_HEX = re.compile(r"([+-]?)(0[xX](?:[0-9a-fA-F]+\.?[0-9a-fA-F]*|\.[0-9a-fA-F]+))([pP][+-]?\d+)?")
_C_SPECIAL = re.compile(r"([+-]?)(inf|infinity|nan(\([0-9A-Za-z_]*\))?)", re.IGNORECASE)
_YAML_INF = re.compile(r"([+-]?)\.(inf|Inf|INF)")
_YAML_NAN = re.compile(r"\.(nan|NaN|NAN)")
_INT64 = (-(2**63), 2**63 - 1)
_TOKEN = re.compile(r"[A-Za-z0-9_]+")
# A -p rule's parameter name as rcl's lexer reads it (a file's keys are not restricted).
_PARAMETER_NAME = re.compile(r"[A-Za-z0-9_/]+(\.[A-Za-z0-9_/]+)*")
_PARAMETERS_KEY = "ros__parameters"
# Options that take one value, and flags, besides -p, -r and --params-file.
_VALUE_OPTIONS = ("--log-level", "--log-config-file", "--log-file-name", "-e", "--enclave")
_FLAGS = tuple(f"--{onoff}-{what}" for onoff in ("enable", "disable")
               for what in ("rosout-logs", "stdout-logs", "external-lib-logs"))


def _c_double(text: str) -> float | None:
    """The number ``strtod`` reads from all of ``text`` (None if it reads none, or sets ERANGE:
    an overflow, or an underflow to zero or below the normal range)."""
    if m := _YAML_INF.fullmatch(text):
        return -math.inf if m.group(1) == "-" else math.inf
    if _YAML_NAN.fullmatch(text):
        return math.nan
    if m := _C_SPECIAL.fullmatch(text):
        return float(m.group(1) + m.group(2).split("(")[0])
    if m := _C_HEX.fullmatch(text):
        x = float.fromhex(m.group(1) + m.group(2) + (m.group(3) or "p0"))
        nonzero = any(c in "123456789abcdefABCDEF" for c in m.group(2)[2:])
    elif m := _C_DECIMAL.fullmatch(text):
        x = float(text)
        nonzero = any(c in "123456789" for c in m.group(1))
    else:
        return None
    if math.isinf(x) or (x == 0.0 and nonzero) or 0.0 < abs(x) < sys.float_info.min:
        return None
    return x


def scalar_value(text: str, *, string: bool = False) -> bool | int | float | str:
    """A YAML scalar as rcl types it; ``string``: it was quoted or tagged ``!!str``."""
    if string:
        return text
    if text in _TRUE:
        return True
    if text in _FALSE:
        return False
    if m := _C_INTEGER.fullmatch(text):
        digits = m.group(2)
        base = 16 if digits[:2] in ("0x", "0X") else 8 if len(digits) > 1 and digits[0] == "0" else 10
        n = int(digits[2:] if base == 16 else digits, base) * (-1 if m.group(1) == "-" else 1)
        if _INT64[0] <= n <= _INT64[1]:
            return n
        # Beyond strtol's range rcl reads the text with strtod (octal digits as decimal ones).
    x = _c_double(text)
    return text if x is None else x


def _line(node: yaml.Node) -> int:
    return position(node)[0]


def _at(where: str, node: yaml.Node, what: str = "") -> str:
    """Where a problem is: ``parameter file FILE:LINE:COLUMN: what`` in a file (``where`` is
    ``parameter file FILE``), ``-p RULE (column C): what`` in a ``-p`` value."""
    line, column = position(node)
    place = f"{where}:{line}:{column}" if where.startswith("parameter file") else f"{where} (column {column})"
    return f"{place}: {what}" if what else place


def yaml_value(node: yaml.Node, where: str, name: str = "") -> Any:
    """A parameter value from a composed YAML node: a scalar or a sequence of scalars of one
    type (rcl's rules); a mapping or a nested sequence is a :class:`ConfigError` naming
    ``where`` (the file or the ``-p`` rule), the place and the parameter ``name``."""
    if isinstance(node, yaml.ScalarNode):
        return scalar_value(str(node.value), string=getattr(node, "rcl_string", False))
    if isinstance(node, yaml.SequenceNode):
        items = []
        for item in node.value:
            if not isinstance(item, yaml.ScalarNode):
                raise ConfigError(f"{_at(where, item, name)}: a list holds values, not lists or mappings",
                                  parameter=name or None)
            items.append(yaml_value(item, where, name))
        kinds = {type(v) for v in items}
        if len(kinds) > 1:
            names = sorted(k.__name__ for k in kinds)
            raise ConfigError(f"{_at(where, node, name)}: a list holds values of one type, got {' and '.join(names)} "
                              "(quote text that looks like a number or a boolean)", parameter=name or None)
        return items
    raise ConfigError(f"{_at(where, node, name)}: expected a value or a list, got a mapping", parameter=name or None)


# --------------------------------------------------------------------------- parameter files
def pattern_matches(pattern: str, fqn: str) -> bool:
    """Whether a node pattern (``/NS/NAME``, with ``*`` for one name component and ``**`` for
    any number, none included) matches the node ``fqn``."""
    parts = []
    for component in pattern.strip("/").split("/"):
        parts.append("(/[^/]+)*" if component == "**" else "/[^/]+" if component == "*" else "/" + re.escape(component))
    return re.fullmatch("".join(parts), fqn) is not None


@dataclass(frozen=True)
class Section:
    """One ``NODE: ros__parameters:`` section of a parameter file: the node pattern as written
    (``key``), absolute (``pattern``), its line, and its ``(name, value, line, column)``
    parameters."""

    key: str
    pattern: str
    line: int
    parameters: tuple[tuple[str, Any, int, int], ...]

    @property
    def wildcard(self) -> bool:
        """Whether the pattern holds ``*`` or ``**`` (it may then apply to other nodes too)."""
        return "*" in self.pattern

    @property
    def node_name(self) -> str:
        """The node name the pattern ends in (``*`` or ``**`` for a wildcard)."""
        return self.pattern.rsplit("/", 1)[-1]

    def matches(self, fqn: str) -> bool:
        """Whether the section applies to the node ``/NS/NAME`` (:func:`pattern_matches`)."""
        return pattern_matches(self.pattern, fqn)


@dataclass(frozen=True)
class ParameterFile:
    """A ``--params-file`` (or the replay's ``--config``): its path and sections in order."""

    path: Path
    sections: tuple[Section, ...]


def _flatten(node: yaml.MappingNode, prefix: str, where: str) -> Iterator[tuple[str, Any, int, int]]:
    for key, value in node.value:
        name = f"{prefix}{key.value}"
        if isinstance(value, yaml.MappingNode):
            yield from _flatten(value, name + ".", where)
        else:
            yield name, yaml_value(value, where, name), *position(key)


def _parameters(node: yaml.MappingNode, pattern: str, path: Path) -> tuple[tuple[str, Any, int, int], ...]:
    """A section's parameters, dotted; one given twice (a dotted ``estimator.lag_span`` beside
    a nested ``estimator: {lag_span: ...}``) is refused naming both places."""
    out = tuple(_flatten(node, "", f"parameter file {path}"))
    first: dict[str, tuple[int, int]] = {}
    for name, _value, line, column in out:
        if name in first:
            raise ConfigError(f"parameter file {path}:{line}:{column}: parameter {name} given twice in section "
                              f"{pattern} (first at line {first[name][0]}, column {first[name][1]}); give it once",
                              parameter=name)
        first[name] = (line, column)
    return out


def _sections(node: yaml.Node, path: list[str], written: list[str], file: Path) -> Iterator[Section]:
    """The sections under ``node``, whose keys so far are ``written``, with the name components
    ``path`` (namespaces and node)."""
    where = f"parameter file {file}"
    if not isinstance(node, yaml.MappingNode):
        raise ConfigError(f"{_at(where, node)}: expected a mapping of node names to 'ros__parameters:'")
    for key, value in node.value:
        name = str(key.value)
        if name != _PARAMETERS_KEY:
            components = [c for c in name.split("/") if c]
            bad = [c for c in components if c not in ("*", "**") and not _TOKEN.fullmatch(c)]
            if bad or not components:
                raise ConfigError(f"{_at(where, key)}: {name!r} is not a node name: names hold letters, digits and "
                                  "'_', with '/' between namespaces and '*' or '**' as wildcards")
            yield from _sections(value, [*path, *components], [*written, name], file)
            continue
        if not path:
            raise ConfigError(f"{_at(where, key)}: 'ros__parameters' needs a node name above it")
        pattern = "/" + "/".join(path)
        if not isinstance(value, yaml.MappingNode):
            raise ConfigError(f"{_at(where, key)}: section {pattern}: 'ros__parameters' must be a mapping of "
                              "parameters")
        yield Section(key="/".join(written), pattern=pattern, line=_line(key),
                      parameters=_parameters(value, pattern, file))


def read_parameter_file(path: str | Path) -> ParameterFile:
    """A ROS 2 parameter file's sections; every problem (missing, not UTF-8, not YAML, a key or
    a parameter given twice, not the ``NODE: ros__parameters:`` layout, a mixed list) is a
    :class:`ConfigError` naming the file (:mod:`.yaml_files`' policy)."""
    path = Path(path)
    root = compose(read_text(path, "parameter file"), f"parameter file {path}")
    return ParameterFile(path, () if root is None else tuple(_sections(root, [], [], path)))


# --------------------------------------------------------------------------- the command line
@dataclass(frozen=True)
class ParameterRule:
    """A ``-p [NODE:]NAME:=VALUE`` rule: ``node`` is None when it applies to every node."""

    node: str | None
    name: str
    value: Any
    text: str

    @property
    def pattern(self) -> str:
        """The node pattern rcl files the rule under: every node, or ``/NODE`` (so a prefixed
        rule applies to the node of that name in the root namespace only)."""
        return "/**" if self.node is None else f"/{self.node}"


@dataclass(frozen=True)
class RosArguments:
    """What ``--ros-args`` say about one node: its name and namespace after the remaps, the
    parameter sources in command-line order, and the arguments outside ``--ros-args``."""

    node_name: str
    namespace: str
    sources: tuple[ParameterFile | ParameterRule, ...]
    other_arguments: tuple[str, ...]

    @property
    def fqn(self) -> str:
        return f"{self.namespace.rstrip('/')}/{self.node_name}"


@dataclass(frozen=True)
class Assignment:
    """A value a source gives a parameter, filed under a node ``pattern``; ``source``: the
    ``-p`` rule, or the file and section; ``origin``: the same with the line and column of a
    file's value; ``exact``: the source names one node (a ``-p`` rule, or a section without
    wildcards), not every node of a kind."""

    name: str
    value: Any
    source: str
    origin: str
    pattern: str
    exact: bool


def assignments(source: ParameterFile | ParameterRule) -> list[Assignment]:
    """Every value a ``-p`` rule or a parameter file gives, for whichever node."""
    if isinstance(source, ParameterRule):
        return [Assignment(source.name, source.value, source.text, source.text, source.pattern, True)]
    return [Assignment(name, value, f"parameter file {source.path}, section {s.key}",
                       f"parameter file {source.path}:{line}:{column}, section {s.key}", s.pattern, not s.wildcard)
            for s in source.sections for name, value, line, column in s.parameters]


def in_rcl_order(sources: Sequence[ParameterFile | ParameterRule],
                 applies: Callable[[str], bool]) -> list[Assignment]:
    """The assignments of ``sources`` to the node whose patterns ``applies``, in the order rcl
    applies them (a later one wins). rcl files every value under its node pattern, the
    patterns in the order they first appear, a repeated value replacing the earlier one in
    place; the node then takes the patterns that match it in that order. So a later ``-p``
    (filed under ``/**``) does not override a section that names the node if ``/**`` appeared
    first."""
    entries: dict[str, dict[str, Assignment]] = {}
    for source in sources:
        for a in assignments(source):
            entries.setdefault(a.pattern, {})[a.name] = a
    return [a for pattern, entry in entries.items() if applies(pattern) for a in entry.values()]


def _split_rule(flag: str, rule: str) -> tuple[str | None, str, str]:
    """``[NODE:]NAME:=VALUE`` of a ``-p`` or ``-r`` rule as (node, name, value)."""
    head, sep, value = rule.partition(":=")
    node, colon, name = head.rpartition(":")
    if not sep or not name or (colon and not _TOKEN.fullmatch(node)):
        raise ConfigError(f"{flag} {rule}: expected [NODE:]NAME:=VALUE")
    return (node if colon else None), name, value


def _parameter_rule(flag: str, rule: str) -> ParameterRule:
    node, name, text = _split_rule(flag, rule)
    where = f"{flag} {rule}"
    if not _PARAMETER_NAME.fullmatch(name):
        raise ConfigError(f"{where}: {name!r} is not a parameter name")
    if not text.strip():
        raise ConfigError(f"{where}: no value after ':='")
    root = compose(text, where)
    if root is None:
        raise ConfigError(f"{where}: no value after ':='")
    return ParameterRule(node, name, yaml_value(root, where, name), where)


def _remap(flag: str, rule: str, original: str, renamed: dict[str, str]) -> None:
    """Record a ``__node``/``__ns`` remap that applies to the node first named ``original``."""
    node, name, value = _split_rule(flag, rule)
    if name not in ("__node", "__ns") or (node is not None and node != original) or name in renamed:
        return
    if name == "__node" and not _TOKEN.fullmatch(value):
        raise ConfigError(f"{flag} {rule}: a node name holds letters, digits and '_'")
    if name == "__ns" and not (value.startswith("/") and all(_TOKEN.fullmatch(c) for c in value.strip("/").split("/")
                                                              if value != "/")):
        raise ConfigError(f"{flag} {rule}: a namespace starts with '/' and holds names of letters, digits and '_'")
    renamed[name] = value


def parse_ros_arguments(argv: Sequence[str], node_name: str) -> RosArguments:
    """The ROS arguments of a command line (``argv`` as ``rclpy.init`` takes it) for the node
    first named ``node_name``. A malformed argument is a :class:`ConfigError` naming it; the
    parameter files are read here, so a missing or malformed one is too."""
    sources: list[ParameterFile | ParameterRule] = []
    renamed: dict[str, str] = {}
    others: list[str] = []
    in_ros = False
    i = 0
    while i < len(argv):
        arg = argv[i]
        i += 1
        if arg == "--ros-args":
            in_ros = True
        elif not in_ros:
            others.append(arg)
        elif arg == "--":
            in_ros = False
        elif arg in _FLAGS:
            pass
        elif arg in ("-p", "--param", "-r", "--remap", "--params-file", *_VALUE_OPTIONS):
            if i == len(argv):
                raise ConfigError(f"{arg} at the end of the ROS arguments: it needs a value")
            value = argv[i]
            i += 1
            if arg in ("-p", "--param"):
                sources.append(_parameter_rule(arg, value))
            elif arg in ("-r", "--remap"):
                _remap(arg, value, node_name, renamed)
            elif arg == "--params-file":
                sources.append(read_parameter_file(value))
        else:
            raise ConfigError(f"unknown ROS argument {arg!r} (after --ros-args: -p NAME:=VALUE, --params-file FILE, "
                              "-r FROM:=TO, --log-level LEVEL, ...; end them with --)")
    return RosArguments(renamed.get("__node", node_name), renamed.get("__ns", "/"), tuple(sources), tuple(others))
