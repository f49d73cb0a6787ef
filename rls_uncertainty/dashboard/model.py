"""What the dashboard shows of the estimates, built from the node's output arrays (no ROS, no
web server: the live subscriber and the replay reader feed the same :class:`.hub.Hub`).

Topics. :func:`array_key` names what a topic under the node carries: the estimation method
(``time``: the recursive least squares of the paper, ``~/M/<array>``; ``frequency``: the
frequency-domain estimator of docs/frequency.md, ``~/M/frequency/<array>`` for the four paired
arrays), the model and the array. It is the one place that maps topics to methods: everything
downstream (pairing, histories, the page) keeps the methods apart.

Pairing. Every output array carries its sample's time in the label of its last dim
(``stamp:SEC.NANOSEC``, docs/dashboard.md), so a model's sample is complete when its
``estimates``, ``standard_errors`` (corrected, Eqs. 20/22), ``standard_errors_conventional``
(Eq. 13) and ``converged`` arrays *of the same stamp* have arrived, in whatever order and
interleaved with other samples: never by arrival. An array whose partners never come (a lost
message) is dropped, and counted, once :data:`MAX_PENDING` samples of newer stamps of its
model have completed.

History. Each model keeps its completed samples in columns of bounded size: when
:data:`HISTORY_CAPACITY` samples are held, every other sample of the older half is dropped,
so the newest half stays at full rate and older data is thinned progressively (memory is
bounded whatever the flight's length). Only the display is thinned: the node computes every
sample.
"""

from __future__ import annotations

import math
from collections import OrderedDict
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..aero.models import OUTPUTS, REGRESSORS
from ..datapath.outputs import (
    PAIRED,
    TIME_DOMAIN,
    ArrayKey,
    parse_stamp_label,
)

__all__ = [
    "ArrayUpdate",
    "array_update",
    "Sample",
    "ModelHistory",
    "Pairing",
    "MAX_PENDING",
    "MAX_WAITING",
    "HISTORY_CAPACITY",
    "MAX_MODELS",
    "MAX_PARAMETERS",
    "MAX_STAMP_NS",
    "refusal",
]

MAX_PENDING = 64  # newer samples completed before a stamp's missing partner arrays count as lost
MAX_WAITING = 4096  # stamps per model awaiting partners (a late joiner's burst of kept samples)
HISTORY_CAPACITY = 20_000  # samples per model; 200 s at full rate at 50 Hz, older data thinned
# What a node can publish (Eq. 2): six models per method, each with at most one parameter per
# regressor. Beyond, arrays and samples are refused and counted: memory stays bounded whatever
# a recording or a node sends.
MAX_MODELS = len(OUTPUTS)
MAX_PARAMETERS = len(REGRESSORS)
MAX_STAMP_NS = 2**63 - 1  # int64 nanoseconds since 1970: up to the year 2262


@dataclass(frozen=True)
class ArrayUpdate:
    """One received ``~/M/<suffix>`` array: its parameter names (``layout.dim[0].label``), its
    values, the sample stamp from its last dim's label, when it was published (ns since the
    epoch, DDS source time; None when unknown, as in a replay) and the estimation method."""

    model: str
    suffix: str
    names: tuple[str, ...]
    data: tuple[float, ...]
    stamp_ns: int
    published_ns: int | None = None
    method: str = TIME_DOMAIN


def array_update(key: ArrayKey, msg: Any, published_ns: int | None = None) -> ArrayUpdate:
    """An :class:`ArrayUpdate` from a ``std_msgs/Float64MultiArray`` (rclpy's, rosbags' or
    :mod:`...cdr`'s message: read by field name): the names from ``layout.dim[0].label``, the
    stamp from the last dim's label. ValueError when the layout does not carry them."""
    dims = msg.layout.dim
    if len(dims) < 2:
        raise ValueError(f"{key.model}/{key.suffix}: {len(dims)} dims, expected the names and the stamp")
    names = tuple(str(dims[0].label).split(","))
    stamp = parse_stamp_label(str(dims[-1].label))
    return ArrayUpdate(key.model, key.suffix, names, tuple(float(x) for x in msg.data), stamp, published_ns,
                       key.method)


@dataclass(frozen=True)
class Sample:
    """A model's complete sample: estimate, corrected and conventional standard errors and
    convergence flags per parameter, the publish time of its last array, the method."""

    model: str
    stamp_ns: int
    names: tuple[str, ...]
    estimate: tuple[float, ...]
    se: tuple[float, ...]
    se_conventional: tuple[float, ...]
    converged: tuple[float, ...]
    published_ns: int | None
    method: str = TIME_DOMAIN


@dataclass
class _Pending:
    """A stamp's arrays so far, and how many samples of newer stamps completed since."""

    arrays: dict[str, ArrayUpdate] = field(default_factory=dict)
    overtaken: int = 0


