"""The offline replay (rls_uncertainty/offline/replay.py): outputs, determinism, agreement with the
pipeline, options, and no partial output on failure. No DDS."""

import csv
import os
import shutil
from itertools import pairwise
from pathlib import Path

import numpy as np
import pytest
from bag_samples import fails, no_hang, read_all

from rls_uncertainty import cli
from rls_uncertainty.offline.bags import read_inputs
from rls_uncertainty.offline.figures import REPLAY_FIGURES
from rls_uncertainty.offline.replay import replay, run_pipeline
from rls_uncertainty.settings import load_parameters_file, pipeline_config

ROOT = Path(__file__).resolve().parents[1]
BUNDLED = ROOT / "bags" / "t2_maneuver"


def test_replay_writes_identical_outputs_twice_and_matches_the_pipeline(tmp_path):
    params = load_parameters_file("t2")
    r1 = replay(BUNDLED, params, tmp_path / "r1", progress=False)
    replay(BUNDLED, params, tmp_path / "r2", progress=False, plots=False)
    for name in ("estimates.csv", "estimates.mcap"):
        assert (tmp_path / "r1" / name).read_bytes() == (tmp_path / "r2" / name).read_bytes()
    assert {p.name for p in (tmp_path / "r1").glob("*.png")} == {
        f"{m}_{kind}.png" for m in ("CZ", "Cm") for kind in REPLAY_FIGURES}
    with open(tmp_path / "r1" / "estimates.csv") as fh:
        rows = list(csv.DictReader(fh))
    assert list(rows[0]) == ["time", "model", "parameter", "estimate", "std_error", "std_error_conventional",
                             "converged", "lags"]
    # The CSV's values are the pipeline's, fed message by message from a list here.
    messages, _ = read_inputs(BUNDLED)
    again = run_pipeline(messages, pipeline_config(params))
    last = again.outputs[-1]
    # One row per sample and parameter of every ready model.
    n_rows = sum(int(sum(n for n, r in zip(r1.pipeline.sizes, o.ready, strict=True) if r)) for o in again.outputs)
    assert len(rows) == n_rows
    assert r1.estimates == again.estimates and r1.last_output.stamp_ns == last.stamp_ns
    final = {r["parameter"]: r for r in rows if float(r["time"]) == last.stamp_ns * 1e-9}
    for j, names in enumerate(again.pipeline.parameter_names):
        for i, name in enumerate(names):
            assert float(final[name]["estimate"]) == last.theta[j, i]
            assert float(final[name]["std_error"]) == last.se[j, i]
            assert float(final[name]["std_error_conventional"]) == last.se_conventional[j, i]
            assert int(final[name]["converged"]) == int(last.converged[j, i])
            assert int(final[name]["lags"]) == int(last.lags[j]) == again.pipeline.bank.lags_used[j]
    # The bundled maneuver converges: the flags in the CSV switch on for every parameter.
    assert {r["parameter"] for r in rows if r["converged"] == "1"} == {r["parameter"] for r in rows}
    topics = read_all(tmp_path / "r1" / "estimates.mcap")
    est = topics["/rls_estimator/CZ/estimates"]
    assert est[-1][1].layout.dim[0].label == "CZ_0,CZ_alpha,CZ_delta_e"
    from rls_uncertainty.datapath.outputs import parse_stamp_label

    for t, msg in est:  # every array carries its sample time; log time is the same
        assert parse_stamp_label(msg.layout.dim[1].label) == t
    assert list(est[-1][1].data) == list(last.theta[0, :3])
    assert len(topics["/rls_estimator/sample_stamp"]) == len(again.outputs)


def test_replay_options_select_span_models_and_lags(tmp_path):
    code = cli.main(["replay", str(BUNDLED), "--config", "t2", "--out", str(tmp_path / "o"), "--models", "CZ",
                     "--lag-span", "all", "--start", "1.0", "--end", "9.0", "--no-figures", "--quiet"])
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


