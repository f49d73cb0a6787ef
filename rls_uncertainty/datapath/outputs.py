"""The node's outputs: names, topics, array layouts, stamp labels and their CDR bytes.

The node ``rls_estimator`` (:data:`NODE_NAME`) publishes, for every sample the pipeline used
(a :class:`.pipeline.SampleOutput`), in this order and relative to the node
(``/rls_estimator/...``):

* ``sample_stamp`` (``std_msgs/Header``): the sample's time, ``frame_id`` the node's
  ``frame_id`` parameter;
* per ready model M (:data:`MODEL_OUTPUTS`, each a ``std_msgs/Float64MultiArray``):
  ``M/estimates``, ``M/standard_errors`` (corrected, Eqs. 20/22),
  ``M/standard_errors_conventional`` (Eq. 13), ``M/converged`` (1.0/0.0 per parameter), and
  on the samples whose grid index is a multiple of ``outputs.covariance_decimation``
  ``M/covariance`` and ``M/covariance_conventional`` (n x n, row-major). Models still
  initializing, or withheld as non-finite, publish nothing: no NaN leaves. (Not with
  ``estimator.method: frequency``, which publishes the frequency-domain arrays only.)
* with ``estimator.method`` ``frequency`` or ``both``, per model M ready in the frequency
  domain on the samples where it publishes (every ``frequency.every``-th,
  :mod:`.frequency_path`; :data:`FREQUENCY_OUTPUTS`): ``M/frequency/estimates``,
  ``M/frequency/standard_errors`` (corrected, docs/frequency.md F7-F10),
  ``M/frequency/standard_errors_conventional`` (F5) and ``M/frequency/converged``, over the
  model's parameters without the bias (:attr:`.config.ModelConfig.frequency_parameter_names`:
  the frequency-domain method does not estimate it), labelled and stamped as the others.

Every array's ``layout.dim`` (:func:`dims`): one dim per axis labelled with the model's
parameter names (comma-separated), then ``(stamp label, 1, 1)``: the sample's time as
``stamp:SEC.NANOSEC`` (:func:`stamp_label`, read back by :func:`parse_stamp_label`), so each
array pairs with its sample without a second topic. Strides are row-major as ROS defines them.

Once per ``diagnostics_period`` (the node's steady clock; the replay's data time), per model
whose fit is ready (:data:`FIT_OUTPUTS`, reliable, transient local, depth 1: a display that
joins late gets the latest at once; :meth:`OutputLayout.encode_fit`):

* ``M/fit``: ``[r_squared, samples, bound_2sigma, rho_1 ... rho_L]``, ``dim[0]`` labelled
  ``r_squared,samples,bound_2sigma,rho_1,...,rho_L`` (L written out) of size and stride
  ``3 + L``: R^2, the samples since the estimator started (``n``), the white-noise bound
  ``2 / sqrt(n)`` and the residual autocorrelation coefficients ``rho_i = R(i) / R(0)`` (Eq. 17)
  at the ``L`` lags in use (at most :data:`FIT_LAGS_SHOWN`: with all lags kept, the first ones);
* ``M/identifiability``: an ``n x (n + 3)`` row-major matrix, one row per parameter:
  the correlations of its estimate with each parameter's (the corrected covariance, Eqs.
  20/22), its regressor's standard deviation since the start, the resolution that is tested
  against (both 0 for the bias, which is not tested) and 1.0/0.0 identifiable
  (:mod:`.identifiability`); ``dim[0]`` labelled with the parameter names, ``dim[1]`` with the
  parameter names then ``excitation,resolution,identifiable``.

Both carry the stamp label of the newest sample the estimator used in their last dim.

:class:`OutputLayout` makes a sample's messages as ``(topic index, CDR bytes)`` pairs: the node
publishes the bytes on its publisher of that index, the offline replay records them in
``estimates.mcap`` under the same topic: one function, byte-identical outputs (checked over DDS
in ``test/test_player.py``). No ROS import: :mod:`.cdr` encodes.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Iterator, Sequence
from typing import TYPE_CHECKING, NamedTuple

import numpy as np

from .cdr import (
    encode_float64_multiarray_dims,
    encode_float64_multiarray_tail,
    encode_header,
    multiarray_dim,
    multiarray_head,
)

if TYPE_CHECKING:  # annotations only: the pipeline is the core, this module its edge
    from .config import PipelineConfig
    from .pipeline import Pipeline, SampleOutput

# The node's name: its parameter sections, its private topics (/rls_estimator/...) and its
# diagnostics ("rls_estimator: ...").
NODE_NAME = "rls_estimator"

__all__ = [
    "PAIRED", "FIT_ARRAYS", "SHOWN", "TIME_DOMAIN", "FREQUENCY_DOMAIN", "METHODS", "ArrayKey", "array_key",
    "split_topic",
    "NODE_NAME", "HEADER", "FLOAT64_MULTIARRAY", "SAMPLE_STAMP", "MODEL_OUTPUTS", "ARRAY_OUTPUTS", "FREQUENCY",
    "FREQUENCY_OUTPUTS", "FIT_OUTPUTS",
    "FIT_LAGS_SHOWN", "stamp_label", "parse_stamp_label", "dims", "output_topics", "fit_topics", "PublishedArray",
    "Row", "OutputLayout", "fit_records",
]

HEADER = "std_msgs/msg/Header"
FLOAT64_MULTIARRAY = "std_msgs/msg/Float64MultiArray"
SAMPLE_STAMP = "sample_stamp"
# Every array published per model M as ~/M/<suffix>, in publishing order: three vectors of
# estimates and standard errors, the convergence flags, then (decimated) the two covariances.
MODEL_OUTPUTS = ("estimates", "standard_errors", "standard_errors_conventional", "converged", "covariance",
                 "covariance_conventional")
ARRAY_OUTPUTS = MODEL_OUTPUTS[:3]  # the estimates and their standard errors
# With estimator.method frequency or both, per model M as ~/M/frequency/<suffix>: the vectors.
FREQUENCY = "frequency"
FREQUENCY_OUTPUTS = MODEL_OUTPUTS[:4]
_PER_MODEL = len(MODEL_OUTPUTS)
# Published per model M as ~/M/<suffix> once per diagnostics period (module docstring).
FIT_OUTPUTS = ("fit", "identifiability")
FIT_LAGS_SHOWN = 1000  # autocorrelation coefficients in ~/M/fit at most (estimator.lag_span -1 keeps every lag)


def stamp_label(stamp: int) -> str:
    """``layout.dim[-1].label`` of every output array: the sample's time (``stamp:SEC.NANOSEC``)."""
    sec, nanosec = divmod(int(stamp), 1_000_000_000)
    return f"stamp:{sec}.{nanosec:09d}"


