"""Report-grade figures of a replay and of a campaign (matplotlib).

Front ends import this module lazily, when they draw (``replay``, ``campaign``); the numerical
core never imports it. Every figure is written in each requested format (:func:`save`: PNG at
``dpi``, 300 by default, SVG and PDF as vectors), with units on every axis
(:func:`parameter_unit`) and a title that names the maneuver or bag and the model. The
figures follow the paper's (Grauer & Morelli): Fig. 12 (:func:`figure12`), the final
estimate of every maneuver of a campaign with conventional (Eq. 13) and corrected (Eqs.
20/22) 2-sigma bars, the mean and the observed scatter. What each figure shows:
``docs/tools.md``, "Figures".
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from .errors import ConfigError

if TYPE_CHECKING:  # annotations only
    from matplotlib.figure import Figure

__all__ = ["FORMATS", "DEFAULT_DPI", "figure_formats", "parameter_unit", "parameter_label", "save", "figure12"]

FORMATS = ("png", "svg", "pdf")
DEFAULT_DPI = 300
# Regressors of Eq. 2 measured in radians: the flow angles, the control surfaces and the
# nondimensional rates (p b/2V, q cbar/2V, r b/2V: an angular rate times a time, in rad).
_PER_RADIAN = ("alpha", "beta", "delta_e", "delta_a", "delta_r", "p", "q", "r")
_RATE_REGRESSOR = {"p": "p b/2V", "q": "q cbar/2V", "r": "r b/2V"}


def figure_formats(text: str | Sequence[str]) -> tuple[str, ...]:
    """``"png,svg"`` (or a sequence of names) as a tuple of formats of :data:`FORMATS`, in the
    order given, each once; :class:`.errors.ConfigError` naming ``--figures`` otherwise."""
    names = [s.strip().lower() for s in (text.split(",") if isinstance(text, str) else text)]
    bad = [s for s in names if s not in FORMATS]
    if bad or not names:
        raise ConfigError(f"--figures: unknown figure format(s) {bad or names}; choose from {', '.join(FORMATS)}")
    return tuple(dict.fromkeys(names))


def _suffix(parameter: str) -> str:
    """``CZ_alpha`` -> ``alpha`` (outputs of Eq. 1 have no underscore)."""
    return parameter.split("_", 1)[1] if "_" in parameter else ""


def parameter_unit(parameter: str) -> str:
    """The unit of a parameter of Eq. 2 from its name: a derivative with respect to an angle,
    a control surface or a nondimensional rate (``q_hat = q cbar/2V``, in rad) is per radian
    (``1/rad``); the bias (``CZ_0``) is dimensionless (``-``)."""
    return "1/rad" if _suffix(parameter) in _PER_RADIAN else "-"


def parameter_label(parameter: str) -> str:
    """An axis label: the name and its unit, and for a rate derivative the rate it is per
    (``Cm_q, 1/rad (per q cbar/2V)``)."""
    rate = _RATE_REGRESSOR.get(_suffix(parameter))
    unit = parameter_unit(parameter)
    return f"{parameter}, {'dimensionless' if unit == '-' else unit}" + (f" (per {rate})" if rate else "")


def _pyplot() -> Any:
    import matplotlib  # noqa: PLC0415 - drawing only, on demand

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # noqa: PLC0415 - after the backend is chosen

    return plt


# One look for every figure: small fonts for a report column, light grid.
_STYLE = {"font.size": 8, "axes.titlesize": 9, "axes.labelsize": 8, "legend.fontsize": 7, "xtick.labelsize": 7,
          "ytick.labelsize": 7, "axes.grid": True, "grid.alpha": 0.3, "lines.linewidth": 1.0,
          "svg.hashsalt": "rls_uncertainty"}
# No dates or versions in the files: the same figure gives the same bytes.
_METADATA: dict[str, dict[str, Any]] = {"png": {"Software": None}, "svg": {"Date": None, "Creator": None},
                                        "pdf": {"CreationDate": None, "Producer": None, "Creator": None}}


def save(fig: Figure, stem: Path, formats: Sequence[str] = ("png",), dpi: int = DEFAULT_DPI) -> list[Path]:
    """``fig`` as ``stem.<format>`` for each of ``formats`` (PNG at ``dpi``), then closed."""
    plt = _pyplot()
    written = []
    try:
        for fmt in formats:
            path = stem.with_name(f"{stem.name}.{fmt}")
            fig.savefig(path, format=fmt, dpi=dpi, metadata=_METADATA[fmt])
            written.append(path)
    finally:
        plt.close(fig)
    return written


def _ensemble(estimates: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per parameter: the mean of the finite estimates and their sample standard deviation
    (the observed scatter of Table 4; NaN with fewer than two)."""
    mean, scatter = np.full(estimates.shape[1], np.nan), np.full(estimates.shape[1], np.nan)
    for i in range(estimates.shape[1]):
        e = estimates[np.isfinite(estimates[:, i]), i]
        if e.size:
            mean[i] = e.mean()
        if e.size > 1:
            scatter[i] = e.std(ddof=1)
    return mean, scatter