def _not_a_bag(tmp_path, kind):
    """An input no reader may open: a FIFO named x.mcap, a symbolic link loop, a device, a bag
    directory whose MCAP file is a FIFO."""
    if kind == "fifo":
        os.mkfifo(tmp_path / "x.mcap")
        return tmp_path / "x.mcap", "a FIFO, not a regular file or a directory"
    if kind == "loop":
        (tmp_path / "loop").symlink_to(tmp_path / "loop")
        return tmp_path / "loop", "a symbolic link loop"
    if kind == "device":
        return Path("/dev/zero"), "a character device, not a regular file or a directory"
    bag = tmp_path / "bag"
    shutil.copytree(BUNDLED, bag)
    mcap = next(bag.glob("*.mcap"))
    mcap.unlink()
    os.mkfifo(mcap)
    return bag, f"{mcap}: a FIFO, not a regular file"


@pytest.mark.parametrize("kind", ["fifo", "loop", "device", "fifo_in_bag"])
def test_an_input_that_no_reader_may_open_is_refused_at_once_in_one_line(tmp_path, capsys, kind):
    bag, problem = _not_a_bag(tmp_path, kind)
    out = tmp_path / "out"
    with no_hang(60):  # a reader that opened the FIFO would block here
        fails(capsys, ["replay", str(bag), "--config", "t2", "--out", str(out), "--quiet"], problem)
    assert not out.exists() and not [p for p in tmp_path.iterdir() if p.name.endswith(".partial")]


def test_the_printed_summary_is_the_last_sample_of_every_ready_model(tmp_path, capsys):
    assert cli.main(["replay", str(BUNDLED), "--config", "t2", "--out", str(tmp_path / "o"), "--no-figures",
                     "--quiet"]) == 0
    out = capsys.readouterr().out.splitlines()
    assert out[0].split() == ["parameter", "estimate", "SE", "conv.", "SE", "corr.", "corr/conv", "SE", "%", "state"]
    assert set(out[1]) == {"-"}
    params = load_parameters_file("t2")
    again = run_pipeline(read_inputs(BUNDLED)[0], pipeline_config(params))
    last = again.outputs[-1]
    expected = [(name, last.theta[j, i], last.se_conventional[j, i], last.se[j, i])
                for j, names in enumerate(again.pipeline.parameter_names) for i, name in enumerate(names)]
    rows = [line.split() for line in out[2:2 + len(expected)]]
    assert [r[0] for r in rows] == [e[0] for e in expected] == [
        "CZ_0", "CZ_alpha", "CZ_delta_e", "Cm_0", "Cm_alpha", "Cm_q", "Cm_delta_e"]
    flags = {name: last.converged[j, i] for j, names in enumerate(again.pipeline.parameter_names)
             for i, name in enumerate(names)}
    for row, (name, est, se_conv, se_corr) in zip(rows, expected, strict=True):
        # Four decimals: these standard errors are all above 0.001; the percent error; the state.
        assert row[1:] == [f"{est:.4f}", f"{se_conv:.4f}", f"{se_corr:.4f}", f"{se_corr / se_conv:.2f}",
                           f"{100 * se_corr / abs(est):.1f}", "converged" if flags[name] else "settling"]
    assert all(flags.values())  # the bundled maneuver converges every parameter
    assert out[2 + len(expected)] == ""


