"""Fig. 12 of the paper for a campaign: every maneuver's end-of-maneuver estimate of each
parameter of one model, with its conventional (Eq. 13) and corrected (Eq. 22) 2-sigma bars,
the mean over the maneuvers and the band mean +- 2 scatter (the sample standard deviation of
the estimates). A corrected bar about as long as the band is what the paper shows; the
conventional bars are much shorter in turbulence. Matplotlib is imported when a figure is drawn.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np

from .run import ManeuverResult
from .table4 import Table4Row

__all__ = ["figure12", "campaign_figures"]


def figure12(path: Path, model: str, rows: Sequence[Table4Row], results: Sequence[ManeuverResult], *,
             dpi: int = 150) -> Path:
    """``path``: one panel per parameter of ``model`` (its :class:`.table4.Table4Row` s),
    x the maneuvers in campaign order (those not estimated left empty)."""
    import matplotlib  # noqa: PLC0415 - figures only

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # noqa: PLC0415

    names = [res.name for res in results]
    x = np.arange(1, len(names) + 1)
    fig, axes = plt.subplots(len(rows), 1, figsize=(7.5, 1.9 * len(rows) + 0.6), sharex=True, squeeze=False)
    for ax, row in zip(axes[:, 0], rows, strict=True):
        values = {r.maneuver: r for res in results for r in res.rows if r.parameter == row.parameter and r.ok}
        th = np.array([values[n].estimate if n in values else np.nan for n in names])
        sc = np.array([values[n].se_conventional if n in values else np.nan for n in names])
        se = np.array([values[n].se_corrected if n in values else np.nan for n in names])
        if np.isfinite(row.scatter):
            ax.axhspan(row.mean - 2 * row.scatter, row.mean + 2 * row.scatter, color="0.85", label="mean +- 2 scatter")
        ax.axhline(row.mean, color="k", lw=0.8, label="mean")
        ax.errorbar(x - 0.12, th, yerr=2 * se, fmt="o", ms=3, color="tab:blue", capsize=2, lw=1,
                    label="corrected 2 sigma")
        ax.errorbar(x + 0.12, th, yerr=2 * sc, fmt="s", ms=3, color="tab:red", capsize=2, lw=1,
                    label="conventional 2 sigma")
        ax.set_ylabel(row.parameter)
    axes[0, 0].legend(loc="upper right", fontsize=7, ncol=2)
    axes[-1, 0].set_xlabel("maneuver")
    if len(names) <= 30:
        axes[-1, 0].set_xticks(x, names, rotation=60, fontsize=7)
    fig.suptitle(f"{model}: end-of-maneuver estimates over {len(names)} maneuvers (Fig. 12)")
    fig.tight_layout()
    fig.savefig(path, dpi=dpi, metadata={"Software": None})
    plt.close(fig)
    return path


def campaign_figures(out: Path, rows: Sequence[Table4Row], results: Sequence[ManeuverResult]) -> list[Path]:
    """``fig12_<model>.png`` for every model with an estimate in some maneuver."""
    written = []
    models = list(dict.fromkeys(r.model for r in rows))
    for model in models:
        mine = [r for r in rows if r.model == model]
        if any(r.maneuvers for r in mine):
            written.append(figure12(out / f"fig12_{model}.png", model, mine, results))
    return written