def parse_stamp_label(label: str) -> int:
    """The sample time in nanoseconds from :func:`stamp_label`'s text."""
    if not label.startswith("stamp:"):
        raise ValueError(f"not a stamp label: {label!r}")
    sec, _, nanosec = label[6:].partition(".")
    return int(sec) * 1_000_000_000 + int(nanosec)


def dims(names: str, shape: tuple[int, ...], stamp: str) -> list[tuple[str, int, int]]:
    """The ``std_msgs/MultiArrayLayout`` dims ``(label, size, stride)`` of an array of
    ``shape`` over the parameters ``names``, row-major as ROS defines them: one per axis
    labelled ``names``, then ``(stamp, 1, 1)`` (the stamp is always in the last dim)."""
    out = [(names, size, 0) for size in shape] + [(stamp, 1, 1)]
    stride = 1
    for i in range(len(out) - 1, -1, -1):
        stride *= out[i][1]
        out[i] = (out[i][0], out[i][1], stride)
    return out


def output_topics(models: Iterable[str], *, time: bool = True, frequency: bool = False) -> list[tuple[str, str]]:
    """``(relative topic, message type)`` of every per-sample output of the models named in
    ``models`` (e.g. ``["CZ", "Cm"]``), in publishing order: the time-domain arrays
    (:data:`MODEL_OUTPUTS`) unless ``time`` is false, then with ``frequency`` the
    frequency-domain ones (:data:`FREQUENCY_OUTPUTS`)."""
    models = list(models)
    arrays = [(f"{m}/{suffix}", FLOAT64_MULTIARRAY) for m in models for suffix in MODEL_OUTPUTS] if time else []
    if frequency:
        arrays += [(f"{m}/{FREQUENCY}/{suffix}", FLOAT64_MULTIARRAY) for m in models for suffix in FREQUENCY_OUTPUTS]
    return [(SAMPLE_STAMP, HEADER), *arrays]


def fit_topics(models: Iterable[str]) -> list[tuple[str, str]]:
    """``(relative topic, message type)`` of the per-period outputs of ``models``
    (:data:`FIT_OUTPUTS`), in publishing order."""
    return [(f"{m}/{suffix}", FLOAT64_MULTIARRAY) for m in models for suffix in FIT_OUTPUTS]