# ------------------------------------------------------------------ outputs a plotting tool can name
def test_the_wide_csv_holds_the_long_csv_one_row_per_sample(tmp_path):
    """estimates_wide.csv: a header row, a numeric time column, one column per parameter and
    quantity, comma separated, empty cells while a model is not ready: what PlotJuggler's CSV
    loader reads (it skips empty cells); every number equals estimates.csv's."""
    replay(BUNDLED, load_parameters_file("t2"), tmp_path / "r", progress=False, plots=False)
    result = run_pipeline(read_inputs(BUNDLED)[0], pipeline_config(load_parameters_file("t2")))
    lines = (tmp_path / "r" / "estimates_wide.csv").read_text().splitlines()
    header = lines[0].split(",")
    quantities = ("", "_se", "_se_conventional", "_converged")
    assert header == ["time"] + [f"{p}{q}" for names, model in zip(result.pipeline.parameter_names, ("CZ", "Cm"),
                                                                    strict=True)
                                  for p in [*names, model] for q in (quantities if p != model else ("_lags",))]
    assert len(header) == len(set(header))
    rows = [line.split(",") for line in lines[1:]]
    assert len(rows) == len(result.outputs)
    assert all(len(r) == len(header) for r in rows)
    times = [float(r[0]) for r in rows]  # numeric, increasing
    assert all(b > a for a, b in pairwise(times))
    wide = {(r[0], col): cell for r in rows for col, cell in zip(header[1:], r[1:], strict=True)}
    with open(tmp_path / "r" / "estimates.csv") as fh:
        long = list(csv.DictReader(fh))
    seen = set()
    for r in long:
        for q, field in (("", "estimate"), ("_se", "std_error"), ("_se_conventional", "std_error_conventional")):
            key = (r["time"], r["parameter"] + q)
            assert wide[key] == r[field]
            seen.add(key)
        key = (r["time"], r["parameter"] + "_converged")
        assert float(wide[key]) == int(r["converged"])
        assert int(wide[(r["time"], r["model"] + "_lags")]) == int(r["lags"])
        seen |= {key, (r["time"], r["model"] + "_lags")}
    # Every other cell is empty: exactly the samples where the model was not ready.
    assert all(cell == "" for key, cell in wide.items() if key not in seen)
    assert sum(cell == "" for cell in wide.values()) > 0
    for out, r in zip(result.outputs, rows, strict=True):
        for j, cols in enumerate(result.pipeline.parameter_names):
            cells = [dict(zip(header, r, strict=True))[c] for c in cols]
            assert all(c != "" for c in cells) if out.ready[j] else all(c == "" for c in cells)


def test_the_replays_mcap_carries_every_topic_the_node_publishes_byte_for_byte(tmp_path):
    from rls_uncertainty.datapath.outputs import OutputLayout, fit_topics, output_topics

    params = load_parameters_file("t2")
    replay(BUNDLED, params, tmp_path / "r", progress=False, plots=False)
    result = run_pipeline(read_inputs(BUNDLED)[0], pipeline_config(params))
    from mcap.reader import make_reader

    with open(tmp_path / "r" / "estimates.mcap", "rb") as fh:
        reader = make_reader(fh)
        got = [(ch.topic, sch.name, msg.log_time, msg.data)
               for sch, ch, msg in reader.iter_messages(log_time_order=False)]
    want_topics = {(f"/rls_estimator/{t}", m) for t, m in output_topics(["CZ", "Cm"]) + fit_topics(["CZ", "Cm"])}
    want_topics.add(("/diagnostics", "diagnostic_msgs/msg/DiagnosticArray"))
    assert {(t, s) for t, s, _, _ in got} == want_topics
    layout = OutputLayout.of(result.pipeline)
    expected = [(f"/rls_estimator/{layout.topics[i][0]}", layout.topics[i][1], out.stamp_ns, data)
                for out in result.outputs for i, data in layout.encode(out, "base_link")]
    key = lambda r: (r[2], r[0])  # noqa: E731 - the bag is ordered by log time, then topic rank
    per_sample = [r for r in got if r[0] != "/diagnostics" and not r[0].endswith(("/fit", "/identifiability"))]
    assert sorted(per_sample) == sorted(expected)
    assert sorted(per_sample, key=key) == sorted(expected, key=key)
    # ~/M/fit and ~/M/identifiability once per model at every /diagnostics time (its period of data time)
    # from the model's first published estimates on.
    diagnostics = sorted(r[2] for r in got if r[0] == "/diagnostics")
    for topic, _ in fit_topics(["CZ", "Cm"]):
        model = topic.split("/")[0]
        first = min(r[2] for r in per_sample if r[0] == f"/rls_estimator/{model}/estimates")
        times = sorted(r[2] for r in got if r[0] == f"/rls_estimator/{topic}")
        assert times == [d for d in diagnostics if d >= first] and len(times) >= 9, topic


