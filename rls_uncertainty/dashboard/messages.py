"""The page's ``samples`` and ``snapshot`` messages (docs/dashboard.md, "What the page
receives"), built in pieces of at most :data:`FRAME_VALUES` numbers: a batch of a replay, or a
model's whole display history, is never one message of many megabytes, so what one page has
not read yet stays bounded (:mod:`.feed`) whatever the history's length.

A ``samples`` message holds, per model, columns as :meth:`.model.ModelHistory.columns` gives
them and ``count``: how many samples of that method and model the server has shown up to the
last one in the message (the page's own count, which tests compare with a replay's). A
snapshot is a ``snapshot`` message (the page starts over: the models' latest quality) followed
by ``samples`` messages marked ``"snapshot": true``, oldest first per model; each model's last
one carries its ``count``.
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator, Mapping, Sequence

from .model import ModelHistory, Sample, sample_columns

__all__ = ["FRAME_VALUES", "per_message", "samples_messages", "snapshot_messages"]

FRAME_VALUES = 4096  # numbers in one message at most: about 80 kB of JSON


def per_message(parameters: int, max_values: int = FRAME_VALUES) -> int:
    """Samples of a model of ``parameters`` parameters in one message: a time and four numbers
    per parameter each (estimate, corrected and conventional standard errors, flag)."""
    return max(1, max_values // (1 + 4 * parameters))


def samples_messages(method: str, runs: Iterable[tuple[str, Sequence[Sample], int]], sent_ns: int,
                     max_values: int = FRAME_VALUES) -> list[dict]:
    """The ``samples`` messages of one method's new samples. ``runs``: per model its samples
    (time order, one set of parameter names) and its count after the last of them. Models
    share a message while it holds at most ``max_values`` numbers; a longer run is split."""
    out: list[dict] = []
    models: dict[str, dict] = {}
    published: list[int] = []
    size = 0

    def flush() -> None:
        nonlocal size
        if models:
            out.append({"type": "samples", "method": method, "models": dict(models),
                        "published_ns": max(published) if published else None, "sent_ns": sent_ns})
        models.clear()
        published.clear()
        size = 0

    for model, samples, count in runs:
        k = per_message(len(samples[0].names), max_values)
        for start in range(0, len(samples), k):
            piece = samples[start:start + k]
            values = len(piece) * (1 + 4 * len(piece[0].names))
            if model in models or (models and size + values > max_values):
                flush()
            cols = sample_columns(piece)
            cols["count"] = count - (len(samples) - start - len(piece))
            models[model] = cols
            published.extend(s.published_ns for s in piece if s.published_ns is not None)
            size += values
    flush()
    return out


def snapshot_messages(histories: Mapping[tuple[str, str], ModelHistory], counts: Mapping[tuple[str, str], int],
                      quality: list[dict], max_values: int = FRAME_VALUES) -> Iterator[dict]:
    """The snapshot of the display histories (by ``(method, model)``), in pieces."""
    yield {"type": "snapshot", "quality": quality}
    for (method, model), h in histories.items():
        k = per_message(len(h.names), max_values)
        for start in range(0, h.size, k):
            cols = h.columns(start, start + k)
            if start + k >= h.size:
                cols["count"] = counts.get((method, model), 0)
            yield {"type": "samples", "method": method, "snapshot": True, "models": {model: cols}}
