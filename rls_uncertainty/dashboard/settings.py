"""The dashboard's settings: where the page listens (:class:`ServerOptions`), which node the
dashboard and the operator commands talk to, where DDS looks for it, and the reference values
the page draws: each option checked once, with an error that names it. No ROS or web import
(the command line validates before anything starts, and makes its flags from
:class:`ServerOptions`' fields)."""

from __future__ import annotations

import ipaddress
import math
import re
import secrets
from dataclasses import dataclass
from pathlib import Path

from ..errors import ConfigError
from ..schema import check, option
from ..settings.config import NODE_NAME
from ..settings.yaml_files import load

__all__ = ["DEFAULT_NODE", "ServerOptions", "is_loopback", "check_options", "full_node_name",
           "load_reference"]

DEFAULT_NODE = f"/{NODE_NAME}"
_NAME = re.compile(r"^(/[A-Za-z_][A-Za-z0-9_]*)+$")


@dataclass(frozen=True)
class ServerOptions:
    """Where to listen and the token the page must present, if any: checked when built."""

    host: str = option("127.0.0.1", "address to listen on (any but loopback needs a token, generated and printed "
                       "when not given)", cli="--host", own_check=True)
    port: int = option(8080, "TCP port (0 picks a free one)", low=0, high=65535, cli="--port")
    token: str | None = option(None, "token the page must present (at least 16 printable ASCII characters without "
                               "spaces; default: generated when --host is not loopback)", cli="--token",
                               own_check=True)

    def __post_init__(self) -> None:
        check(self, "")
        if self.host != "localhost":
            try:
                ipaddress.ip_address(self.host)
            except ValueError:
                raise ConfigError(f"--host {self.host!r}: give an IP address of this machine (default 127.0.0.1)",
                                  parameter="--host") from None
        t = self.token
        if t is not None and (len(t) < 16 or not t.isascii() or not t.isprintable() or " " in t):
            raise ConfigError("--token: at least 16 printable ASCII characters without spaces", parameter="--token")


def is_loopback(host: str) -> bool:
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


def check_options(host: str, port: int, token: str | None) -> ServerOptions:
    """The options (checked by :class:`ServerOptions`, ConfigError naming the one to change); a
    non-loopback host without a token gets a generated one."""
    options = ServerOptions(host, port, token)
    if token is None and not is_loopback(host):
        return ServerOptions(host, port, secrets.token_urlsafe(24))
    return options


def full_node_name(value: str) -> str:
    """``--node``: a node name, relative names taken from the root (``rls_estimator`` ->
    ``/rls_estimator``, ``ns/rls_estimator`` -> ``/ns/rls_estimator``)."""
    full = value if value.startswith("/") else f"/{value}"
    if not _NAME.match(full):
        raise ConfigError(f"--node {value!r}: not a ROS node name (for example {DEFAULT_NODE} or /ns/{NODE_NAME})")
    return full


def load_reference(path: str | Path) -> dict[str, float]:
    """``--reference FILE``: a YAML mapping of parameter names (as the node's arrays name them,
    e.g. ``CZ_alpha``) to finite reference values (wind tunnel, simulation, a previous flight)."""
    data = load(path, "--reference")
    if not isinstance(data, dict) or not data:
        raise ConfigError(f"--reference {path}: expected a mapping of parameter names to numbers, e.g. CZ_alpha: -3.9")
    out = {}
    for name, value in data.items():
        ok = isinstance(value, int | float) and not isinstance(value, bool) and math.isfinite(value)
        if not isinstance(name, str) or not ok:
            raise ConfigError(f"--reference {path}: {name!r}: {value!r} is not a finite number")
        out[name] = float(value)
    return out
