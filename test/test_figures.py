"""The report figures (rls_uncertainty/offline/figures.py): files in every requested format, units on
every axis, y-limits from the excited part, the convergence time and the retained lags where
the run's own outputs put them, Fig. 7 against the batch formula, Fig. 12 against its inputs.
The figures are read back from the matplotlib objects the module drew (captured as they are
saved). No DDS.

Tolerances: a marker's x is the stamp or lag count itself, compared exactly (times as the
difference of integer nanosecond stamps, once converted to seconds); Fig. 7's curve is the
batch formula evaluated from streamed sums, compared with estimator.batch within 1e-9
relative (why: test_figure_data's module docstring)."""

import csv
import struct
from pathlib import Path

import numpy as np
import pytest

from rls_uncertainty.errors import ConfigError
from rls_uncertainty.estimator.batch import batch_estimate
from rls_uncertainty.offline import figures
from rls_uncertainty.offline.bags import convert, read_inputs
from rls_uncertainty.offline.figures import (
    REPLAY_FIGURES,
    FigureOptions,
    figure12,
    figure_formats,
    parameter_label,
    parameter_unit,
    y_limits,
)
from rls_uncertainty.offline.replay import replay, run_pipeline
from rls_uncertainty.settings import load_parameters_file, pipeline_config

from conftest import FLIGHT_DATA, ROOT

BUNDLED = ROOT / "bags" / "t2_maneuver"
MAPPING = ROOT / "msg_schemas" / "fti_msgs" / "mapping.yaml"
T2_MODELS = (("CZ", ("CZ_0", "CZ_alpha", "CZ_delta_e")), ("Cm", ("Cm_0", "Cm_alpha", "Cm_q", "Cm_delta_e")))
# An axis label is "quantity, unit": the units the figures use.
UNITS = ("s", "Hz", "samples", "dimensionless", "1/rad", "1/Hz")


# Figures read back from their objects need no print resolution: 60 dpi keeps the tests fast.
LOW = FigureOptions(("png",), 60)


def _capturing(monkeypatch) -> dict:
    """Every figure saved from now on, by file stem (``CZ_estimates``), kept after closing."""
    drawn: dict = {}
    save = figures.save

    def keep(fig, stem, formats=("png",), dpi=figures.DEFAULT_DPI):
        drawn[Path(stem).name] = fig
        return save(fig, stem, formats, dpi)

    monkeypatch.setattr(figures, "save", keep)
    return drawn


@pytest.fixture
def capture(monkeypatch):
    return _capturing(monkeypatch)


def _replay(tmp_path, capture, params=None, bag=BUNDLED, options=LOW):
    out = tmp_path / "r"
    result = replay(bag, params or load_parameters_file("t2"), out, progress=False, figures=options)
    return out, result, dict(capture)


@pytest.fixture(scope="module")
def t2(tmp_path_factory):
    """The bundled T-2 maneuver replayed once with its configuration: (out, result, figures)."""
    with pytest.MonkeyPatch.context() as mp:
        drawn = _capturing(mp)
        return _replay(tmp_path_factory.mktemp("t2"), drawn)


def _stamps(text: str) -> int:
    sec, nanosec = text.split(".")
    return int(sec) * 10**9 + int(nanosec)


def _csv_rows(out: Path) -> list[dict[str, str]]:
    with open(out / "estimates.csv") as fh:
        return list(csv.DictReader(fh))


def _first_stamp(out: Path) -> int:
    with open(out / "estimates_wide.csv") as fh:
        return _stamps(fh.readlines()[1].split(",", 1)[0])


def _line(ax, label_start):
    lines = [ln for ln in ax.get_lines() if str(ln.get_label()).startswith(label_start)]
    assert len(lines) == 1, [ln.get_label() for ln in ax.get_lines()]
    return lines[0]


