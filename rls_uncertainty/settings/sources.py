"""Where the node's parameters come from, and what is refused.

The node reads its command line before rcl does (:func:`startup_parameters`; the syntax and
rcl's reading of values and files are in :mod:`.ros_arguments`), and the replay's ``--config``
is read by the same rules (:func:`load_parameters_file`). A misconfiguration stops the node before it starts, in one
line naming the parameter, the reason and where the value came from, exit status 2:

* a value out of range, of the wrong type or not one of the choices; a parameter file that is
  missing, unreadable or not valid YAML, or not laid out as ``NODE: ros__parameters:``; a
  malformed ``-p``, ``-r`` or ``--params-file`` argument; an argument outside ``--ros-args``;
* a parameter the node does not know (``estimator.lag``), given with ``-p`` (with no node
  prefix or this node's) or in a file section that names this node (``rls_estimator:``,
  ``/NAMESPACE/rls_estimator:``), with the closest known name as a suggestion
  (``did you mean estimator.lag_span?``);
* an unknown parameter in a wildcard section (``/**:``, ``/*:``) when it can only be meant for
  this node: in one of its groups (``estimator.``, ``inputs.``, ``limits.``, ...) or close to
  one of its names;
* a parameter file none of whose sections applies to this node (``rls_estimatr:``), by name,
  namespace or wildcard as rcl matches them (the replay, which has no namespace, takes the
  sections named ``rls_estimator`` in any namespace and the wildcard ones).

One WARN line each, and the node starts: the other unknown names of a wildcard section (such a
section applies to every node of a launch, so they may be meant for another), the sections of
a file that are for other nodes, and a ``-p OTHER_NODE:NAME:=VALUE`` rule for another node.
The parameters every ROS 2 node has (``use_sim_time``, ``start_type_description_service``,
``qos_overrides.*``) are known. A later source wins, as in rcl: files and ``-p`` rules in
command-line order, sections in file order.

A value is refused by the options class that holds it (:mod:`.parameters`), and the refusal
names where the value came from: the file, its line and column, or the ``-p`` rule.
"""

from __future__ import annotations

import difflib
import warnings
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from ..errors import ConfigError
from .config import NODE_NAME
from .models import config_dir
from .parameters import PARAMETER_NAMES, in_group, node_config, pipeline_config, typed, unknown_parameter
from .ros_arguments import (
    ParameterFile,
    ParameterRule,
    in_rcl_order,
    parse_ros_arguments,
    pattern_matches,
    read_parameter_file,
)

__all__ = [
    "NodeParameters",
    "ROS_PARAMETERS",
    "node_parameters",
    "node_parameters_file",
    "load_parameters_file",
    "startup_parameters",
]

# Parameters of every ROS 2 node (rclpy declares them), accepted beside the table's.
ROS_PARAMETERS = {"use_sim_time": False, "start_type_description_service": True}
_ROS_PREFIXES = ("qos_overrides.",)


@dataclass(frozen=True)
class NodeParameters:
    """The node's parameter values from its sources (dotted name -> value as given, the ROS
    parameters of every node included), where each came from, and the warnings to log."""

    values: dict[str, Any]
    origins: dict[str, str]
    warnings: tuple[str, ...]


def _suggestion(name: str) -> str:
    return unknown_parameter(name, tuple(ROS_PARAMETERS))


def _ours(name: str) -> bool:
    """A name that can only be meant for this node: in one of its groups, or close to one of its names."""
    return in_group(name) or bool(_suggestion(name))


def _known(name: str) -> bool:
    return name in PARAMETER_NAMES or name in ROS_PARAMETERS or name.startswith(_ROS_PREFIXES)


def _applies(node_name: str, fqn: str | None) -> Callable[[str], bool]:
    """Whether a node pattern applies to the node ``fqn`` (None: ``node_name`` in any namespace)."""
    if fqn is not None:
        return lambda pattern: pattern_matches(pattern, fqn)
    return lambda pattern: pattern.rsplit("/", 1)[-1] in (node_name, "*", "**")


def _source_notes(source: ParameterFile | ParameterRule, node_name: str, applies: Callable[[str], bool],
                  shown: str) -> list[str]:
    """The warnings about a source's parts for other nodes; a file with no part for the node
    (``shown``) is a :class:`ConfigError`."""
    if isinstance(source, ParameterRule):
        return [] if applies(source.pattern) else [f"{source.text}: for node {source.pattern}, not {shown}: ignored"]
    if not any(applies(s.pattern) for s in source.sections):
        keys = [s.key for s in source.sections]
        close = difflib.get_close_matches(node_name, [s.node_name for s in source.sections], n=1, cutoff=0.6)
        hint = f"; did you mean {node_name}?" if close else ""
        held = f"it has sections for {', '.join(keys)}{hint}" if keys else "it has no 'NODE: ros__parameters:' section"
        raise ConfigError(f"parameter file {source.path}: no section for node {shown} ({held}); name the node "
                          f"({node_name}, /NAMESPACE/{node_name}) or use a wildcard (/**)")
    others = [s.key for s in source.sections if not applies(s.pattern)]
    return [f"parameter file {source.path}: sections for other nodes ignored: {', '.join(others)}"] if others else []