def test_the_replays_diagnostics_report_lags_and_flags_once_per_period_of_data_time(tmp_path):
    """/diagnostics in estimates.mcap: one array per diagnostics_period (1 s) of data time plus
    one at the end, from the node's own policy; each model's status carries the lag count and
    convergence flags of the newest sample produced before it (auto lags, so the count moves)."""
    params = {**load_parameters_file("t2"), "estimator.lag_selection": "auto"}
    replay(BUNDLED, params, tmp_path / "r", progress=False, plots=False)
    topics = read_all(tmp_path / "r" / "estimates.mcap")
    diag = topics["/diagnostics"]
    messages, _ = read_inputs(BUNDLED)
    span = (max(s for _, s, _ in messages) - messages[0][1]) * 1e-9
    assert int(span) <= len(diag) <= int(span) + 1
    assert [t for t, _ in diag] == sorted(t for t, _ in diag)
    # Independently: feed the messages one by one; whenever the newest stamp is a period past
    # the previous report, the newest sample so far is what the report must show.
    from rls_uncertainty.datapath.inputs import feed
    from rls_uncertainty.datapath.pipeline import Pipeline

    pipe = Pipeline(pipeline_config(params))
    newest, due, previous, expected = None, None, None, []
    for kind, stamp, msg in messages:
        newest = (feed(pipe, kind, msg) or [newest])[-1]
        due = stamp if due is None else max(due, stamp)
        if previous is None:
            previous = stamp
        elif due - previous >= 10**9:
            expected.append((due, newest))
            previous = due
    assert [t for t, _ in diag[:-1]] == [t for t, _ in expected]
    checked = set()
    for (_t, msg), (_, out) in zip(diag, expected, strict=False):
        for status in msg.status:
            values = {kv.key: kv.value for kv in status.values}
            model = status.name.split()[-1]  # "rls_estimator: model CZ"
            j = ("CZ", "Cm").index(model) if model in ("CZ", "Cm") else None
            if j is None or out is None or not out.ready[j]:
                continue
            assert int(values["lags"]) == int(out.lags[j])
            names = pipe.parameter_names[j]
            flagged = {p for p, f in zip(names, out.converged[j], strict=False) if f}
            assert set(filter(None, values["converged_parameters"].split(","))) == flagged
            checked.add((model, values["lags"], values["converged"]))
    # auto lags vary, and both the flag states were seen.
    assert {m for m, _, _ in checked} == {"CZ", "Cm"}
    assert len({lags for _, lags, _ in checked}) > 2
    assert {c for _, _, c in checked} == {"True", "False"}


def test_the_progress_bar_is_drawn_on_a_terminal_or_when_asked(monkeypatch, capsys):
    """progress=None (the command's default): a bar on a terminal only, none into a log file or
    a pipe; True (--progress): always; False (--quiet): never. Never on stdout."""
    import io
    import sys

    messages, _ = read_inputs(BUNDLED)
    config = pipeline_config(load_parameters_file("t2"))

    class Terminal(io.StringIO):
        def isatty(self):
            return True

    def frames(stream, progress):
        monkeypatch.setattr(sys, "stderr", stream)
        run_pipeline(messages, config, progress=progress)
        monkeypatch.undo()
        return stream.getvalue()

    assert frames(io.StringIO(), None) == ""  # a log file or pipe gets no carriage-return frames
    assert frames(Terminal(), False) == ""
    for drawn in (frames(Terminal(), None), frames(io.StringIO(), True)):
        last = drawn.rstrip("\n").split("\r")[-1]
        assert drawn.endswith("\n") and f"{len(messages)}/{len(messages)}" in last and "messages/s" in last, drawn
        assert last.startswith("replay: 100%")
    assert capsys.readouterr().out == ""


def test_the_replays_diagnostics_never_divide_by_zero_elapsed_time():
    """Messages whose stamps do not advance the data time after the last report (older
    stamps at the end of a bag) get no report over zero elapsed time: every input rate in
    every report is that of the data, never a count divided by a vanishing period."""
    from rls_uncertainty.settings import node_config

    params = load_parameters_file("t2")
    messages, _ = read_inputs(BUNDLED)
    # Cut the bag at the message where the last 1 s report falls due (the same rule, written
    # out here), then replay the first second's messages again: older stamps, no data time.
    newest, previous, cut = None, None, 0
    for i, (_kind, stamp, _msg) in enumerate(messages):
        newest = stamp if newest is None else max(newest, stamp)
        if previous is None:
            previous = stamp
        elif newest - previous >= 10**9:
            previous, cut = newest, i
    head = messages[: cut + 1]
    tail = [m for m in messages if m[1] <= messages[0][1] + 10**9]
    result = run_pipeline([*head, *tail], pipeline_config(params), diagnostics=node_config(params))
    assert result.diagnostics[-1][0] == max(stamp for _, stamp, _ in head)
    rates = [float(v) for _, statuses in result.diagnostics for s in statuses for k, v in s.values
             if k.endswith(".rate_hz")]
    assert rates and max(rates) < 1000  # the bag's fastest stream is 200 Hz