def _assert_png(path: Path, fig, dpi: int) -> None:
    """``path`` is a PNG of ``fig`` at ``dpi``: its pixel size is the figure's size in inches
    times ``dpi`` (to the pixel matplotlib rounds to)."""
    data = path.read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n"
    size = np.array(struct.unpack(">II", data[16:24]))
    assert np.abs(size - fig.get_size_inches() * dpi).max() <= 1, (size, fig.get_size_inches() * dpi)


# ------------------------------------------------------------------ options and units


def test_formats_and_resolution_are_checked_once_naming_the_option():
    assert figure_formats("png, SVG,pdf,png") == ("png", "svg", "pdf")
    assert FigureOptions(("pdf",), 600).formats == ("pdf",)
    for bad in ("gif", "", "png,jpg"):
        with pytest.raises(ConfigError, match="--figures"):
            figure_formats(bad)
    for dpi in (10, 5000, 150.5, True):
        with pytest.raises(ConfigError, match="--dpi"):
            FigureOptions(("png",), dpi)


def test_parameter_units_follow_the_regressor():
    assert [parameter_unit(p) for p in ("CZ_0", "CZ_alpha", "Cm_q", "Cl_p", "CY_beta", "Cn_delta_r", "Cl_delta_a")] \
        == ["-", "1/rad", "1/rad", "1/rad", "1/rad", "1/rad", "1/rad"]
    assert parameter_label("Cm_q") == "Cm_q, 1/rad (per q cbar/2V)"
    assert parameter_label("CZ_0") == "CZ_0, dimensionless"


# ------------------------------------------------------------------ y-limits


def test_the_y_limits_come_from_the_excited_part_not_the_early_transient():
    """Before excitation at 2 s the estimate swings by +/-1000; after it, it settles at -4 with
    a shrinking band, and a 3-sample spike at 5 s. The limits hold the final 2-sigma band,
    leave the transient and the spike out, and make the final band a visible part of the axis."""
    t = np.arange(0.0, 12.0, 0.02)
    theta = -4.0 + 0.3 * np.exp(-(t - 2.0) / 2.0)
    se = 0.1 + 0.4 * np.exp(-(t - 2.0) / 2.0)
    early = t < 2.0
    theta[early] = 1000.0 * np.sin(40 * t[early])
    se[early] = 500.0
    theta[(t >= 5.0) & (t < 5.06)] = 30.0  # a spike: 1% of the excited samples
    lo, hi = y_limits(t, theta, se, 2.0)
    assert lo <= theta[-1] - 2 * se[-1] and hi >= theta[-1] + 2 * se[-1]
    assert -6.0 < lo and hi < -2.0
    assert 4 * se[-1] / (hi - lo) > 0.15  # the final band fills more than 15% of the axis
    # From the first sample instead, the transient would set the scale.
    lo_all, hi_all = y_limits(t, theta, se, t[0])
    assert hi_all - lo_all > 100 * (hi - lo)
    assert y_limits(t, theta, se, 20.0) is None  # nothing after the start


# ------------------------------------------------------------------ the replay's figures


def test_every_requested_format_is_written(tmp_path, capture):
    options = FigureOptions(("png", "svg", "pdf"), 60)
    params = load_parameters_file("t2") | {"models.enabled": ["Cm"]}
    out, _, drawn = _replay(tmp_path, capture, params, options=options)
    stems = {f"Cm_{kind}" for kind in REPLAY_FIGURES}
    assert set(drawn) == stems
    for stem in stems:
        assert (out / f"{stem}.pdf").read_bytes()[:5] == b"%PDF-"
        assert b"<svg" in (out / f"{stem}.svg").read_bytes()[:2000]
        _assert_png(out / f"{stem}.png", drawn[stem], 60)