class PublishedArray(NamedTuple):
    """One array published for a sample: ``~/<model>/<suffix>`` with ``data`` (flat,
    row-major float64) of ``shape`` ``(n,)`` or ``(n, n)`` over the parameters ``names``
    (comma-separated, as in ``layout.dim[0].label``)."""

    model: str
    suffix: str
    names: str
    shape: tuple[int, ...]
    data: np.ndarray


class Row(NamedTuple):
    """One ready model's estimates of a sample (model ``index`` of the configuration)."""

    index: int  # type: ignore[assignment]  # shadows tuple.index; the field name is the API
    model: str
    names: tuple[str, ...]
    estimates: np.ndarray
    standard_errors: np.ndarray
    standard_errors_conventional: np.ndarray


class OutputLayout:
    """The outputs of one configuration's ``models``: ``(output name, parameter names)`` in
    the order of the pipeline's models; ``frequency``: per model, the parameters of its
    frequency-domain outputs (None: none published); ``time``: whether the time-domain arrays
    are published. :attr:`topics` lists every output topic (index 0 ``sample_stamp``, then
    :data:`MODEL_OUTPUTS` per model, then :data:`FREQUENCY_OUTPUTS` per model);
    :meth:`encode` gives a sample's messages by topic index."""

    def __init__(self, models: Sequence[tuple[str, Sequence[str]]],
                 frequency: Sequence[Sequence[str]] | None = None, *, time: bool = True) -> None:
        self.models = [(name, tuple(names)) for name, names in models]
        self.time = time
        self.frequency_models = None if frequency is None else \
            [(name, tuple(names)) for (name, _), names in zip(self.models, frequency, strict=True)]
        self.topics = output_topics([name for name, _ in self.models], time=time, frequency=frequency is not None)
        self.fit_topics = fit_topics(name for name, _ in self.models)
        # Per model: n, index of its first topic; per topic index: what :meth:`arrays` names it
        # and its layout bytes before the stamp's dim (:meth:`encode`).
        self._per_model = [(len(names), 1 + _PER_MODEL * j) for j, (_, names) in enumerate(self.models)] if time else []
        first = 1 + len(self._per_model) * _PER_MODEL
        self._per_frequency = [(len(names), first + len(FREQUENCY_OUTPUTS) * j)
                               for j, (_, names) in enumerate(self.frequency_models or [])]
        self._topic_info: list[tuple[str, str, str, tuple[int, ...], bytes]] = \
            [("", "", "", (), b"")] * len(self.topics)  # index 0: sample_stamp
        suffixes = [(MODEL_OUTPUTS, self.models if time else [], self._per_model),
                    ([f"{FREQUENCY}/{suffix}" for suffix in FREQUENCY_OUTPUTS], self.frequency_models or [],
                     self._per_frequency)]
        for names_of_outputs, models_, firsts in suffixes:
            for (name, names), (n, first) in zip(models_, firsts, strict=True):
                label = ",".join(names)
                for k, suffix in enumerate(names_of_outputs):
                    shape = (n, n) if suffix.startswith("covariance") else (n,)
                    self._topic_info[first + k] = (name, suffix, label, shape, _head(label, shape))

    @classmethod
    def for_config(cls, config: PipelineConfig) -> OutputLayout:
        """The outputs of a configuration (its ``estimator.method`` decides which)."""
        frequency = [m.frequency_parameter_names for m in config.models] if config.frequency is not None else None
        return cls([(m.output, m.parameter_names) for m in config.models], frequency, time=config.publishes_time)

    @classmethod
    def of(cls, pipeline: Pipeline) -> OutputLayout:
        return cls.for_config(pipeline.config)

    def arrays(self, out: SampleOutput) -> Iterator[PublishedArray]:
        """Every array published for a sample, per ready model in the order of
        :data:`MODEL_OUTPUTS` (the covariances only when ``out.covariance`` is set)."""
        info, new = self._topic_info, PublishedArray._make
        for index, data in self._walk(out):
            model, suffix, label, shape, _ = info[index]
            yield new((model, suffix, label, shape, data.ravel() if len(shape) == 2 else data))

    def encode(self, out: SampleOutput, frame_id: str, wanted: Sequence[bool] | None = None) -> list[tuple[int, bytes]]:
        """``(index into topics, CDR bytes)`` of every message published for ``out``:
        ``sample_stamp`` (header ``frame_id``), then each ready model's arrays; with
        ``wanted`` (a flag per topic index), only those of the topics it flags. The bytes are
        those of :func:`.cdr.encode_float64_multiarray_dims` over :meth:`arrays` (with
        :func:`dims`); the dims before the stamp's are built once per layout."""
        stamp = out.stamp_ns
        sec, nanosec = divmod(stamp, 1_000_000_000)
        messages = [(0, encode_header(sec, nanosec, frame_id))] if wanted is None or wanted[0] else []
        when = multiarray_dim(stamp_label(stamp), 1, 1)
        encode, info = encode_float64_multiarray_tail, self._topic_info
        for index, data in self._walk(out):
            if wanted is None or wanted[index]:
                messages.append((index, encode(info[index][4], when, data)))
        return messages

    def _walk(self, out: SampleOutput) -> Iterator[tuple[int, np.ndarray]]:
        """``(topic index, data)`` of every array published for ``out`` (a covariance as its
        ``(n, n)`` block), in :attr:`topics` order."""
        cov = out.covariance
        ready = out.ready.tolist()
        values = (out.theta, out.se, out.se_conventional, out.converged.astype(np.float64))
        for j, (n, first) in enumerate(self._per_model):
            if ready[j]:
                for k in range(4):
                    yield first + k, values[k][j, :n]
                if cov is not None:
                    yield first + 4, cov[0, j, :n, :n]
                    yield first + 5, cov[1, j, :n, :n]
        f = out.frequency
        if f is None or not self._per_frequency:
            return
        ready = f.ready.tolist()
        values = (f.theta, f.se, f.se_conventional, f.converged.astype(np.float64))
        for j, (n, first) in enumerate(self._per_frequency):
            if ready[j]:
                for k in range(len(FREQUENCY_OUTPUTS)):
                    yield first + k, values[k][j, :n]

    def rows(self, out: SampleOutput) -> Iterator[Row]:
        """Each ready model's time-domain estimates and standard errors of ``out`` (what the
        replay writes; none when they are not published). The rows are checked again here: a
        row with a non-finite value is skipped, so no NaN or infinity ever leaves."""
        if self.time:
            yield from _rows(self.models, out.ready, out.theta, out.se, out.se_conventional)

    def frequency_rows(self, out: SampleOutput) -> Iterator[Row]:
        """:meth:`rows` of the frequency-domain results (over the parameters without the bias),
        on the samples where they are published."""
        f = out.frequency
        if f is not None and self.frequency_models is not None:
            yield from _rows(self.frequency_models, f.ready, f.theta, f.se, f.se_conventional)

    # ------------------------------------------------------------------ once per period
    def encode_fit(self, pipe: Pipeline) -> list[tuple[int, bytes]]:
        """``(index into fit_topics, CDR bytes)`` of ``M/fit`` and ``M/identifiability`` of
        each model whose fit is ready (module docstring); nothing before the first sample or
        where a figure is not finite."""
        return [m for j in range(len(self.models)) for m in self.encode_fit_model(pipe, j)]

    def encode_fit_model(self, pipe: Pipeline, j: int) -> list[tuple[int, bytes]]:
        """:meth:`encode_fit` of model ``j`` alone (the node encodes one model per step)."""
        stamp = pipe.last_stamp_ns
        if stamp is None:
            return []
        arrays = _fit_arrays(pipe, j, self.models[j][1], stamp_label(stamp))
        if arrays is None:
            return []
        return [(len(FIT_OUTPUTS) * j + i, encode_float64_multiarray_dims(d, data.tolist()))
                for i, (d, data) in enumerate(arrays)]


