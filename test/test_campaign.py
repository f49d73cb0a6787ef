"""campaign/__init__.py and ``rls-uncertainty campaign``: a campaign written to --out (the
maneuvers' rows, Table 4 in CSV and Markdown, the summary, Fig. 12 per model), from bags or
from a maneuvers file; a failed maneuver is named and the others still count. No ROS."""

from __future__ import annotations

import csv
import multiprocessing
import os
from pathlib import Path

import numpy as np
import pytest
import yaml
from bag_samples import fails, no_hang

from rls_uncertainty import cli
from rls_uncertainty.campaign import CampaignSettings, campaign_to, load_maneuvers
from rls_uncertainty.campaign.figure import campaign_figures
from rls_uncertainty.executors import LocalProcesses
from rls_uncertainty.settings import node_config, pipeline_config
from rls_uncertainty.testing import parameters, replay_bag

ROOT = Path(__file__).resolve().parents[1]
BUNDLED = ROOT / "bags" / "t2_maneuver"
SPANS = [("a", 0.0, 11.0), ("b", 0.5, 11.5), ("c", 1.0, 11.9)]


@pytest.fixture(scope="module")
def maneuvers_file(tmp_path_factory):
    f = tmp_path_factory.mktemp("m") / "maneuvers.yaml"
    f.write_text(yaml.safe_dump({"maneuvers": [{"name": n, "start": s, "end": e} for n, s, e in SPANS]}))
    return f


def test_the_command_writes_table4_from_the_replays_of_its_maneuvers(tmp_path, maneuvers_file, capsys):
    out = tmp_path / "out"
    assert cli.main(["campaign", str(BUNDLED), "--maneuvers", str(maneuvers_file), "--config", "config/t2.yaml",
                     "--out", str(out), "--workers", "2", "--quiet"]) == 0
    assert sorted(p.name for p in out.iterdir()) == ["fig12_CZ.png", "fig12_Cm.png", "maneuvers.csv", "models.json",
                                                     "summary.txt", "table4.csv", "table4.md"]
    finals = [replay_bag(BUNDLED, "t2", start=s, end=e) for _, s, e in SPANS]
    with open(out / "table4.csv") as fh:
        table = {r["parameter"]: r for r in csv.DictReader(fh)}
    for p in finals[0].parameters:
        est = np.array([f.final(p).estimate for f in finals])
        assert float(table[p]["mean"]) == pytest.approx(est.mean(), rel=1e-14)
        assert float(table[p]["scatter"]) == pytest.approx(est.std(ddof=1), rel=1e-12)
        se = np.mean([f.final(p).std_error for f in finals])
        assert float(table[p]["se_corrected"]) == pytest.approx(se, rel=1e-14)
        assert float(table[p]["corrected_over_scatter"]) == pytest.approx(se / est.std(ddof=1), rel=1e-12)
    printed = capsys.readouterr().out
    assert printed.startswith((out / "summary.txt").read_text()) and "3 maneuvers in" in printed


def test_a_failed_maneuver_is_named_and_the_others_still_count(tmp_path):
    p = parameters("t2")
    settings = CampaignSettings(pipeline_config(p), node_config(p).topics)
    maneuvers = load_maneuvers(_file(tmp_path, [("good", 0.0, 11.0), ("late", 20.0, 30.0), ("good2", 1.0, 11.9)]),
                               BUNDLED)
    c = campaign_to(tmp_path / "out", maneuvers, settings, LocalProcesses(1), figures=None)
    assert [r.maneuvers for r in c.table] == [2] * 7
    rows = list(csv.DictReader((tmp_path / "out" / "maneuvers.csv").read_text().splitlines()))
    late = [r for r in rows if r["maneuver"] == "late"]
    assert len(late) == 7 and all(r["status"].startswith("failed: ") and r["estimate"] == "" for r in late)
    assert "late: failed:" in (tmp_path / "out" / "summary.txt").read_text()
    assert "- late: failed:" in (tmp_path / "out" / "table4.md").read_text()


def _file(tmp_path, spans):
    f = tmp_path / "m.yaml"
    f.write_text(yaml.safe_dump({"maneuvers": [{"name": n, "start": s, "end": e} for n, s, e in spans]}))
    return f


def test_no_maneuver_estimated_is_exit_status_1(tmp_path, capsys):
    f = _file(tmp_path, [("x", 0.0, 0.2), ("y", 0.2, 0.4)])
    assert cli.main(["campaign", str(BUNDLED), "--maneuvers", str(f), "--out", str(tmp_path / "o"), "--quiet",
                     "--workers", "1", "--no-figures"]) == 1
    assert "0 of 2 maneuvers used" in capsys.readouterr().out