def test_a_figure_drawn_twice_is_the_same_bytes_in_every_format(tmp_path):
    """No date, version or random id in the files (save's metadata and svg.hashsalt)."""
    est, conv, corr = _campaign()
    names = [f"m{i:02d}" for i in range(14)]
    for run in ("a", "b"):
        (tmp_path / run).mkdir()
        figure12("CZ", names, ["CZ_0", "CZ_alpha", "CZ_delta_e"], est, conv, corr, tmp_path / run,
                 formats=("png", "svg", "pdf"), dpi=60)
    for fmt in ("png", "svg", "pdf"):
        assert (tmp_path / "a" / f"CZ_fig12.{fmt}").read_bytes() == (tmp_path / "b" / f"CZ_fig12.{fmt}").read_bytes()


def test_the_default_is_png_at_the_default_dpi_and_a_summary(tmp_path, capture, capsys):
    from rls_uncertainty import cli
    from rls_uncertainty.offline.figures import DEFAULT_DPI

    out = tmp_path / "r"
    assert cli.main(["replay", str(BUNDLED), "--config", "t2", "--out", str(out), "--quiet", "--models", "CZ"]) == 0
    printed = capsys.readouterr().out
    assert set(capture) == {f"CZ_{kind}" for kind in REPLAY_FIGURES}
    assert {p.suffix for p in out.iterdir() if p.stem in capture} == {".png"}
    assert DEFAULT_DPI == 150
    _assert_png(out / "CZ_fit.png", capture["CZ_fit"], DEFAULT_DPI)
    summary = (out / "summary.txt").read_text()
    assert printed.startswith(summary) and "CZ_alpha" in summary and "591 used" in summary


def test_the_command_line_writes_the_formats_and_resolution_asked(tmp_path, capture):
    from rls_uncertainty import cli

    out = tmp_path / "r"
    assert cli.main(["replay", str(BUNDLED), "--config", "t2", "--out", str(out), "--quiet", "--models", "Cm",
                     "--figures", "svg,png", "--dpi", "72"]) == 0
    assert {p.name for p in out.iterdir() if p.stem in capture} == {
        f"Cm_{kind}.{fmt}" for kind in REPLAY_FIGURES for fmt in ("svg", "png")}
    _assert_png(out / "Cm_lags.png", capture["Cm_lags"], 72)


def test_every_axis_names_its_unit_and_every_title_the_bag_and_model(t2):
    _, _, drawn = t2
    for stem, fig in drawn.items():
        model = stem.split("_")[0]
        assert fig._suptitle is not None
        assert "t2_maneuver" in fig._suptitle.get_text() and f" {model} " in fig._suptitle.get_text()
        axes = [ax for ax in fig.get_axes() if ax.get_visible()]
        xlabels = [ax.get_xlabel() for ax in axes if ax.get_xlabel()]
        assert xlabels, stem
        for label in xlabels + [ax.get_ylabel() for ax in axes if ax.get_ylabel()]:
            unit = label.split(", ", 1)[1].split(" (")[0]
            assert unit in UNITS, (stem, label)
        plotted = [ax for ax in axes if ax.get_lines() and not hasattr(ax, "_functions")]
        assert all(ax.get_ylabel() for ax in plotted), stem


def test_the_convergence_time_is_where_each_flag_stays_set(t2):
    out, _, drawn = t2
    since: dict[str, int | None] = {}
    for row in _csv_rows(out):
        stamp = _stamps(row["time"])
        if row["converged"] == "1":
            since[row["parameter"]] = since.get(row["parameter"]) or stamp
        else:
            since[row["parameter"]] = None
    t0 = _first_stamp(out)
    for model, names in T2_MODELS:
        axes = [ax for ax in drawn[f"{model}_estimates"].get_axes() if ax.get_ylabel()]
        assert [ax.get_ylabel().split(",")[0] for ax in axes] == list(names)
        for name, ax in zip(names, axes, strict=True):
            x = _line(ax, "converged from").get_xdata()
            assert since[name] is not None
            assert list(x) == [(since[name] - t0) * 1e-9] * 2


