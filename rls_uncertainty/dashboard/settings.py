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
from collections import Counter
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any
from urllib.parse import urlsplit

from ..errors import ConfigError
from ..schema import check, option
from ..settings.config import NODE_NAME
from ..settings.yaml_files import load

__all__ = ["DEFAULT_NODE", "ServerOptions", "strong_token", "origin_of", "is_loopback", "check_options",
           "full_node_name", "load_reference"]

DEFAULT_NODE = f"/{NODE_NAME}"
_NAME = re.compile(r"^(/[A-Za-z_][A-Za-z0-9_]*)+$")
TOKEN_LENGTH, TOKEN_DISTINCT, TOKEN_BITS = 16, 10, 64
TOKEN_RULE = (f"at least {TOKEN_LENGTH} printable ASCII characters without spaces, at least {TOKEN_DISTINCT} of "
              f"them different, and {TOKEN_BITS} bits or more by their frequencies (not a repeated pattern)")


@dataclass(frozen=True)
class ServerOptions:
    """Where to listen, the token the page must present if any, the other web pages allowed to
    open the socket, and the connection bounds: checked when built."""

    host: str = option("127.0.0.1", "address to listen on (any but loopback needs a token, generated and printed "
                       "when not given)", cli="--host", own_check=True)
    port: int = option(8080, "TCP port (0 picks a free one)", low=0, high=65535, cli="--port")
    token: str | None = option(None, f"token the page must present ({TOKEN_RULE}; default: generated when --host "
                               "is not loopback)", cli="--token", own_check=True)
    allow_origin: tuple[str, ...] = option((), "origins besides the dashboard's own whose pages may open its socket "
                                           "(comma-separated, e.g. https://wall.example:8443)",
                                           cli="--allow-origin", own_check=True)
    max_connections: int = option(256, "connections served at once (pages, their assets and sockets); more are "
                                  "closed at once and counted", low=1, high=100_000, cli="--max-connections")
    header_timeout: float = option(10.0, "seconds a connection has to send a complete request, from its start or "
                                   "its previous response; then it is closed and counted", unit="s", low=0.1,
                                   high=3600.0, cli="--header-timeout")

    def __post_init__(self) -> None:
        check(self, "")
        if self.host != "localhost":
            try:
                ipaddress.ip_address(self.host)
            except ValueError:
                raise ConfigError(f"--host {self.host!r}: give an IP address of this machine (default 127.0.0.1)",
                                  parameter="--host") from None
        if self.token is not None and not strong_token(self.token):
            raise ConfigError(f"--token: {TOKEN_RULE} (python3 -c 'import secrets; print(secrets.token_urlsafe(24))' "
                              "makes one)", parameter="--token")
        object.__setattr__(self, "allow_origin", tuple(origin_of(o) for o in self.allow_origin))


def strong_token(token: str) -> bool:
    """Whether ``token`` meets :data:`TOKEN_RULE`: printable ASCII without spaces, at least
    :data:`TOKEN_LENGTH` characters, :data:`TOKEN_DISTINCT` of them different, and at least
    :data:`TOKEN_BITS` bits by its characters' frequencies (length times their Shannon entropy;
    16 identical characters have 0, a 32-character ``secrets.token_urlsafe(24)`` about 150)."""
    if len(token) < TOKEN_LENGTH or not token.isascii() or not token.isprintable() or " " in token:
        return False
    counts = Counter(token).values()
    bits = -sum(k * math.log2(k / len(token)) for k in counts)
    return len(counts) >= TOKEN_DISTINCT and bits >= TOKEN_BITS


def origin_of(value: str) -> str:
    """An ``--allow-origin`` entry as browsers send ``Origin``: ``scheme://host[:port]``
    (lower case, http or https, no path); ConfigError naming the flag otherwise."""
    parts = urlsplit(value.strip())
    try:
        port = parts.port
    except ValueError:
        port = None
        parts = parts._replace(netloc="")
    if parts.scheme not in ("http", "https") or not parts.hostname or parts.path not in ("", "/") or parts.query \
            or parts.fragment or parts.username or parts.password:
        raise ConfigError(f"--allow-origin {value!r}: give origins as scheme://host[:port] (http or https, no path), "
                          "e.g. https://wall.example:8443", parameter="--allow-origin")
    host = f"[{parts.hostname}]" if ":" in parts.hostname else parts.hostname
    return f"{parts.scheme}://{host}" + (f":{port}" if port is not None else "")


def is_loopback(host: str) -> bool:
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


def check_options(host: str = "127.0.0.1", port: int = 8080, token: str | None = None, **more: Any) -> ServerOptions:
    """The options (checked by :class:`ServerOptions`, ConfigError naming the one to change); a
    non-loopback host without a token gets a generated one."""
    options = ServerOptions(host, port, token, **more)
    if token is None and not is_loopback(host):
        return replace(options, token=secrets.token_urlsafe(24))
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