def figure12(model: str, maneuvers: Sequence[str], parameters: Sequence[str], estimates: Any,
             se_conventional: Any, se_corrected: Any, out_dir: str | Path, *, se_corrected_all: Any = None,
             formats: Sequence[str] = ("png",), dpi: int = DEFAULT_DPI, title: str | None = None,
             lags: str = "configured lags") -> list[Path]:
    """The paper's Fig. 12 for one model of a campaign: per parameter (one panel each), every
    maneuver's final estimate with its conventional (Eq. 13) and corrected (Eqs. 20/22)
    2-sigma bars side by side (and corrected with all lags when ``se_corrected_all`` is
    given), the mean over the maneuvers (a line) and the observed scatter (a band of mean
    +/- 2 sample standard deviations), y in the parameter's unit.

    ``model``: the model's output (``"CZ"``), used in the file name ``<model>_fig12.<fmt>``
    and the title; ``maneuvers``: the maneuvers' names (x axis, in this order);
    ``parameters``: the model's parameter names (``CZ_0, CZ_alpha, ...``); ``estimates``,
    ``se_conventional``, ``se_corrected`` and optionally ``se_corrected_all``: arrays
    ``(len(maneuvers), len(parameters))``, NaN where a maneuver has no value (a failed
    maneuver: drawn as a gap and left out of the mean and scatter); ``out_dir``: an existing
    directory; ``formats``: of :data:`FORMATS`; ``dpi``: PNG resolution; ``title``: the
    campaign's name (default: the model's); ``lags``: how the corrected bars' lags are named
    in the legend (``"50 lags"``). Returns the files written."""
    est = np.asarray(estimates, dtype=float)
    bars = [("conventional", np.asarray(se_conventional, dtype=float), "tab:red"),
            (f"corrected, {lags}", np.asarray(se_corrected, dtype=float), "tab:blue")]
    if se_corrected_all is not None:
        bars.append(("corrected, all lags", np.asarray(se_corrected_all, dtype=float), "tab:green"))
    shape = (len(maneuvers), len(parameters))
    for name, a in [("estimates", est)] + [(b[0], b[1]) for b in bars]:
        if a.shape != shape:
            raise ValueError(f"figure12: {name} must be (maneuvers, parameters) = {shape}, got {a.shape}")
    mean, scatter = _ensemble(est)
    plt = _pyplot()
    x = np.arange(len(maneuvers))
    offsets = np.linspace(-0.2, 0.2, len(bars)) if len(bars) > 1 else np.zeros(1)
    with plt.rc_context(_STYLE):
        fig, axes = plt.subplots(len(parameters), 1, figsize=(7, 1.8 * len(parameters) + 0.6), sharex=True,
                                 squeeze=False)
        for i, ax in enumerate(axes[:, 0]):
            if np.isfinite(scatter[i]):
                ax.axhspan(mean[i] - 2 * scatter[i], mean[i] + 2 * scatter[i], color="0.85", lw=0,
                           label="mean +/- 2 scatter")
            if np.isfinite(mean[i]):
                ax.axhline(mean[i], color="k", lw=0.8, label="mean")
            for (label, se, color), dx in zip(bars, offsets, strict=True):
                ax.errorbar(x + dx, est[:, i], yerr=2 * se[:, i], fmt="o", ms=2.5, color=color, elinewidth=1,
                            capsize=2, label=f"2 sigma {label}")
            ax.set_ylabel(parameter_label(parameters[i]))
        axes[0, 0].legend(loc="lower left", bbox_to_anchor=(0, 1.02), ncol=3, frameon=False)
        bottom = axes[-1, 0]
        bottom.set_xticks(x)
        if len(maneuvers) <= 30:  # a maneuver without any estimate is named as such
            none = ~np.isfinite(est).any(axis=1)
            bottom.set_xticklabels([f"{m} (none)" if n else m for m, n in zip(maneuvers, none, strict=True)],
                                   rotation=60, ha="right")
        else:  # too many names to read: the index (the order of the given names)
            bottom.set_xticks(x[:: max(1, len(x) // 20)])
        bottom.set_xlabel("maneuver" if len(maneuvers) <= 30 else "maneuver index")
        fig.suptitle(f"{title or model}: {model} final estimates over {len(maneuvers)} maneuvers (Fig. 12)")
        fig.tight_layout()
    return save(fig, Path(out_dir) / f"{model}_fig12", formats, dpi)
