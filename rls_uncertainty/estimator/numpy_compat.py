"""numpy functions the estimator uses that numpy 1.26 lacks."""

from __future__ import annotations

import numpy as np

__all__ = ["vecdot", "einsum_vecdot"]


def einsum_vecdot(a: np.ndarray, b: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
    """``np.vecdot`` (numpy >= 2.0) for numpy 1.26: dot products over the last axis."""
    return np.einsum("...i,...i->...", a, b, out=out)


vecdot = getattr(np, "vecdot", einsum_vecdot)
