"""The node's output messages for one sample, as CDR bytes: one function for every place that
publishes or records them (the offline replay's ``estimates.mcap``; the node publishes the
same bytes, checked over DDS in ``test/test_player.py``).

Per sample, in this order: ``sample_stamp`` (``std_msgs/Header``), then for each ready model M
``M/estimates``, ``M/standard_errors`` (corrected) and ``M/standard_errors_conventional``
(``std_msgs/Float64MultiArray``, parameter names in ``layout.dim[0].label``, the sample time in
``layout.dim[1].label``). Topics are relative to the node (``/rls_estimator/...`` when
published). No ROS import: :mod:`.cdr` encodes.
"""

from __future__ import annotations

from collections.abc import Iterable
from typing import TYPE_CHECKING

from .cdr import encode_float64_multiarray, encode_header
from .messages import ARRAY_OUTPUTS, stamp_label

if TYPE_CHECKING:
    from .pipeline import Pipeline, SampleOutput

__all__ = ["HEADER", "FLOAT64_MULTIARRAY", "SAMPLE_STAMP", "sample_messages", "output_topics"]

HEADER = "std_msgs/msg/Header"
FLOAT64_MULTIARRAY = "std_msgs/msg/Float64MultiArray"
SAMPLE_STAMP = "sample_stamp"


def sample_messages(pipeline: Pipeline, out: SampleOutput, frame_id: str) -> list[tuple[str, str, bytes]]:
    """``(relative topic, message type, CDR bytes)`` of every message the node publishes for
    the :class:`.pipeline.SampleOutput` ``out`` (models still initializing publish nothing)."""
    stamp = out.stamp_ns
    sec, nanosec = divmod(stamp, 1_000_000_000)
    messages = [(SAMPLE_STAMP, HEADER, encode_header(sec, nanosec, frame_id))]
    when = stamp_label(stamp)
    for name, label, theta, se, se_conv in pipeline.published(out):
        for suffix, data in zip(ARRAY_OUTPUTS, (theta, se, se_conv), strict=True):
            messages.append((f"{name}/{suffix}", FLOAT64_MULTIARRAY,
                             encode_float64_multiarray(label, data.tolist(), when)))
    return messages


def output_topics(models: Iterable[str]) -> list[tuple[str, str]]:
    """``(relative topic, message type)`` of every per-sample output of the models named in
    ``models`` (e.g. ``["CZ", "Cm"]``), in publishing order."""
    arrays = [(f"{m}/{suffix}", FLOAT64_MULTIARRAY) for m in models for suffix in ARRAY_OUTPUTS]
    return [(SAMPLE_STAMP, HEADER), *arrays]
