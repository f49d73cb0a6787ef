"""Which node the dashboard and the operator commands talk to, where DDS looks for it, and the
reference values the page draws: each option checked once, with an error that names it. No
ROS import (the command line validates before anything starts)."""

from __future__ import annotations

import math
import os
import re
from pathlib import Path

import yaml

from ..errors import ConfigError
from ..settings.config import NODE_NAME

__all__ = ["DEFAULT_NODE", "full_node_name", "split_node_name", "discovery_environment", "where", "load_reference"]

DEFAULT_NODE = f"/{NODE_NAME}"
_NAME = re.compile(r"^(/[A-Za-z_][A-Za-z0-9_]*)+$")


def full_node_name(value: str) -> str:
    """``--node``: a node name, relative names taken from the root (``rls_estimator`` ->
    ``/rls_estimator``, ``ns/rls_estimator`` -> ``/ns/rls_estimator``)."""
    full = value if value.startswith("/") else f"/{value}"
    if not _NAME.match(full):
        raise ConfigError(f"--node {value!r}: not a ROS node name (for example {DEFAULT_NODE} or /ns/{NODE_NAME})")
    return full


def split_node_name(full: str) -> tuple[str, str]:
    """``(namespace, name)`` of a fully qualified node name such as ``/ns/rls_estimator``."""
    ns, _, name = full.rpartition("/")
    return ns or "/", name


def discovery_environment() -> dict[str, str]:
    """The ROS domain and discovery settings DDS reads from the environment (with ROS's
    defaults), for the page and the error messages."""
    return {
        "domain": os.environ.get("ROS_DOMAIN_ID", "") or "0",
        "discovery_range": os.environ.get("ROS_AUTOMATIC_DISCOVERY_RANGE", "") or "SUBNET",
        "static_peers": os.environ.get("ROS_STATIC_PEERS", ""),
    }


def where() -> str:
    """``ROS_DOMAIN_ID=N, ROS_AUTOMATIC_DISCOVERY_RANGE=R`` for messages."""
    env = discovery_environment()
    peers = f", ROS_STATIC_PEERS={env['static_peers']}" if env["static_peers"] else ""
    return f"ROS_DOMAIN_ID={env['domain']}, ROS_AUTOMATIC_DISCOVERY_RANGE={env['discovery_range']}{peers}"


def load_reference(path: str | Path) -> dict[str, float]:
    """``--reference FILE``: a YAML mapping of parameter names (as the node's arrays name them,
    e.g. ``CZ_alpha``) to finite reference values (wind tunnel, simulation, a previous flight)."""
    try:
        data = yaml.safe_load(Path(path).read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, yaml.YAMLError) as exc:
        raise ConfigError(f"--reference {path}: cannot read: {exc}") from exc
    if not isinstance(data, dict) or not data:
        raise ConfigError(f"--reference {path}: expected a mapping of parameter names to numbers, e.g. CZ_alpha: -3.9")
    out = {}
    for name, value in data.items():
        ok = isinstance(value, int | float) and not isinstance(value, bool) and math.isfinite(value)
        if not isinstance(name, str) or not ok:
            raise ConfigError(f"--reference {path}: {name!r}: {value!r} is not a finite number")
        out[name] = float(value)
    return out