def _assert_final_bands_shown(result, drawn) -> list:
    """Each parameter's final corrected 2-sigma band lies within its axes and fills more
    than a tenth of them; returns each model's estimate axes."""
    models = []
    for model, names in zip(result.models, result.parameter_names, strict=True):
        axes = [ax for ax in drawn[f"{model}_estimates"].get_axes() if ax.get_ylabel()]
        for name, ax in zip(names, axes, strict=True):
            final = result.final(name)
            lo, hi = ax.get_ylim()
            assert lo <= final.estimate - 2 * final.std_error and final.estimate + 2 * final.std_error <= hi
            assert 4 * final.std_error / (hi - lo) > 0.1, name
        models.append(axes)
    return models


def test_the_estimates_axes_show_the_final_bands(t2):
    _, result, drawn = t2
    _assert_final_bands_shown(result, drawn)


@pytest.mark.parametrize("lags", [50, "auto"])
def test_the_retained_lags_and_the_white_noise_bound_are_marked(tmp_path, capture, lags):
    params = load_parameters_file("t2")
    if lags == "auto":
        params |= {"estimator.lag_selection": "auto"}
    out, result, drawn = _replay(tmp_path, capture, params)
    last = {}
    for row in _csv_rows(out):
        last[row["model"]] = int(row["lags"])
    if lags == "auto":
        assert last["CZ"] != 50 or last["Cm"] != 50
    for model in ("CZ", "Cm"):
        ax = drawn[f"{model}_autocorrelation"].get_axes()[0]
        assert list(_line(ax, "retained lags").get_xdata()) == [last[model]] * 2
        (band,) = [p for p in ax.patches if str(p.get_label()).startswith("2 sigma white-noise")]
        y = band.get_patch_transform().transform(band.get_path().vertices)[:, 1]
        n = result.counters()["samples_used"]
        assert (y.min(), y.max()) == pytest.approx((-2 / np.sqrt(n), 2 / np.sqrt(n)), rel=1e-12)
        for ax in drawn[f"{model}_lags"].get_axes():
            if ax.get_visible():
                assert list(_line(ax, "retained lags").get_xdata()) == [max(last[model], 1)] * 2


def test_fig7_is_the_batch_formula_at_every_plotted_lag(t2):
    _, result, drawn = t2
    params = load_parameters_file("t2")
    recorded = run_pipeline(read_inputs(BUNDLED)[0], pipeline_config(params), record=True)
    rows = recorded.pipeline.regression
    for j, (model, names) in enumerate(T2_MODELS):
        n = len(names)
        X = np.array([r[1][j, :n] for r in rows])
        z = np.array([r[2][j] for r in rows])
        axes = [ax for ax in drawn[f"{model}_lags"].get_axes() if ax.get_visible()]
        assert [ax.get_title(loc="left") for ax in axes] == list(names)
        curve = _line(axes[0], "corrected, batch")
        L = np.asarray(curve.get_xdata())
        assert L[0] == 1 and L[-1] == len(rows) - 1  # from 1 lag to all of them
        batch = {int(lag): batch_estimate(X, z, int(lag)) for lag in L}
        for i, (name, ax) in enumerate(zip(names, axes, strict=True)):
            se = np.array([np.sqrt(batch[int(lag)][2][i, i]) for lag in L])
            np.testing.assert_allclose(_line(ax, "corrected, batch").get_ydata(), se, rtol=1e-9)
            conventional = np.sqrt(batch[1][1][i, i])
            np.testing.assert_allclose(_line(ax, "conventional").get_ydata(), [conventional] * 2, rtol=1e-9)
            assert list(_line(ax, "recursive, end of run").get_ydata()) == [result.final(name).std_error]


@pytest.fixture(scope="module")
def twin_otter_bag(tmp_path_factory):
    bag = tmp_path_factory.mktemp("flight") / "f1_017"
    convert(FLIGHT_DATA / "totter_f1_017", MAPPING, bag)
    return bag


