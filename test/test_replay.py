"""The offline replay (rls_uncertainty/replay.py): outputs, determinism, agreement with the
pipeline, options, and no partial output on failure. No DDS."""

import csv
from pathlib import Path

import numpy as np
from bag_samples import fails, read_all

from rls_uncertainty import cli
from rls_uncertainty.bags import read_inputs
from rls_uncertainty.config import load_parameters_file, pipeline_config
from rls_uncertainty.replay import replay, run_pipeline

ROOT = Path(__file__).resolve().parents[1]
BUNDLED = ROOT / "bags" / "t2_maneuver"


def test_replay_writes_identical_outputs_twice_and_matches_the_pipeline(tmp_path):
    params = load_parameters_file("t2")
    r1 = replay(BUNDLED, params, tmp_path / "r1", progress=False)
    replay(BUNDLED, params, tmp_path / "r2", progress=False, plots=False)
    for name in ("estimates.csv", "estimates.mcap"):
        assert (tmp_path / "r1" / name).read_bytes() == (tmp_path / "r2" / name).read_bytes()
    assert {p.name for p in (tmp_path / "r1").glob("*.png")} == {
        "CZ_estimates.png", "Cm_estimates.png", "CZ_autocorrelation.png", "Cm_autocorrelation.png"}
    with open(tmp_path / "r1" / "estimates.csv") as fh:
        rows = list(csv.DictReader(fh))
    assert list(rows[0]) == ["time", "model", "parameter", "estimate", "std_error", "std_error_conventional"]
    # One row per sample and parameter of every ready model.
    n_rows = sum(int(sum(n for n, r in zip(r1.pipeline.sizes, o.ready) if r)) for o in r1.outputs)
    assert len(rows) == n_rows
    # The CSV's last values are the pipeline's, fed message by message independently here.
    messages, _ = read_inputs(BUNDLED)
    again = run_pipeline(messages, pipeline_config(params))
    last = again.outputs[-1]
    final = {r["parameter"]: r for r in rows if float(r["time"]) == last.stamp_ns * 1e-9}
    for j, names in enumerate(again.pipeline.parameter_names):
        for i, name in enumerate(names):
            assert float(final[name]["estimate"]) == last.theta[j, i]
            assert float(final[name]["std_error"]) == last.se[j, i]
            assert float(final[name]["std_error_conventional"]) == last.se_conventional[j, i]
    topics = read_all(tmp_path / "r1" / "estimates.mcap")
    est = topics["/rls_estimator/CZ/estimates"]
    assert est[-1][1].layout.dim[0].label == "CZ_0,CZ_alpha,CZ_delta_e"
    from rls_uncertainty.messages import parse_stamp_label

    for t, msg in est:  # every array carries its sample time; log time is the same
        assert parse_stamp_label(msg.layout.dim[1].label) == t
    assert list(est[-1][1].data) == list(last.theta[0, :3])
    assert len(topics["/rls_estimator/sample_stamp"]) == len(again.outputs)


def test_replay_options_select_span_models_and_lags(tmp_path):
    code = cli.main(["replay", str(BUNDLED), "--config", "t2", "--out", str(tmp_path / "o"), "--models", "CZ",
                     "--lags", "all", "--start", "1.0", "--end", "9.0", "--no-plots", "--quiet"])
    assert code == 0
    with open(tmp_path / "o" / "estimates.csv") as fh:
        rows = list(csv.DictReader(fh))
    assert {r["model"] for r in rows} == {"CZ"}
    t = np.array([float(r["time"]) for r in rows])
    t0 = 1_767_225_600
    assert t.min() >= t0 + 1.0 and t.max() <= t0 + 9.0


def test_no_partial_output_when_the_replay_fails(tmp_path, capsys):
    out = tmp_path / "out"
    fails(capsys, ["replay", str(tmp_path / "missing"), "--out", str(out), "--quiet"], "missing", "no such bag")
    assert not out.exists()


def test_the_printed_summary_is_the_last_sample_of_every_ready_model(tmp_path, capsys):
    assert cli.main(["replay", str(BUNDLED), "--config", "t2", "--out", str(tmp_path / "o"), "--no-plots",
                     "--quiet"]) == 0
    out = capsys.readouterr().out.splitlines()
    assert out[0].split() == ["parameter", "estimate", "SE", "conv.", "SE", "corr.", "corr/conv"]
    assert set(out[1]) == {"-"}
    params = load_parameters_file("t2")
    again = run_pipeline(read_inputs(BUNDLED)[0], pipeline_config(params))
    last = again.outputs[-1]
    expected = [(name, last.theta[j, i], last.se_conventional[j, i], last.se[j, i])
                for j, names in enumerate(again.pipeline.parameter_names) for i, name in enumerate(names)]
    rows = [line.split() for line in out[2:2 + len(expected)]]
    assert [r[0] for r in rows] == [e[0] for e in expected] == [
        "CZ_0", "CZ_alpha", "CZ_delta_e", "Cm_0", "Cm_alpha", "Cm_q", "Cm_delta_e"]
    for row, (_name, est, se_conv, se_corr) in zip(rows, expected):
        # Four decimals: these standard errors are all above 0.001.
        assert row[1:] == [f"{est:.4f}", f"{se_conv:.4f}", f"{se_corr:.4f}", f"{se_corr / se_conv:.2f}"]
    assert out[2 + len(expected)] == ""
