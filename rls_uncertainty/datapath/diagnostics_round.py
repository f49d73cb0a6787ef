"""One diagnostics period of the node as short steps, so that reporting never holds up a sample.

A period's report (:class:`.diagnostics.Snapshot` -> :meth:`.diagnostics.DiagnosticsPolicy.update`
-> ``/diagnostics``, and ``~/M/fit``, ``~/M/identifiability`` by
:meth:`.outputs.OutputLayout.encode_fit_model`) costs several milliseconds of CPU with six
models, longer than an input period at 1 kHz. The node runs it as a :class:`DiagnosticsRound`
on its one executor thread, one :meth:`DiagnosticsRound.step` per intake pass, so the inputs
are fed between the steps. Each step does a bounded part:

1. on creation: the pipeline's counters (:meth:`.pipeline.Pipeline.counters`, plain copies) and
   the node's own facts, handed in (its clock, matched publishers, the latencies of the period);
2. one model's report (:meth:`.pipeline.Pipeline.model_report`), per model;
3. one model's ``fit`` and ``identifiability`` arrays, handed to ``publish_fit`` as they are
   encoded, per model;
4. the policy (:meth:`.diagnostics.DiagnosticsPolicy.update`) on the snapshot;
5. ``publish`` of the statuses (the node builds and publishes the ``DiagnosticArray``).

Each part reads the pipeline as it is when the part runs: a model's report may include the
samples that arrived after the counters were copied. With no message between the steps the
result is exactly the one-shot report of the same pipeline state.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import Any

from .diagnostics import DiagnosticsPolicy, Snapshot, Status
from .outputs import OutputLayout
from .pipeline import Pipeline

__all__ = ["DiagnosticsRound"]


class DiagnosticsRound:
    """The steps of one diagnostics period (module docstring). ``facts`` are the keyword
    arguments of :class:`.diagnostics.Snapshot` other than ``counters`` and ``models``."""

    def __init__(self, pipeline: Pipeline, layout: OutputLayout, policy: DiagnosticsPolicy,
                 facts: Mapping[str, Any], publish_fit: Callable[[int, bytes], None],
                 publish: Callable[[list[Status]], None]) -> None:
        self.pipeline, self.layout = pipeline, layout
        self._policy, self._facts = policy, dict(facts)
        self._publish_fit, self._publish = publish_fit, publish
        self._counters = pipeline.counters()
        self._models: list[tuple[str, Mapping]] = []
        self._statuses: list[Status] = []
        n = len(pipeline.config.models)
        self._steps: list[Callable[[], None]] = [
            *(lambda j=j: self._report(j) for j in range(n)),
            *(lambda j=j: self._fit(j) for j in range(n)),
            self._update,
            lambda: self._publish(self._statuses),
        ]
        self._next = 0

    @property
    def done(self) -> bool:
        return self._next >= len(self._steps)

    def step(self) -> bool:
        """Run the next step; True when the round is done (the statuses were published)."""
        if not self.done:
            self._next += 1
            self._steps[self._next - 1]()
        return self.done

    def run(self) -> None:
        """All remaining steps at once."""
        while not self.step():
            pass

    def _report(self, j: int) -> None:
        self._models.append((self.pipeline.config.models[j].output, self.pipeline.model_report(j)))

    def _fit(self, j: int) -> None:
        for index, raw in self.layout.encode_fit_model(self.pipeline, j):
            self._publish_fit(index, raw)

    def _update(self) -> None:
        snapshot = Snapshot(counters=self._counters, models=self._models, **self._facts)
        self._statuses = self._policy.update(snapshot)