@dataclass
class Pairing:
    """Completes samples from arrays paired by their stamps (see the module docstring).
    ``dropped`` counts arrays refused, by reason.

    A stamp's arrays wait for their partners as long as fewer than ``max_pending`` samples of
    *newer* stamps have completed: each array's messages come in order, so partners that did
    not come before that many newer samples were lost. Counting newer samples, not all
    samples, lets a late joiner's burst (every kept sample of one array, then of the next)
    pair up. At most ``max_stamps`` stamps wait per model; beyond, the oldest are dropped."""

    max_pending: int = MAX_PENDING
    max_stamps: int = MAX_WAITING
    dropped: dict[str, int] = field(default_factory=dict)
    _pending: dict[tuple[str, str], OrderedDict[int, _Pending]] = field(default_factory=dict)

    def count(self, reason: str, n: int = 1) -> None:
        self.dropped[reason] = self.dropped.get(reason, 0) + n

    def add(self, update: ArrayUpdate) -> Sample | None:
        """The sample ``update`` completes, if any."""
        if update.suffix not in PAIRED:
            return None
        if len(update.data) != len(update.names) or not update.names:
            self.count("bad_layout")
            return None
        if not all(math.isfinite(x) for x in update.data):
            self.count("non_finite")
            return None
        pending = self._pending.setdefault((update.method, update.model), OrderedDict())
        entry = pending.get(update.stamp_ns)
        if entry is None:
            entry = pending[update.stamp_ns] = _Pending()
            while len(pending) > self.max_stamps:
                self.count("unpaired", len(pending.popitem(last=False)[1].arrays))
        arrays = entry.arrays
        if update.suffix in arrays:
            self.count("duplicate")
            return None
        arrays[update.suffix] = update
        if len(arrays) < len(PAIRED):
            return None
        del pending[update.stamp_ns]
        for stamp in [s for s, e in pending.items() if s < update.stamp_ns]:
            waiting = pending[stamp]
            waiting.overtaken += 1
            if waiting.overtaken > self.max_pending:  # its partners were lost
                del pending[stamp]
                self.count("unpaired", len(waiting.arrays))
        names = {a.names for a in arrays.values()}
        if len(names) != 1:
            self.count("mismatched_names", len(arrays))
            return None
        published = [a.published_ns for a in arrays.values() if a.published_ns is not None]
        return Sample(update.model, update.stamp_ns, update.names, arrays["estimates"].data,
                      arrays["standard_errors"].data, arrays["standard_errors_conventional"].data,
                      arrays["converged"].data, max(published) if published else None, update.method)


class ModelHistory:
    """A model's samples in columns (time in ns; per parameter estimate, corrected and
    conventional standard errors, convergence flag), bounded by thinning the older half."""

    def __init__(self, names: Sequence[str], capacity: int = HISTORY_CAPACITY) -> None:
        if capacity < 4:
            raise ValueError(f"capacity must be at least 4, got {capacity}")
        self.names = tuple(names)
        self.capacity = capacity
        n = len(self.names)
        self._t = np.empty(capacity, dtype=np.int64)
        self._v = np.empty((capacity, 4, n))  # estimate, se, se_conventional, converged
        self.size = 0
        self.thinned = 0  # samples dropped from the display history

    def append(self, s: Sample) -> None:
        if self.size == self.capacity:
            self._thin()
        self._t[self.size] = s.stamp_ns
        self._v[self.size] = (s.estimate, s.se, s.se_conventional, s.converged)
        self.size += 1

    def _thin(self) -> None:
        """Drop every other sample of the older half (the oldest sample is kept)."""
        half = self.size // 2
        keep = np.r_[np.arange(0, half, 2), np.arange(half, self.size)]
        k = keep.size
        self._t[:k] = self._t[keep]
        self._v[:k] = self._v[keep]
        self.thinned += self.size - k
        self.size = k

    @property
    def last_stamp(self) -> int | None:
        return int(self._t[self.size - 1]) if self.size else None

    def stamp_from_end(self, k: int) -> int | None:
        """The stamp of the ``k``-th newest sample (the oldest when fewer are held)."""
        return int(self._t[max(0, self.size - k)]) if self.size else None

    def columns(self, start: int = 0, stop: int | None = None) -> dict:
        """Samples ``start`` to ``stop`` (the newest when None) as JSON-ready columns: ``t`` (s),
        and per quantity one list per parameter."""
        stop = self.size if stop is None else min(stop, self.size)
        t = self._t[start:stop]
        v = self._v[start:stop]
        return {
            "names": list(self.names),
            "t": (t * 1e-9).tolist(),
            "estimate": v[:, 0].T.tolist(),
            "se": v[:, 1].T.tolist(),
            "se_conventional": v[:, 2].T.tolist(),
            "converged": v[:, 3].T.tolist(),
        }


def refusal(s: Sample) -> str:
    """Why a complete sample is not shown (empty: it is): ``time_out_of_range`` (not in
    [0, :data:`MAX_STAMP_NS`]), ``too_many_parameters`` (more than :data:`MAX_PARAMETERS`),
    ``non_finite`` or ``se_not_positive`` (a corrected or conventional standard error of 0 or
    less: no band to draw; Eqs. 13, 20 and 22 give positive variances)."""
    if not 0 <= s.stamp_ns <= MAX_STAMP_NS:
        return "time_out_of_range"
    if len(s.names) > MAX_PARAMETERS:
        return "too_many_parameters"
    if not all(math.isfinite(x) for x in (*s.estimate, *s.se, *s.se_conventional)):
        return "non_finite"
    if not all(x > 0 for x in (*s.se, *s.se_conventional)):
        return "se_not_positive"
    return ""


def sample_columns(samples: Sequence[Sample]) -> dict:
    """Samples of one model (same names) as :meth:`ModelHistory.columns` does."""
    first = samples[0]
    n = len(first.names)
    return {
        "names": list(first.names),
        "t": [s.stamp_ns * 1e-9 for s in samples],
        "estimate": [[s.estimate[i] for s in samples] for i in range(n)],
        "se": [[s.se[i] for s in samples] for i in range(n)],
        "se_conventional": [[s.se_conventional[i] for s in samples] for i in range(n)],
        "converged": [[s.converged[i] for s in samples] for i in range(n)],
    }