def test_the_twin_otter_final_bands_are_visible(tmp_path, capture, twin_otter_bag):
    """The lateral maneuver's aileron starts at about 8.5 s: before it, the Cl estimates swing
    over many times their final band; the axes are set from the excited part."""
    _, result, drawn = _replay(tmp_path, capture, load_parameters_file("twin_otter_lateral"), twin_otter_bag)
    axes = dict(zip(result.models, _assert_final_bands_shown(result, drawn), strict=True))
    (shaded,) = [p for p in axes["Cl"][0].patches if p.get_label() == "before excitation"]
    x = shaded.get_patch_transform().transform(shaded.get_path().vertices)[:, 0]
    assert 8.0 < x.max() < 9.0  # the aileron's first input


# ------------------------------------------------------------------ Fig. 12


def _campaign(seed=4, maneuvers=14):
    rng = np.random.default_rng(seed)
    est = np.array([-0.3, -4.0, -0.5]) + rng.normal(0, [0.01, 0.1, 0.02], (maneuvers, 3))
    conv = np.tile([0.003, 0.03, 0.006], (maneuvers, 1))
    return est, conv, 3 * conv


def test_figure12_draws_every_maneuver_the_mean_and_the_scatter(tmp_path, capture):
    est, conv, corr = _campaign()
    est[3] = np.nan  # a failed maneuver
    names = [f"m{i:02d}" for i in range(14)]
    written = figure12("CZ", names, ["CZ_0", "CZ_alpha", "CZ_delta_e"], est, conv, corr, tmp_path,
                       se_corrected_all=1.1 * corr, formats=("png", "pdf"), dpi=80, title="sim", lags="50 lags")
    assert written == [tmp_path / "CZ_fig12.png", tmp_path / "CZ_fig12.pdf"]
    assert all(p.stat().st_size > 0 for p in written)
    fig = capture["CZ_fig12"]
    axes = fig.get_axes()
    assert [ax.get_ylabel() for ax in axes] == ["CZ_0, dimensionless", "CZ_alpha, 1/rad", "CZ_delta_e, 1/rad"]
    assert [t.get_text() for t in axes[-1].get_xticklabels()][3] == "m03 (none)"
    for i, ax in enumerate(axes):
        ok = np.isfinite(est[:, i])
        mean, scatter = est[ok, i].mean(), est[ok, i].std(ddof=1)
        assert list(_line(ax, "mean").get_ydata()) == pytest.approx([mean, mean], rel=1e-14)
        (band,) = [p for p in ax.patches if p.get_label().startswith("mean +/- 2 scatter")]
        y = band.get_patch_transform().transform(band.get_path().vertices)[:, 1]
        assert (y.min(), y.max()) == pytest.approx((mean - 2 * scatter, mean + 2 * scatter), rel=1e-12)
        bars = {c.get_label(): c for c in ax.containers}
        assert set(bars) == {"2 sigma conventional", "2 sigma corrected, 50 lags", "2 sigma corrected, all lags"}
        for label, se in (("2 sigma conventional", conv), ("2 sigma corrected, 50 lags", corr),
                          ("2 sigma corrected, all lags", 1.1 * corr)):
            line, _caps, (segments,) = bars[label].lines
            np.testing.assert_array_equal(line.get_ydata(), est[:, i])
            spans = np.array([s[1, 1] - s[0, 1] for s in segments.get_segments() if len(s)])  # NaN: no bar
            np.testing.assert_allclose(spans, 4 * se[ok, i], rtol=1e-12)


