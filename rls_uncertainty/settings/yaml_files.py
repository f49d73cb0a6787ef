"""The package's one YAML reader, with one error policy.

Every YAML the package reads goes through here: parameter files and ``-p`` values
(:mod:`.ros_arguments`), aircraft files (:mod:`.models`), a campaign's maneuvers file, the
dashboard's reference values and ``convert``'s mapping file. A problem is one line naming the
file and, when the text is at fault, the line and column: ``WHAT FILE:LINE:COLUMN: problem``
(``WHAT`` says which kind of file, ``parameter file``, ``mapping file``...), raised as
:class:`.errors.ConfigError` or the caller's error class. A key given twice in one mapping is
refused here, naming both places: YAML leaves it to the reader and PyYAML keeps the last one
in silence. A file that is not a regular file (a directory, a FIFO) is refused before it is
opened, so that reading never blocks.

Scalars are composed with a mark of whether they were written as text (quoted or tagged
``!!str``): rcl types a parameter's value by that (:func:`.ros_arguments.scalar_value`).
"""

from __future__ import annotations

import stat
from pathlib import Path
from typing import Any

import yaml

from ..errors import ConfigError

__all__ = ["read_text", "compose", "load", "load_mapping", "position"]

_STR_TAG = "tag:yaml.org,2002:str"


class _Loader(yaml.SafeLoader):
    """Composes YAML nodes, marks the scalars written as text and refuses a key given twice."""

    def compose_scalar_node(self, anchor: Any) -> yaml.ScalarNode:  # the anchor's name (the stubs say otherwise)
        event = self.peek_event()  # type: ignore[no-untyped-call]
        node = super().compose_scalar_node(anchor)
        node.rcl_string = event.style in ("'", '"') or event.tag == _STR_TAG  # type: ignore[attr-defined]
        return node

    def compose_mapping_node(self, anchor: Any) -> yaml.MappingNode:
        node = super().compose_mapping_node(anchor)
        seen: dict[tuple[str, str], yaml.Node] = {}
        for key, _value in node.value:
            if not isinstance(key, yaml.ScalarNode):
                continue
            first = seen.setdefault((key.tag, str(key.value)), key)
            if first is not key:
                raise yaml.constructor.ConstructorError(
                    problem=f"key {key.value!r} given twice (first at line {first.start_mark.line + 1}, column "
                            f"{first.start_mark.column + 1}); give it once", problem_mark=key.start_mark)
        return node


def position(node: yaml.Node) -> tuple[int, int]:
    """The (line, column) where a composed node starts, from 1."""
    return int(node.start_mark.line) + 1, int(node.start_mark.column) + 1


def read_text(path: str | Path, what: str, error: type[Exception] = ConfigError) -> str:
    """The UTF-8 text of a file; missing, not a regular file, unreadable or not UTF-8 is one
    line ``WHAT FILE: problem``."""
    path = Path(path)
    where = f"{what} {path}"
    try:
        mode = path.stat().st_mode
        if not stat.S_ISREG(mode):
            kind = "a directory" if stat.S_ISDIR(mode) else "not a regular file"
            raise error(f"{where}: {kind}; give a YAML file")
        return path.read_text(encoding="utf-8")
    except FileNotFoundError as exc:
        raise error(f"{where}: no such file") from exc
    except UnicodeDecodeError as exc:
        raise error(f"{where}: not UTF-8 text (byte {exc.start})") from exc
    except OSError as exc:
        raise error(f"{where}: cannot be read ({exc.strerror or exc})") from exc


def compose(text: str, where: str, error: type[Exception] = ConfigError) -> yaml.Node | None:
    """The composed YAML of ``text`` (None when empty); ``where`` names its source (``parameter
    file p.yaml``, ``-p rate:=x``): a problem is one line ``WHERE:LINE:COLUMN: problem``."""
    try:
        return yaml.compose(text, Loader=_Loader)
    except yaml.MarkedYAMLError as exc:
        mark = exc.problem_mark or exc.context_mark
        at = f":{mark.line + 1}:{mark.column + 1}" if mark is not None else ""
        raise error(f"{where}{at}: not valid YAML: {exc.problem or exc.context}") from exc
    except yaml.YAMLError as exc:
        raise error(f"{where}: not valid YAML: {' '.join(str(exc).split())}") from exc


def load(path: str | Path, what: str, error: type[Exception] = ConfigError) -> Any:
    """A YAML file's contents as Python values (``safe_load``'s), read by the policy of the
    module docstring."""
    where = f"{what} {path}"
    node = compose(read_text(path, what, error), where, error)
    if node is None:
        return None
    try:
        return _Loader("").construct_document(node)
    except yaml.MarkedYAMLError as exc:
        mark = exc.problem_mark or exc.context_mark
        at = f":{mark.line + 1}:{mark.column + 1}" if mark is not None else ""
        raise error(f"{where}{at}: {exc.problem or exc.context}") from exc


def load_mapping(path: str | Path, what: str, error: type[Exception] = ConfigError) -> dict[str, Any]:
    """A YAML file whose top level is a mapping (:func:`load`)."""
    data = load(path, what, error)
    if not isinstance(data, dict):
        raise error(f"{what} {path}: expected a mapping at the top level")
    return data