@pytest.mark.parametrize(("argv", "needle"), [
    (["--maneuvers", "M"], "--maneuvers cuts one recording into maneuvers; got 2 INPUTs"),
    (["--workers", "2", "--scheduler", "tcp://127.0.0.1:1"], "drop --workers"),
])
def test_misuse_is_one_error_line_before_anything_runs(tmp_path, capsys, argv, needle):
    assert cli.main(["campaign", str(BUNDLED), str(BUNDLED), "--out", str(tmp_path / "o"), *argv]) == 2
    err = capsys.readouterr().err
    assert needle in err and err.count("\n") == 1 and not (tmp_path / "o").exists()


def test_fig12_gets_each_maneuver_s_values_and_table_4_s_mean_and_scatter(tmp_path, monkeypatch):
    """campaign_figures hands figures.figure12 (tested in test_figures.py) every maneuver's
    estimate and three standard errors per parameter, in campaign order, and Table 4's mean and
    scatter, one call per model."""
    from rls_uncertainty.offline import figures
    p = parameters("t2")
    settings = CampaignSettings(pipeline_config(p), node_config(p).topics)
    c = campaign_to(tmp_path / "o", load_maneuvers(_file(tmp_path, SPANS), BUNDLED), settings, LocalProcesses(1),
                    figures=None)
    calls = []
    monkeypatch.setattr(figures, "figure12", lambda *a, **k: calls.append((a, k)) or [])
    campaign_figures(tmp_path, c.table, c.results)
    assert [a[0] for a, _k in calls] == ["CZ", "Cm"]
    for (model, maneuvers, names, est, se_conv, se_corr, _out), kw in calls:
        rows = [r for r in c.table if r.model == model]
        assert list(maneuvers) == [res.name for res in c.results] and list(names) == [r.parameter for r in rows]
        assert kw["mean"] == [r.mean for r in rows] and kw["scatter"] == [r.scatter for r in rows]
        for i, res in enumerate(c.results):
            got = {r.parameter: r for r in res.rows}
            np.testing.assert_array_equal(est[i], [got[n].estimate for n in names])
            np.testing.assert_array_equal(se_conv[i], [got[n].se_conventional for n in names])
            np.testing.assert_array_equal(se_corr[i], [got[n].se_corrected for n in names])
            np.testing.assert_array_equal(kw["se_corrected_all"][i], [got[n].se_corrected_all for n in names])


def test_campaign_writes_fig12_in_every_format_asked_for(tmp_path, maneuvers_file, capsys):
    """--figures png,svg,pdf gives each model's Fig. 12 in the three formats; --dpi bad is one
    line naming it and its range (FigureOptions' declaration), exit 2, nothing written."""
    out = tmp_path / "o"
    argv = ["campaign", str(BUNDLED), "--maneuvers", str(maneuvers_file), "--config", "t2", "--out", str(out),
            "--quiet", "--workers", "1", "--figures", "png,svg,pdf"]
    assert cli.main(argv) == 0
    want = {f"fig12_{m}.{f}" for m in ("CZ", "Cm") for f in ("png", "svg", "pdf")}
    assert {p.name for p in out.glob("fig12_*")} == want
    capsys.readouterr()
    with pytest.raises(SystemExit) as exc:
        cli.main([*argv[:-2], "--out", str(tmp_path / "x"), "--dpi", "5"])
    err = capsys.readouterr().err
    assert exc.value.code == 2 and len(err.splitlines()) == 1 and "--dpi: must be an integer in [50, 1200]" in err
    assert not (tmp_path / "x").exists()


@pytest.mark.parametrize("kind", ["fifo", "loop", "device"])
def test_an_input_that_no_reader_may_open_is_refused_before_any_maneuver_runs(tmp_path, capsys, kind):
    """Beside a good bag, a FIFO named x.mcap, a symbolic link loop or a device: one line, exit 2,
    no worker started (no hang), no output and no unfinished one."""
    bag = {"fifo": tmp_path / "x.mcap", "loop": tmp_path / "loop", "device": Path("/dev/zero")}[kind]
    if kind == "fifo":
        os.mkfifo(bag)
    elif kind == "loop":
        bag.symlink_to(bag)
    problem = {"fifo": "a FIFO, not a regular file or a directory", "loop": "a symbolic link loop",
               "device": "a character device, not a regular file or a directory"}[kind]
    out = tmp_path / "out"
    with no_hang(60):
        fails(capsys, ["campaign", str(BUNDLED), str(bag), "--config", "config/t2.yaml", "--out", str(out),
                       "--workers", "2", "--quiet"], f"{bag}: {problem}")
    assert not out.exists() and not [p for p in tmp_path.iterdir() if p.name.endswith(".partial")]
    assert multiprocessing.active_children() == []
