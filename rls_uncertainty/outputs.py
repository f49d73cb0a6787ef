"""The node's output messages for one sample, as CDR bytes: one function for every place that
publishes or records them (the offline replay's ``estimates.mcap``; the node publishes the
same bytes, checked over DDS in ``test/test_player.py``).

Per sample, in this order: ``sample_stamp`` (``std_msgs/Header``), then for each ready model M
the arrays of :meth:`.pipeline.Pipeline.published_arrays` (``std_msgs/Float64MultiArray``):
``M/estimates``, ``M/standard_errors`` (corrected), ``M/standard_errors_conventional``,
``M/converged``, and on decimated samples ``M/covariance`` and ``M/covariance_conventional``
(parameter names in the label of each parameter axis, the sample time in the label of the last
dim). Topics are relative to the node (``/rls_estimator/...`` when published). The node
publishes exactly these bytes. No ROS import: :mod:`.cdr` encodes.
"""

from __future__ import annotations

from collections.abc import Iterable
from typing import TYPE_CHECKING

from .cdr import encode_float64_multiarray, encode_float64_multiarray_dims, encode_header
from .messages import stamp_label

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
    for a in pipeline.published_arrays(out):
        if len(a.shape) == 1:
            raw = encode_float64_multiarray(a.names, a.data.tolist(), when)
        else:
            raw = encode_float64_multiarray_dims(a.dims(when), a.data.tolist())
        messages.append((f"{a.model}/{a.suffix}", FLOAT64_MULTIARRAY, raw))
    return messages


def output_topics(models: Iterable[str]) -> list[tuple[str, str]]:
    """``(relative topic, message type)`` of every per-sample output of the models named in
    ``models`` (e.g. ``["CZ", "Cm"]``), in publishing order."""
    from .pipeline import MODEL_OUTPUTS  # noqa: PLC0415 - pipeline imports numpy and the estimator

    arrays = [(f"{m}/{suffix}", FLOAT64_MULTIARRAY) for m in models for suffix in MODEL_OUTPUTS]
    return [(SAMPLE_STAMP, HEADER), *arrays]
