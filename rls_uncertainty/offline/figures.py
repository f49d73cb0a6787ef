"""Report-grade figures of a replay and of a campaign (matplotlib).

Front ends import this module when they draw (``replay``, ``campaign``); the numerical core
never imports it, and matplotlib is imported only when a figure is drawn. Every figure is
written in each requested format (:class:`FigureOptions`: PNG at ``dpi``, 150 by default;
SVG and PDF as vectors; no dates or random ids, so a run gives the same bytes), with units on
every axis (:func:`parameter_label`) and a title that names the maneuver or bag and the
model. The figures follow the paper's (Grauer & Morelli):

* :func:`replay_figures`, per model of a replay: ``M_estimates`` (Figs. 6/13: estimates with
  corrected Eq. 22 and conventional Eq. 13 2-sigma bands, the excitation onset, the
  convergence time, y-limits from the excited part, :func:`y_limits`), ``M_fit`` (Figs. 3-4:
  measured and modelled coefficient, residual, its spectrum), ``M_autocorrelation`` (Figs.
  5/11: recursive Eq. 17 and batch Eq. 10, the 2-sigma white-noise bound, the retained lags)
  and ``M_lags`` (Fig. 7: batch corrected standard errors, Eqs. 8-11, against the retained
  lags), from a :class:`.figure_data.FigureData`;
* :func:`figure12`, per model of a campaign: every maneuver's final estimate with its
  conventional and corrected 2-sigma bars, the mean and the observed scatter (and, when given,
  the frequency-domain estimates with their corrected bars and mean).

What a reader sees in each: ``docs/tools.md``, "Figures".
"""

from __future__ import annotations

import gc
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from functools import partial
from pathlib import Path
from typing import TYPE_CHECKING, Any, NamedTuple

import numpy as np

from ..datapath.display import RANGE_PAD, RANGE_QUANTILE, band_limits, parameter_rate, parameter_unit
from ..errors import ConfigError
from ..extras import optional
from ..progress import Progress
from ..schema import check, option
from .figure_data import excitation_start

if TYPE_CHECKING:  # annotations only
    from matplotlib.figure import Figure

    from .figure_data import FigureData, ModelFinal
    from .results import History

__all__ = ["FORMATS", "REPLAY_FIGURES", "DEFAULT_DPI", "FigureOptions", "figure_formats", "parameter_unit",
           "parameter_label", "save", "y_limits", "replay_figures", "figure12"]

FORMATS = ("png", "svg", "pdf")
# A replay's figures per model, ``M_<kind>.<format>`` (replay_figures).
REPLAY_FIGURES = ("estimates", "fit", "autocorrelation", "lags")
DEFAULT_DPI = 150  # half the drawing time of 300 (benchmarks/figure_benchmark.py); --dpi for print
DPI_RANGE = (50, 1200)
# Regressors of Eq. 2 measured in radians: the flow angles, the control surfaces and the
# nondimensional rates (p b/2V, q cbar/2V, r b/2V: an angular rate times a time, in rad).


def figure_formats(text: str | Sequence[str]) -> tuple[str, ...]:
    """``"png,svg"`` (or a sequence of names) as a tuple of formats of :data:`FORMATS`, in the
    order given, each once; :class:`.errors.ConfigError` naming ``--figures`` otherwise."""
    names = [s.strip().lower() for s in (text.split(",") if isinstance(text, str) else text)]
    bad = [s for s in names if s not in FORMATS]
    if bad or not names:
        raise ConfigError(f"--figures: unknown figure format(s) {bad or names}; choose from {', '.join(FORMATS)}")
    return tuple(dict.fromkeys(names))