def _typed(values: dict[str, Any], origins: dict[str, str]) -> dict[str, Any]:
    """Each value in its parameter's ROS type (:func:`.parameters.typed`); the parameters every
    node has must be true or false (the options classes check the others)."""
    for name, given in values.items():
        if name in ROS_PARAMETERS and not isinstance(given, bool):
            raise ConfigError(f"parameter {name!r} must be true or false, got {given!r} (from {origins[name]})")
    return {name: typed(name, given) for name, given in values.items()}


def node_parameters(sources: Sequence[ParameterFile | ParameterRule], node_name: str = NODE_NAME,
                    fqn: str | None = None) -> NodeParameters:
    """The values the sources give the node ``fqn`` (``None``: named ``node_name`` in any
    namespace), in rcl's order (:func:`.ros_arguments.in_rcl_order`), checked against
    :data:`.parameters.PARAMETERS` by the policy of the module docstring; a refusal is a
    :class:`ConfigError` naming the source."""
    applies = _applies(node_name, fqn)
    notes = [note for source in sources for note in _source_notes(source, node_name, applies, fqn or node_name)]
    values: dict[str, Any] = {}
    origins: dict[str, str] = {}
    unknown: dict[str, list[str]] = {}
    for a in in_rcl_order(sources, applies):
        if _known(a.name):
            values[a.name], origins[a.name] = a.value, a.origin
        elif a.exact or _ours(a.name):
            raise ConfigError(f"{a.origin}: unknown parameter {a.name!r}{_suggestion(a.name)}")
        else:  # in a wildcard section of a file
            unknown.setdefault(a.source, []).append(a.name)
    notes += [f"{where}: parameters that are not this node's ignored (meant for other nodes?): {', '.join(names)}"
              for where, names in unknown.items()]
    return NodeParameters(_typed(values, origins), origins, tuple(notes))


def _parameter_file_path(path_or_name: str | Path) -> Path:
    path = Path(path_or_name)
    return path if path.suffix else config_dir() / f"{path_or_name}.yaml"


def node_parameters_file(path_or_name: str | Path, node_name: str = NODE_NAME) -> NodeParameters:
    """The node's parameters from a ROS 2 parameter file (``NODE: ros__parameters: ...``, the
    file the node takes with ``--params-file``), or by name from ``config/NAME.yaml``, read as
    the node reads it (:func:`node_parameters`) for ``node_name`` in any namespace."""
    return node_parameters([read_parameter_file(_parameter_file_path(path_or_name))], node_name)


def load_parameters_file(path_or_name: str | Path, node_name: str = NODE_NAME) -> dict[str, Any]:
    """The dotted pipeline and node parameters of :func:`node_parameters_file` (its warnings
    issued as :class:`UserWarning`)."""
    params = node_parameters_file(path_or_name, node_name)
    for note in params.warnings:
        warnings.warn(note, stacklevel=2)
    return {k: v for k, v in params.values.items() if k in PARAMETER_NAMES}


def startup_parameters(argv: Sequence[str], node_name: str = NODE_NAME) -> NodeParameters:
    """The node's parameters from its command line (``argv`` as ``rclpy.init`` takes it), every
    one checked and the whole configuration built once (the aircraft file read), before rcl
    sees them. Arguments outside ``--ros-args`` (the program's path first) are refused: the
    node takes none of its own."""
    args = parse_ros_arguments(argv, node_name)
    others = list(args.other_arguments)
    if others and argv and argv[0] == others[0]:
        others.pop(0)  # the program
    if others:
        raise ConfigError(f"unexpected argument(s) {' '.join(others)}: the node takes ROS arguments only, after "
                          "--ros-args (e.g. --ros-args -p rate:=100.0 --params-file config/t2.yaml)")
    params = node_parameters(args.sources, args.node_name, args.fqn)
    ours = {k: v for k, v in params.values.items() if k in PARAMETER_NAMES}
    try:
        pipeline_config(ours)
        node_config(ours)
    except ConfigError as exc:
        raise with_origin(exc, params.origins) from exc
    return params


def with_origin(exc: ConfigError, origins: dict[str, str]) -> ConfigError:
    """The refusal of a value, with where the value came from when it came from a source."""
    if exc.parameter in origins:
        return ConfigError(f"{exc} (from {origins[exc.parameter]})", parameter=exc.parameter)
    return exc
