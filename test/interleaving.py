"""Messages of several streams in a random order that keeps each stream's own order, for the
sampling and pipeline tests (a node takes its topics' messages as they come)."""

import numpy as np


def interleave(rng, queues, weighted=False):
    """The items of ``queues`` (per stream, a list in its order), the streams randomly
    interleaved: uniformly among the streams with items left (slow streams race ahead, as in a
    node that takes one message per topic per round) or weighted by the items left."""
    pos = dict.fromkeys(queues, 0)
    out = []
    while True:
        left = [n for n in queues if pos[n] < len(queues[n])]
        if not left:
            return out
        if weighted:
            w = np.array([len(queues[n]) - pos[n] for n in left], dtype=float)
            name = left[rng.choice(len(left), p=w / w.sum())]
        else:
            name = left[rng.integers(len(left))]
        out.append(queues[name][pos[name]])
        pos[name] += 1