@dataclass(frozen=True)
class FigureOptions:
    """How figures are written: ``formats`` (of :data:`FORMATS`; PNG is a raster at ``dpi``
    dots per inch, SVG and PDF are vectors). Checked here, once (:class:`.errors.ConfigError`
    naming ``--figures`` or ``--dpi``)."""

    formats: tuple[str, ...] = option(("png",), "figure formats, comma separated, of png, svg, pdf", cli="--figures")
    dpi: int = option(DEFAULT_DPI, "PNG resolution, dots per inch", low=DPI_RANGE[0], high=DPI_RANGE[1], cli="--dpi")

    def __post_init__(self) -> None:
        object.__setattr__(self, "formats", figure_formats(self.formats))
        check(self, "")


def parameter_label(parameter: str) -> str:
    """An axis label: the name and its unit, and for a rate derivative the rate it is per
    (``Cm_q, 1/rad (per q cbar/2V)``)."""
    rate = parameter_rate(parameter)
    unit = parameter_unit(parameter)
    return f"{parameter}, {'dimensionless' if unit == '-' else unit}" + (f" (per {rate})" if rate else "")


def _pyplot() -> Any:
    with optional("figures", what="drawing figures"):
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
    """``fig`` as ``stem.<format>`` for each of ``formats`` (:class:`FigureOptions`), then
    closed."""
    plt = _pyplot()
    options = FigureOptions(tuple(formats), dpi)
    written = []
    try:
        for fmt in options.formats:
            path = stem.with_name(f"{stem.name}.{fmt}")
            with plt.rc_context(_STYLE):  # svg.hashsalt: the same ids in every run
                fig.savefig(path, format=fmt, dpi=options.dpi, metadata=_METADATA[fmt])
            written.append(path)
    finally:
        plt.close(fig)
        # A figure and its canvas (with the rendered pixels) refer to each other: free them now,
        # not at the next collection, so a run holds one figure's pixels at a time.
        gc.collect()
    return written