def _head(names: str, shape: tuple[int, ...]) -> bytes:
    """The layout bytes of an array of ``shape`` over ``names`` before its stamp dim (:func:`dims`)."""
    return multiarray_head(dims(names, shape, "")[:-1], len(shape) + 1)


def _rows(models: list[tuple[str, tuple[str, ...]]], ready: np.ndarray, theta: np.ndarray, se: np.ndarray,
          se_conventional: np.ndarray) -> Iterator[Row]:
    for j, (name, names) in enumerate(models):
        if ready[j]:
            n = len(names)
            row = theta[j, :n], se[j, :n], se_conventional[j, :n]
            if all(map(math.isfinite, row[0].tolist() + row[1].tolist() + row[2].tolist())):
                yield Row(j, name, names, *row)


_Arrays = list[tuple[list[tuple[str, int, int]], np.ndarray]]


def _fit_arrays(pipe: Pipeline, j: int, names: tuple[str, ...], when: str) -> _Arrays | None:
    """The dims and data of model ``j``'s ``fit`` and ``identifiability`` arrays, or None."""
    fit = pipe.model_fit(j)
    if not fit["ready"]:
        return None
    bank, quality = pipe.bank, pipe.identifiability
    n_samples = bank.k
    R = bank.autocorrelation(j)
    lags = min(int(bank.lags_used[j]), FIT_LAGS_SHOWN, R.size - 1)
    rho = R[1 : lags + 1] / R[0] if R[0] > 0 else np.zeros(lags)
    fit_data = np.concatenate([[fit["r_squared"], n_samples, 2.0 / math.sqrt(max(n_samples, 1))], rho])
    n = len(names)
    cols = n + 3
    table = np.zeros((n, cols))
    table[:, :n] = quality.correlation[j, :n, :n]
    bias = quality.bias[j, :n]
    table[:, n] = np.where(bias, 0.0, quality.stats.std[j, :n])
    table[:, n + 1] = np.where(bias, 0.0, quality.resolution[j, :n])
    table[:, n + 2] = quality.identifiable[j, :n]
    if not (np.isfinite(fit_data).all() and np.isfinite(table).all()):
        return None
    label = ",".join(names)
    fit_label = f"r_squared,samples,bound_2sigma{',rho_1,...,rho_' + str(lags) if lags else ''}"
    return [
        ([(fit_label, fit_data.size, fit_data.size), (when, 1, 1)], fit_data),
        ([(label, n, n * cols), (f"{label},excitation,resolution,identifiable", cols, cols), (when, 1, 1)],
         table.ravel()),
    ]


