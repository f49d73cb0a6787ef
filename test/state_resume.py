"""A pipeline resumed in the middle of a run, for the state-file tests: through the file or by
handing the estimation over in memory, and what a saved file holds."""

from __future__ import annotations

import json

import numpy as np

from rls_uncertainty.datapath.pipeline import Pipeline


def contents(path):
    """A state file's arrays and its meta (parsed)."""
    with np.load(path) as data:
        arrays = {k: data[k] for k in data.files}
    return arrays, json.loads(str(arrays.pop("meta")))


def by_file(config, path, seen):
    """``resume(pipe)``: ``pipe`` saved to ``path`` and a fresh pipeline loaded from it; what the
    file held and what the loaded pipeline saves again are appended to ``seen``."""
    def resume(pipe):
        pipe.save_state(path)
        fresh = Pipeline(config)
        fresh.load_state(path)
        fresh.save_state(path.with_name("again.npz"))  # what the loaded pipeline holds
        seen.append((contents(path), contents(path.with_name("again.npz"))))
        return fresh
    return resume


def in_memory(config):
    """The estimation handed over as objects: a fresh pipeline (its inputs, delay line and
    differentiator restarted as after a load) continuing the very banks and instrument path."""
    def resume(pipe):
        fresh = Pipeline(config)
        fresh.bank, fresh._iv = pipe.bank, pipe._iv
        if pipe.frequency is not None:
            fresh.frequency.bank = pipe.frequency.bank
        return fresh
    return resume