def test_a_run_without_estimates_says_why_and_counts_none(tmp_path, capsys):
    """The bundled bag without --config: every JointState lacks the default 'elevator' joint.
    The result counts no estimate (the command exits 1 on it) and the summary names the
    stream, the reason, the joints expected and received and the parameter to change."""
    result = replay(BUNDLED, {}, tmp_path / "r", progress=False, plots=False)
    assert result.estimates == 0
    names = next(m for kind, _s, m in read_inputs(BUNDLED)[0] if kind == "control_surfaces").name
    want = ("no estimates: control_surfaces: all 1200 messages rejected (missing_joint): surfaces.elevator expects "
            f"[elevator], messages carry [{', '.join(names)}]; set surfaces.elevator")
    assert result.explanations == [want]
    from rls_uncertainty.offline.replay import summary_table

    assert summary_table(result) == want
    ok = replay(BUNDLED, load_parameters_file("t2"), tmp_path / "ok", progress=False, plots=False)
    with open(tmp_path / "ok" / "estimates.csv") as fh:
        assert ok.estimates == len({row["time"] for row in csv.DictReader(fh)}) > 480  # samples with a CSV row


def test_models_the_maneuver_never_excites_are_named_with_the_regressors_that_never_moved():
    """All six models on the longitudinal T-2 maneuver: the lateral ones never initialize; the
    regressors named constant are those whose inputs are constant in the bag itself. CX (the
    simulation's thrust balances a constant drag: an exact fit) publishes nothing: its standard
    errors are rounding, withheld at every sample past the publication rule."""
    messages = read_inputs(BUNDLED)[0]
    params = {**load_parameters_file("t2"), "models.enabled": ["CX", "CY", "CZ", "Cl", "Cm", "Cn"]}
    result = run_pipeline(messages, pipeline_config(params))
    assert [line.split(":")[0] for line in result.explanations] == ["CX", "CY", "Cl", "Cn"]
    withheld = result.pipeline.counters()["outputs_withheld"]["CX"]
    assert withheld == 587 - 103 + 1  # every sample from the 103rd on (n = 3, 2 x 50 lags)
    assert f"withheld at all {withheld} samples past the publication rule" in result.explanations[0]
    flat = {"beta": {m.vector.y for k, _s, m in messages if k == "airspeed"},
            "r_hat": {m.angular_velocity.z for k, _s, m in messages if k == "imu"},
            "p_hat": {m.angular_velocity.x for k, _s, m in messages if k == "imu"}}
    assert all(len(values) == 1 for values in flat.values())  # constant in the recording
    cl = next(line for line in result.explanations if line.startswith("Cl:"))
    assert "its 6 regressors were not excited independently in 587 samples" in cl
    assert all(name in cl.split("(")[1].split(" never moved")[0] for name in flat)


def test_the_replay_keeps_no_sample_and_plots_from_a_bounded_history(tmp_path, monkeypatch):
    """The command's result holds no per-sample output: the files are written as the samples
    come, and the plots read an evenly spaced history of at most 2 x PLOT_POINTS samples."""
    from rls_uncertainty.offline import replay as replay_module
    monkeypatch.setattr(replay_module, "PLOT_POINTS", 50)
    result = replay(BUNDLED, load_parameters_file("t2"), tmp_path / "r", progress=False)
    assert result.outputs == [] and result.diagnostics == []
    h = result.history
    assert h.n <= 100 and h.stride == 8 and h.offered == 591  # every used sample offered, every 8th kept
    with open(tmp_path / "r" / "estimates_wide.csv") as fh:
        times = [line.split(",", 1)[0] for line in fh][1:]
    assert [f"{s // 10**9}.{s % 10**9:09d}" for s in h.stamps_ns] == times[::8]
    assert {p.name for p in (tmp_path / "r").glob("*.png")} == {
        f"{m}_{kind}.png" for m in ("CZ", "Cm") for kind in REPLAY_FIGURES}