def fit_records(pipe: Pipeline, log_ns: int, node: str = NODE_NAME) -> list[tuple[int, str, str, bytes]]:
    """The node's per-period outputs (:meth:`OutputLayout.encode_fit`) as bag records of CDR
    bytes logged at ``log_ns``: what the replay writes beside its ``/diagnostics``."""
    layout = OutputLayout.of(pipe)
    return [(log_ns, f"/{node}/{layout.fit_topics[i][0]}", FLOAT64_MULTIARRAY, raw)
            for i, raw in layout.encode_fit(pipe)]


# Reading the arrays back by topic (the dashboard, status, bag readers).
# The four arrays a sample needs, by suffix of ~/M/<suffix>.
PAIRED = ("estimates", "standard_errors", "standard_errors_conventional", "converged")
# Published once per diagnostics period (docs/node.md#fit-and-identifiability): Fig. 5's
# residual autocorrelation with R^2, and the parameters' identifiability.
FIT_ARRAYS = ("fit", "identifiability")
SHOWN = PAIRED + FIT_ARRAYS  # every array the dashboard subscribes to
TIME_DOMAIN = "time"  # the method of ~/M/<array>: recursive least squares (Eqs. 9-22)
FREQUENCY_DOMAIN = "frequency"  # of ~/M/frequency/<array>: equation error in the frequency domain (docs/frequency.md)
METHODS = (TIME_DOMAIN, FREQUENCY_DOMAIN)


class ArrayKey(NamedTuple):
    """What a topic under the node carries: ``method`` (one of :data:`METHODS`), ``model`` and
    ``suffix`` (one of :data:`SHOWN`; of :data:`PAIRED` for :data:`FREQUENCY_DOMAIN`)."""

    method: str
    model: str
    suffix: str


def array_key(relative: str) -> ArrayKey | None:
    """The :class:`ArrayKey` of a topic relative to the node (``CZ/estimates``), or None for a
    topic the dashboard does not show. ``M/frequency/<suffix>`` is the frequency-domain method's
    (only the paired arrays: it publishes no fit or identifiability)."""
    parts = relative.split("/")
    if len(parts) == 2 and parts[0] and parts[1] in SHOWN:
        return ArrayKey(TIME_DOMAIN, parts[0], parts[1])
    if len(parts) == 3 and parts[0] and parts[1] == FREQUENCY_DOMAIN and parts[2] in PAIRED:
        return ArrayKey(FREQUENCY_DOMAIN, parts[0], parts[2])
    return None


def split_topic(topic: str) -> tuple[str, ArrayKey] | None:
    """``(node, key)`` of an absolute topic of a node's shown arrays
    (``/ns/rls_estimator/CZ/frequency/estimates``: ``/ns/rls_estimator`` and the key), for a
    reader that does not know the node's name (a bag); None for any other topic. The
    frequency-domain form is tried first, so its ``frequency`` is never taken for a model."""
    parts = topic.split("/")
    for depth in (3, 2):
        if len(parts) > depth + 1:
            key = array_key("/".join(parts[-depth:]))
            if key is not None:
                return "/".join(parts[:-depth]), key
    return None