def _legend(fig: Figure, ax: Any, ncol: int) -> None:
    """The legend of ``ax``'s lines once, below the panels (constrained layout makes room);
    ``ax`` a sequence of axes: each label once, from the first panel that has it."""
    found: dict[str, Any] = {}
    for one in np.ravel(ax) if isinstance(ax, (np.ndarray, list, tuple)) else [ax]:
        for handle, label in zip(*one.get_legend_handles_labels(), strict=True):
            found.setdefault(label, handle)
    fig.legend(list(found.values()), list(found), loc="outside lower center", ncol=ncol, frameon=False)


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
             lags: str = "configured lags", mean: Any = None, scatter: Any = None,
             stem: str | None = None, frequency: tuple[Any, Any] | None = None, frequency_mean: Any = None,
             ) -> list[Path]:
    """The paper's Fig. 12 for one model of a campaign: per parameter (one panel each), every
    maneuver's final estimate with its conventional (Eq. 13) and corrected (Eqs. 20/22)
    2-sigma bars side by side (and corrected with all lags when ``se_corrected_all`` is
    given), the mean over the maneuvers (a line) and the observed scatter (a band of mean
    +/- 2 sample standard deviations), y in the parameter's unit.

    ``model``: the model's output (``"CZ"``), used in the title and the file name
    ``<stem>.<fmt>`` (``stem`` default ``<model>_fig12``); ``maneuvers``: the maneuvers' names (x axis, in this order);
    ``parameters``: the model's parameter names (``CZ_0, CZ_alpha, ...``); ``estimates``,
    ``se_conventional``, ``se_corrected`` and optionally ``se_corrected_all``: arrays
    ``(len(maneuvers), len(parameters))``, NaN where a maneuver has no value (a failed
    maneuver: drawn as a gap and left out of the mean and scatter); ``out_dir``: an existing
    directory; ``formats``: of :data:`FORMATS`; ``dpi``: PNG resolution; ``title``: the
    campaign's name (default: the model's); ``lags``: how the corrected bars' lags are named
    in the legend (``"50 lags"``); ``mean`` and ``scatter``: per parameter, the campaign's
    own (Table 4's), by default computed here over the finite estimates (the mean and the
    sample standard deviation). ``frequency``: the frequency-domain estimates and corrected
    standard errors, ``(estimates, se_corrected)`` of the same shape (NaN for the bias, which
    that method does not estimate), drawn beside the others in their own colour, with their
    mean per parameter ``frequency_mean`` (a dashed line) when given. Returns the files
    written."""
    options = FigureOptions(tuple(formats), dpi)
    est = np.asarray(estimates, dtype=float)
    arrays = {"estimates": est, "se_conventional": se_conventional, "se_corrected": se_corrected,
              "se_corrected_all": se_corrected_all}
    if frequency is not None:
        arrays |= {"frequency estimates": frequency[0], "frequency se_corrected": frequency[1]}
    shape = (len(maneuvers), len(parameters))
    for name, a in arrays.items():
        if a is not None and np.shape(a) != shape:
            raise ValueError(f"figure12: {name} must be (maneuvers, parameters) = {shape}, got {np.shape(a)}")
    bars = [("conventional", est, np.asarray(se_conventional, dtype=float), "tab:red"),
            (f"corrected, {lags}", est, np.asarray(se_corrected, dtype=float), "tab:blue")]
    if se_corrected_all is not None:
        bars.append(("corrected, all lags", est, np.asarray(se_corrected_all, dtype=float), "tab:green"))
    if frequency is not None:
        bars.append(("frequency domain, corrected", np.asarray(frequency[0], dtype=float),
                     np.asarray(frequency[1], dtype=float), "tab:purple"))
    computed = _ensemble(est)
    mean = computed[0] if mean is None else np.asarray(mean, dtype=float).reshape(len(parameters))
    scatter = computed[1] if scatter is None else np.asarray(scatter, dtype=float).reshape(len(parameters))
    f_mean = None if frequency_mean is None else np.asarray(frequency_mean, dtype=float).reshape(len(parameters))
    plt = _pyplot()
    with plt.rc_context(_STYLE):
        fig, axes = plt.subplots(len(parameters), 1, figsize=(7, 1.8 * len(parameters) + 0.6), sharex=True,
                                 squeeze=False, layout="constrained")
        for i, ax in enumerate(axes[:, 0]):
            _fig12_panel(ax, bars, i, mean[i], scatter[i], None if f_mean is None else f_mean[i])
            ax.set_ylabel(parameter_label(parameters[i]))
        _legend(fig, axes[:, 0], 3)
        _fig12_maneuvers(axes[-1, 0], maneuvers, est)
        fig.suptitle(f"{title or model}: {model} final estimates over {len(maneuvers)} maneuvers (Fig. 12)")
    return save(fig, Path(out_dir) / (stem or f"{model}_fig12"), options.formats, options.dpi)


def _fig12_panel(ax: Any, bars: Sequence[tuple[str, np.ndarray, np.ndarray, str]], i: int, mean: float,
                 scatter: float, frequency_mean: float | None) -> None:
    """Parameter ``i``'s panel of Fig. 12: the band, the mean(s) and each kind of bars, side by side."""
    x = np.arange(bars[0][1].shape[0])
    if np.isfinite(scatter):
        ax.axhspan(mean - 2 * scatter, mean + 2 * scatter, color="0.85", lw=0, label="mean +/- 2 scatter")
    if np.isfinite(mean):
        ax.axhline(mean, color="k", lw=0.8, label="mean")
    if frequency_mean is not None and np.isfinite(frequency_mean):
        ax.axhline(frequency_mean, color="tab:purple", lw=0.8, ls="--", label="frequency-domain mean")
    offsets = np.linspace(-0.15, 0.15, len(bars)) if len(bars) <= 3 else np.linspace(-0.24, 0.24, len(bars))
    for (label, est, se, color), dx in zip(bars, offsets, strict=True):
        ax.errorbar(x + dx, est[:, i], yerr=2 * se[:, i], fmt="o", ms=2.5, color=color, elinewidth=1, capsize=2,
                    label=f"2 sigma {label}")