# ------------------------------------------------------------------ the frequency-domain estimates
def test_estimates_frequency_csv_holds_the_frequency_domain_results_with_the_columns_of_estimates_csv(tmp_path):
    """estimator.method both: estimates_frequency.csv has estimates.csv's columns, one row per
    sample and parameter (without the bias) of every model ready in the frequency domain, the
    values exactly the pipeline's (repr), and the MCAP carries ~/M/frequency/* byte for byte
    what the layout encodes; estimates.csv is unchanged by the method."""
    from mcap.reader import make_reader

    from rls_uncertainty.datapath.outputs import OutputLayout, fit_topics, output_topics
    from rls_uncertainty.offline.replay_files import CSV_COLUMNS

    params = {**load_parameters_file("t2"), "estimator.method": "both"}
    replay(BUNDLED, params, tmp_path / "both", progress=False, plots=False)
    replay(BUNDLED, load_parameters_file("t2"), tmp_path / "time", progress=False, plots=False)
    assert (tmp_path / "both" / "estimates.csv").read_bytes() == (tmp_path / "time" / "estimates.csv").read_bytes()
    assert not (tmp_path / "time" / "estimates_frequency.csv").exists()
    result = run_pipeline(read_inputs(BUNDLED)[0], pipeline_config(params))
    with open(tmp_path / "both" / "estimates_frequency.csv") as fh:
        reader = csv.reader(fh)
        assert tuple(next(reader)) == CSV_COLUMNS
        rows = list(reader)
    want = []
    for out in result.outputs:
        f = out.frequency
        for j, names in enumerate(m.frequency_parameter_names for m in result.pipeline.models):
            if f.ready[j]:
                want += [[f"{out.stamp_ns // 10**9}.{out.stamp_ns % 10**9:09d}", ("CZ", "Cm")[j], p,
                          repr(float(f.theta[j, i])), repr(float(f.se[j, i])), repr(float(f.se_conventional[j, i])),
                          str(int(f.converged[j, i])), str(int(f.lags[j]))] for i, p in enumerate(names)]
    assert rows == want and len(rows) > 2400
    assert {r[2] for r in rows} == {"CZ_alpha", "CZ_delta_e", "Cm_alpha", "Cm_q", "Cm_delta_e"}
    assert {r[7] for r in rows[-5:]} == {"50"}
    with open(tmp_path / "both" / "estimates.mcap", "rb") as fh:
        got = [(ch.topic, msg.log_time, msg.data) for _s, ch, msg in make_reader(fh).iter_messages()
               if "/frequency/" in ch.topic]
    layout = OutputLayout.of(result.pipeline)
    expected = [(f"/rls_estimator/{layout.topics[i][0]}", out.stamp_ns, data)
                for out in result.outputs for i, data in layout.encode(out, "base_link")
                if "/frequency/" in layout.topics[i][0]]
    assert sorted(got) == sorted(expected)
    assert len(got) == 4 * sum(int(out.frequency.ready.sum()) for out in result.outputs)  # four arrays per model
    with open(tmp_path / "both" / "estimates.mcap", "rb") as fh:
        topics = {(ch.topic, sch.name) for sch, ch, _m in make_reader(fh).iter_messages()}
    assert topics >= {(f"/rls_estimator/{t}", m) for t, m in output_topics(["CZ", "Cm"], frequency=True)
                      + fit_topics(["CZ", "Cm"])}


def test_frequency_only_writes_no_time_domain_files_and_counts_its_estimates(tmp_path, capsys):
    code = cli.main(["replay", str(BUNDLED), "--config", "t2", "--out", str(tmp_path / "o"), "--method", "frequency",
                     "--no-figures", "--quiet"])
    assert code == 0  # estimates were published: the frequency-domain ones
    names = {p.name for p in (tmp_path / "o").iterdir()}
    assert "estimates_frequency.csv" in names and not names & {"estimates.csv", "estimates_wide.csv"}
    out = capsys.readouterr().out
    assert out.startswith("frequency domain (docs/frequency.md):")
    assert "Cm_q" in out and "Cm_0" not in out
    from rls_uncertainty.offline.replay_files import CSV_COLUMNS

    with open(tmp_path / "o" / "estimates_frequency.csv") as fh:
        assert tuple(next(csv.reader(fh))) == CSV_COLUMNS
