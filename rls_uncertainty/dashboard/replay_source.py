"""The dashboard's replay source: a finished ``rls-uncertainty replay`` output directory, read
from its ``estimates.mcap`` (the node's own messages, byte for byte, and its ``/diagnostics``;
see :mod:`..replay`), in log order, as the same items the live source hands over."""

from __future__ import annotations

from pathlib import Path

from ..bags import check_mcap_integrity, typestore
from ..errors import BagError
from .health import statuses_of
from .model import PAIRED

__all__ = ["read_replay"]


def read_replay(directory: str | Path) -> tuple[str, list[tuple]]:
    """``(node name, items)`` of a replay directory: ``("array", model, suffix, msg, None)``
    and ``("diagnostics", statuses)`` in log order. BagError when it holds no readable
    ``estimates.mcap``."""
    from rosbags.highlevel import AnyReader  # noqa: PLC0415 - the bag library only for replays

    path = Path(directory) / "estimates.mcap"
    if not path.is_file():
        raise BagError(f"{directory}: no estimates.mcap (the output directory of rls-uncertainty replay)")
    check_mcap_integrity(path)
    items: list[tuple] = []
    node = ""
    try:
        with AnyReader([path], default_typestore=typestore()) as reader:
            arrays = {}
            for c in reader.connections:
                parts = c.topic.rsplit("/", 2)
                if len(parts) == 3 and parts[2] in PAIRED and c.msgtype == "std_msgs/msg/Float64MultiArray":
                    arrays[c.id] = (parts[1], parts[2])
                    node = parts[0]
            wanted = [c for c in reader.connections if c.id in arrays or c.topic == "/diagnostics"]
            for conn, _t, raw in reader.messages(connections=wanted):
                msg = reader.deserialize(raw, conn.msgtype)
                if conn.id in arrays:
                    items.append(("array", *arrays[conn.id], msg, None))
                else:
                    items.append(("diagnostics", statuses_of(msg)))
    except BagError:
        raise
    except Exception as exc:  # rosbags raises many types for a corrupt file
        raise BagError(f"{path}: cannot read: {exc}") from exc
    if not node:
        raise BagError(f"{path}: holds no estimates (no ~/M/estimates topic)")
    return node, items