def test_figure12_draws_the_mean_and_scatter_it_is_given(tmp_path, capture):
    est, conv, corr = _campaign()
    figure12("CZ", [f"m{i}" for i in range(14)], ["CZ_0", "CZ_alpha", "CZ_delta_e"], est, conv, corr, tmp_path,
             mean=[1.0, 2.0, 3.0], scatter=[0.5, 0.0, 0.25], stem="fig12_CZ", dpi=60)
    assert (tmp_path / "fig12_CZ.png").is_file()
    for ax, mean, scatter in zip(capture["fig12_CZ"].get_axes(), (1.0, 2.0, 3.0), (0.5, 0.0, 0.25), strict=True):
        assert list(_line(ax, "mean").get_ydata()) == [mean, mean]
        (band,) = [p for p in ax.patches if p.get_label().startswith("mean +/- 2 scatter")]
        y = band.get_patch_transform().transform(band.get_path().vertices)[:, 1]
        assert (y.min(), y.max()) == pytest.approx((mean - 2 * scatter, mean + 2 * scatter))


def test_figure12_draws_the_frequency_domain_estimates_beside_the_others(tmp_path, capture):
    """frequency=(estimates, se_corrected): a fourth set of bars, in its own colour and legend
    entry, at the frequency-domain estimates with 2-sigma half-lengths, offset from the
    time-domain ones; its mean a dashed line; no bar for the bias (NaN), which still leaves the
    legend complete (taken over every panel)."""
    est, conv, corr = _campaign()
    rng = np.random.default_rng(9)
    f_est = est + rng.normal(0, 0.01, est.shape)
    f_se = 2.5 * conv
    f_est[:, 0] = f_se[:, 0] = np.nan  # the bias: not estimated in the frequency domain
    f_mean = [np.nan, 2.0, 3.0]
    figure12("CZ", [f"m{i}" for i in range(14)], ["CZ_0", "CZ_alpha", "CZ_delta_e"], est, conv, corr, tmp_path,
             se_corrected_all=corr, dpi=60, lags="50 lags", frequency=(f_est, f_se), frequency_mean=f_mean)
    fig = capture["CZ_fig12"]
    axes = fig.get_axes()
    for i, ax in enumerate(axes):
        bars = {c.get_label(): c for c in ax.containers}
        assert len(bars) == 4
        line, _caps, (segments,) = bars["2 sigma frequency domain, corrected"].lines
        np.testing.assert_array_equal(line.get_ydata(), f_est[:, i])
        assert line.get_color() == "tab:purple"
        time_x = bars["2 sigma conventional"].lines[0].get_xdata()
        assert len(set(np.round(line.get_xdata() - time_x, 12))) == 1 and (line.get_xdata() > time_x).all()
        spans = np.array([s[1, 1] - s[0, 1] for s in segments.get_segments() if len(s)])
        if i == 0:
            assert spans.size == 0 and not [ln for ln in ax.get_lines() if ln.get_label() == "frequency-domain mean"]
            continue
        np.testing.assert_allclose(spans, 4 * f_se[:, i], rtol=1e-12)
        assert list(_line(ax, "frequency-domain mean").get_ydata()) == [f_mean[i], f_mean[i]]
    (legend,) = fig.legends
    labels = [t.get_text() for t in legend.get_texts()]
    assert "frequency-domain mean" in labels and "2 sigma frequency domain, corrected" in labels
    with pytest.raises(ValueError, match="frequency estimates must be"):
        figure12("CZ", [f"m{i}" for i in range(14)], ["CZ_0", "CZ_alpha", "CZ_delta_e"], est, conv, corr, tmp_path,
                 frequency=(f_est[:3], f_se))


def test_figure12_refuses_arrays_of_the_wrong_shape_and_unknown_formats(tmp_path):
    est, conv, corr = _campaign()
    with pytest.raises(ValueError, match="se_corrected must be"):
        figure12("CZ", [f"m{i}" for i in range(14)], ["CZ_0", "CZ_alpha", "CZ_delta_e"], est, conv, corr[:5], tmp_path)
    with pytest.raises(ConfigError, match="--figures"):
        figure12("CZ", [f"m{i}" for i in range(14)], ["CZ_0", "CZ_alpha", "CZ_delta_e"], est, conv, corr, tmp_path,
                 formats=("gif",))
    assert list(tmp_path.iterdir()) == []