def _fig12_maneuvers(bottom: Any, maneuvers: Sequence[str], est: np.ndarray) -> None:
    """Fig. 12's x axis: the maneuvers' names (or, for many, their index)."""
    x = np.arange(len(maneuvers))
    bottom.set_xlim(-0.6, len(maneuvers) - 0.4)
    bottom.set_xticks(x)
    if len(maneuvers) <= 30:  # a maneuver without any estimate is named as such
        none = ~np.isfinite(est).any(axis=1)
        bottom.set_xticklabels([f"{m} (none)" if n else m for m, n in zip(maneuvers, none, strict=True)],
                               rotation=60, ha="right")
    else:  # too many names to read: the index (the order of the given names)
        bottom.set_xticks(x[:: max(1, len(x) // 20)])
    bottom.set_xlabel("maneuver" if len(maneuvers) <= 30 else "maneuver index")


def y_limits(t: np.ndarray, theta: np.ndarray, se: np.ndarray, start: float, *, quantile: float = RANGE_QUANTILE,
             pad: float = RANGE_PAD) -> tuple[float, float] | None:
    """y-limits of a parameter's history from the excited part of the maneuver: over the
    samples from ``start`` (:func:`.figure_data.excitation_start`), the ``quantile`` and
    ``1 - quantile`` quantiles of ``theta -/+ 2 se`` (so a short transient after the onset
    does not set the scale), widened to hold the final 2-sigma band, then padded by ``pad``
    of the span (:func:`..datapath.display.band_limits`, the rule the page uses too). None when
    fewer than two finite samples lie after ``start``."""
    sel = t >= start
    return band_limits(theta[sel], se[sel], quantile=quantile, pad=pad)


class _Model(NamedTuple):
    """What the figures of one model of a replay draw from."""

    j: int
    name: str
    parameters: tuple[str, ...]
    columns: int  # the model's first column in the estimates' History
    start: float  # s, the excitation onset (figure_data.excitation_start)


def replay_figures(out_dir: str | Path, title: str, history: History, data: FigureData,
                   options: FigureOptions | None = None, *, progress: bool | None = False) -> list[Path]:
    """Every figure of a replay into ``out_dir``, per model that produced an estimate
    (``docs/tools.md``, "Figures"): ``M_estimates`` (Figs. 6/13), ``M_fit`` (Figs. 3-4),
    ``M_autocorrelation`` (Figs. 5/11) and ``M_lags`` (Fig. 7), in each format of
    ``options``. ``history``: the estimates' bounded history; ``data``: the rest
    (:class:`.figure_data.FigureData`, finished); ``title``: the bag's name; ``progress``: a
    bar per figure on stderr (:mod:`..progress`)."""
    options = options or FigureOptions()
    written: list[Path] = []
    if not history.n:
        return written
    t0 = int(history.stamps_ns[0])
    k = 0
    drawn = [j for j in range(len(data.outputs)) if history.ready(j).any()]
    with Progress(len(drawn) * len(REPLAY_FIGURES), "figures", " figures", progress) as bar:
        for j, name in enumerate(data.outputs):
            params = data.parameters[j]
            stamps, _, _ = data.coefficient(j)
            start = excitation_start((stamps - t0) * 1e-9, data.regressor_history(j))
            model = _Model(j, name, params, k, start)
            k += len(params)
            if j not in drawn:
                continue
            drawings: dict[str, Callable[[], Figure | None]] = {
                "estimates": partial(_estimates, title, model, history, data, t0),
                "fit": partial(_fit, title, model, data, t0),
                "autocorrelation": partial(_autocorrelation, title, model, data),
                "lags": partial(_lag_sweep, title, model, data)}
            for kind, draw in drawings.items():  # one figure in memory at a time
                with _pyplot().rc_context(_STYLE):
                    fig = draw()
                if fig is not None:
                    written += save(fig, Path(out_dir) / f"{name}_{kind}", options.formats, options.dpi)
                bar.update()
    return written


def _seconds(stamps: np.ndarray, t0: int) -> np.ndarray:
    return (stamps - t0) * 1e-9


def _estimates(title: str, m: _Model, history: History, data: FigureData, t0: int) -> Figure:
    """Figs. 6/13: each parameter's estimate with corrected and conventional 2-sigma bands,
    the pre-excitation part shaded, the convergence time marked, y from the excited part."""
    plt = _pyplot()
    ready = history.ready(m.j)
    t = _seconds(history.stamps_ns[ready], t0)
    fig, axes = plt.subplots(len(m.parameters), 1, figsize=(7, 1.6 * len(m.parameters) + 0.9), sharex=True,
                             squeeze=False, layout="constrained")
    for i, ax in enumerate(axes[:, 0]):
        theta, se, sc, _ = (c[ready] for c in history.column(m.columns + i))
        ax.fill_between(t, theta - 2 * se, theta + 2 * se, color="tab:blue", alpha=0.25, lw=0,
                        label="2 sigma corrected (Eq. 22)")
        ax.plot(t, theta - 2 * sc, "--", color="tab:red", lw=0.8, label="2 sigma conventional (Eq. 13)")
        ax.plot(t, theta + 2 * sc, "--", color="tab:red", lw=0.8)
        ax.plot(t, theta, "k", label="estimate")
        if t.size and m.start > t[0]:
            ax.axvspan(t[0], m.start, color="0.9", lw=0, zorder=0, label="before excitation")
        since = int(data.converged_since[m.columns + i])
        if since >= 0:
            ax.axvline((since - t0) * 1e-9, color="tab:green", ls=":", lw=1.2,
                       label="converged from (flag stays set)")
        limits = y_limits(t, theta, se, m.start)
        if limits is not None:
            ax.set_ylim(*limits)
        ax.set_ylabel(parameter_label(m.parameters[i]))
    _legend(fig, axes[0, 0], 3)
    axes[-1, 0].set_xlabel("time, s")
    fig.suptitle(f"{title}: {m.name} estimates")
    return fig


def _fit(title: str, m: _Model, data: FigureData, t0: int) -> Figure:
    """Figs. 3-4: measured and modelled coefficient, the residual, its power spectrum."""
    plt = _pyplot()
    stamps, measured, model = data.coefficient(m.j)
    t = _seconds(stamps, t0)
    fig, (a1, a2, a3) = plt.subplots(3, 1, figsize=(7, 6.4), layout="constrained")
    a1.plot(t, measured, color="0.4", label="measured (Eq. 1)")
    a1.plot(t, model, "tab:blue", label="model, x' theta_k (estimate at each sample)")
    a1.set(xlabel="time, s", ylabel=f"{m.name}, dimensionless")
    _legend(fig, a1, 2)
    residual = measured - model
    a2.plot(t, residual, "k", lw=0.8)
    a2.set(xlabel="time, s", ylabel=f"{m.name} residual, dimensionless")
    a2.set_xlim(a1.get_xlim())
    r2 = data.fits[m.j].r_squared
    if np.isfinite(r2):
        a1.set_title(f"R^2 = {r2:.3f} (samples with an estimate)", loc="right")
    f, P = data.spectra[m.j].psd()
    if f.size > 1:
        a3.semilogy(f[1:], P[1:], "k", lw=0.8)
    a3.set(xlabel="frequency, Hz", ylabel="residual PSD, 1/Hz")
    fig.suptitle(f"{title}: {m.name} fit and residual (Figs. 3-4)")
    return fig


def _retained(final: ModelFinal) -> str:
    setting = final.lag_setting
    how = "auto" if setting == "auto" else "all lags" if setting == "all" else f"lags = {setting}"
    return f"retained lags: {final.lags} ({how})"


def _autocorrelation(title: str, m: _Model, data: FigureData) -> Figure | None:
    """Figs. 5/11: the recursive residual autocorrelation (Eq. 17) and the batch one (Eq. 10)
    over R(0), the 2-sigma white-noise bound 2/sqrt(N) and the retained lags."""
    final = data.finals[m.j] if data.finals else None
    if final is None or final.autocorrelation is None:
        return None
    plt = _pyplot()
    R = final.autocorrelation
    fig, ax = plt.subplots(figsize=(7, 3.4), layout="constrained")
    lags = np.arange(R.size)
    ax.plot(lags, R / R[0], "tab:blue", marker=".", ms=3, label="recursive (Eq. 17)")
    sweep = data.products[m.j].sweep()
    if sweep is not None:  # beyond the stored lags too, to show what the truncation drops
        Rb = sweep.autocorrelation[: max(R.size, min(3 * R.size, 200))]
        ax.plot(np.arange(Rb.size), Rb / Rb[0], "--", color="tab:orange", label="batch (Eq. 10)")
    bound = 2 / np.sqrt(final.samples)
    ax.axhspan(-bound, bound, color="0.85", lw=0, label="2 sigma white-noise bound, 2/sqrt(N)")
    ax.axvline(final.lags, color="tab:red", ls=":", lw=1.2, label=_retained(final))
    ax.set(xlabel="lag, samples", ylabel="R(i) / R(0), dimensionless")
    seconds = ax.secondary_xaxis("top", functions=(lambda x: x / data.rate, lambda s: s * data.rate))
    seconds.set_xlabel("lag, s")
    ax.legend(loc="upper right")
    fig.suptitle(f"{title}: {m.name} residual autocorrelation after N = {final.samples} samples (Figs. 5, 11)")
    return fig


def _lag_sweep(title: str, m: _Model, data: FigureData) -> Figure | None:
    """Fig. 7: each parameter's batch corrected standard error (Eqs. 8-11) against the number
    of retained lags, the conventional one (0 lags) and the retained lags marked with the
    recursive estimator's final corrected standard error."""
    sweep = data.products[m.j].sweep()
    final = data.finals[m.j] if data.finals else None
    if sweep is None or final is None:
        return None
    plt = _pyplot()
    L = np.unique(np.round(np.geomspace(1, max(sweep.max_lag, 1), 60)).astype(int))
    se = np.array([sweep.se_corrected(int(lag), final.window) for lag in L])  # (lags, n)
    n = len(m.parameters)
    cols = 2 if n > 2 else 1
    rows = -(-n // cols)
    fig, axes = plt.subplots(rows, cols, figsize=(3.6 * cols, 2.0 * rows + 0.9), squeeze=False, sharex=True,
                             layout="constrained")
    recursive = data.last_se[m.j]
    for i, ax in enumerate(axes.flat):
        if i >= n:
            ax.set_visible(False)
            continue
        ax.semilogx(L, se[:, i], "tab:blue", label="corrected, batch (Eqs. 8-11)")
        ax.axhline(sweep.se_conventional[i], color="tab:red", ls="--", lw=0.8, label="conventional (0 lags, Eq. 13)")
        ax.axvline(max(final.lags, 1), color="k", ls=":", lw=1.0, label=_retained(final))
        if recursive is not None:
            ax.plot([max(final.lags, 1)], [recursive[i]], "o", color="tab:green", ms=4,
                    label="recursive, end of run (Eq. 22)")
        ax.set_title(m.parameters[i], loc="left")
        ax.set_ylabel(f"SE, {parameter_label(m.parameters[i]).split(', ', 1)[1]}")
        ax.set_ylim(bottom=0)
    for ax in axes[-1]:
        ax.set_xlabel("retained lags L, samples")
    _legend(fig, axes[0, 0], 2)
    fig.suptitle(f"{title}: {m.name} standard error against retained lags, N = {sweep.samples} (Fig. 7)")
    return fig
