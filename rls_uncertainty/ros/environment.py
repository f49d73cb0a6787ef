"""The ROS domain and discovery settings DDS reads from the environment, for the operator's
messages (``status``, the dashboard): which domain and range a command looked on.
"""

from __future__ import annotations

import os

__all__ = ["discovery_environment", "where", "split_node_name"]


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


def split_node_name(full: str) -> tuple[str, str]:
    """``(namespace, name)`` of a fully qualified node name such as ``/ns/rls_estimator``."""
    ns, _, name = full.rpartition("/")
    return ns or "/", name
