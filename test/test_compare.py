"""replay --compare (rls_uncertainty/offline/compare.py): a replay against a reference replay sample by
sample. Equal within the tolerance (also under another OpenBLAS kernel), different with the
largest differences named (a changed parameter; values moved by hand across the tolerance's
edge), not comparable with the reason (another bag, span, models, rate, no run record)."""

import csv
import json
import math
import os
import shutil
import subprocess
import sys

import pytest
from bag_samples import fails

from rls_uncertainty import cli
from rls_uncertainty.errors import ConfigError, NotComparable
from rls_uncertainty.offline.compare import DEFAULT_RTOL, check_reference, comparable, compare_replays, read_run
from rls_uncertainty.offline.replay import replay
from rls_uncertainty.settings import load_parameters_file

from conftest import ROOT

BUNDLED = ROOT / "bags" / "t2_maneuver"


@pytest.fixture(scope="module")
def golden(tmp_path_factory):
    out = tmp_path_factory.mktemp("golden") / "golden"
    replay(BUNDLED, load_parameters_file("t2"), out, progress=False, plots=False)
    return out


def _rows(directory):
    with open(directory / "estimates.csv", newline="") as fh:
        return list(csv.DictReader(fh))


def _write_rows(directory, rows):
    with open(directory / "estimates.csv", "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)


def test_an_unchanged_replay_is_equal(golden, tmp_path, capsys):
    assert cli.main(["replay", str(BUNDLED), "--config", "t2", "--out", str(tmp_path / "r"), "--no-figures", "--quiet",
                     "--compare", str(golden)]) == 0
    out = capsys.readouterr().out
    n = len(_rows(golden))
    assert f"equal: {5 * n} values ({n} samples x parameters) within rtol 1e-06" in out
    assert "the largest difference is 0 of its tolerance" in out


def test_a_changed_parameter_is_different_and_named_with_the_largest_differences(golden, tmp_path, capsys):
    assert cli.main(["replay", str(BUNDLED), "--config", "t2", "--forgetting", "0.9999", "--out",
                     str(tmp_path / "r"), "--no-figures", "--quiet", "--compare", str(golden)]) == 1
    out = capsys.readouterr().out
    assert "configuration differs from the reference's: estimator.forgetting: 0.9999 here, 1.0 in the reference" in out
    assert "DIFFERENT" in out
    # The listed values are the two CSVs' own, at the time given.
    new, old = _rows(tmp_path / "r"), _rows(golden)
    t0 = int(new[0]["time"].replace(".", ""))
    listed = [line.split() for line in out.splitlines() if line.split()[2:3] == ["estimate"]]
    assert len(listed) == 10
    for parameter, time, _q, value, reference, excess in listed:
        at = [i for i, r in enumerate(new) if r["parameter"] == parameter
              and abs((int(r["time"].replace(".", "")) - t0) * 1e-9 - float(time)) < 6e-4]
        assert len(at) == 1 and new[at[0]]["estimate"] == value and old[at[0]]["estimate"] == reference
        s = abs(float(reference)) + float(old[at[0]]["std_error"])
        assert float(excess) == pytest.approx(abs(float(value) - float(reference)) / (DEFAULT_RTOL * s), rel=1e-2)
        assert float(excess) > 1000


def _perturbed(golden, tmp_path, change):
    """A copy of a replay's outputs with ``change`` applied to its estimates.csv rows."""
    here = tmp_path / "here"
    shutil.copytree(golden, here)
    rows = _rows(golden)
    change(rows)
    _write_rows(here, rows)
    return here


@pytest.mark.parametrize("factor,equal", [(0.5, True), (2.0, False)])
def test_the_tolerance_is_rtol_of_the_estimate_plus_its_standard_error(golden, tmp_path, factor, equal):
    def change(rows):
        r = rows[-1]
        s = abs(float(r["estimate"])) + float(r["std_error"])
        r["estimate"] = repr(float(r["estimate"]) + factor * DEFAULT_RTOL * s)

    cmp = compare_replays(_perturbed(golden, tmp_path, change), golden)
    assert cmp.equal is equal and cmp.largest == pytest.approx(factor, rel=1e-6)


def test_standard_errors_are_compared_as_variances(golden, tmp_path):
    """Variances carry rounding in proportion to s^2. At an exact fit (a model's first
    sample) the standard error is rounding: 0 in one run, 1e-5 of s in the other is equal (the
    variance moved by 1e-10 s^2); the same change of a standard error as large as its
    estimate is not (its variance moved by more than 2e-5 s^2)."""
    rows = _rows(golden)
    first = next(i for i, r in enumerate(rows) if r["model"] == "Cm")  # Cm's exact fit
    large = next(i for i, r in enumerate(rows) if float(r["std_error"]) > abs(float(r["estimate"])))

    def scale(r):
        return abs(float(r["estimate"])) + float(r["std_error"])

    def exact(rows):
        rows[first]["std_error"] = "0.0"

    reference = _perturbed(golden, tmp_path / "ref", exact)

    def rounding(rows):
        rows[first]["std_error"] = repr(1e-5 * abs(float(rows[first]["estimate"])))

    assert compare_replays(_perturbed(reference, tmp_path / "a", rounding), reference).equal

    def moved(rows):
        rows[large]["std_error"] = repr(float(rows[large]["std_error"]) + 1e-5 * scale(rows[large]))

    cmp = compare_replays(_perturbed(golden, tmp_path / "b", moved), golden)
    assert not cmp.equal and [d.quantity for d in cmp.worst] == ["std_error"] and cmp.worst[0].excess > 5


def test_flags_lag_counts_and_missing_samples_differ(golden, tmp_path):
    def change(rows):
        rows[100]["converged"] = "1" if rows[100]["converged"] == "0" else "0"
        rows[200]["lags"] = str(int(rows[200]["lags"]) + 1)
        del rows[300]

    cmp = compare_replays(_perturbed(golden, tmp_path, change), golden)
    assert not cmp.equal and cmp.beyond == 2 and (cmp.only_here, cmp.only_there) == (0, 1)
    assert [d.quantity for d in cmp.categorical] == ["converged", "lags"]
    assert "only in the reference" in cmp.report()


def test_another_bag_span_models_or_rate_is_not_comparable(golden, tmp_path, capsys):
    other = tmp_path / "seed7"
    assert cli.main(["make-bag", "--seed", "7", "--out", str(other)]) == 0
    base = ["--config", "t2", "--no-figures", "--quiet", "--compare", str(golden)]
    fails(capsys, ["replay", str(other), "--out", str(tmp_path / "a"), *base], "another bag: its input messages differ")
    fails(capsys, ["replay", str(BUNDLED), "--out", str(tmp_path / "b"), "--end", "9", *base], "another span: end 9.0")
    fails(capsys, ["replay", str(BUNDLED), "--out", str(tmp_path / "c"), "--models", "CZ", *base],
          "other models: CZ (CZ_0 CZ_alpha CZ_delta_e) here; CZ (CZ_0 CZ_alpha CZ_delta_e), Cm (")
    # What can be checked before the bag is read is: no output for these.
    assert not (tmp_path / "b").exists() and not (tmp_path / "c").exists()
    run = read_run(golden)
    faster = {**run, "period_ns": run["period_ns"] // 2}
    with pytest.raises(NotComparable, match="another sample rate: rate 100 Hz here, 50 Hz in the reference"):
        comparable(faster, run)
    (tmp_path / "empty").mkdir()
    fails(capsys, ["replay", str(BUNDLED), "--out", str(tmp_path / "d"), "--config", "t2", "--compare",
                   str(tmp_path / "empty")], "no run.json")


def test_the_tolerances_need_a_reference(tmp_path, capsys):
    fails(capsys, ["replay", str(BUNDLED), "--out", str(tmp_path / "r"), "--rtol", "1e-3"], "--rtol and --atol")


def test_the_reference_is_never_the_output(golden, tmp_path, capsys):
    copy = tmp_path / "g"
    shutil.copytree(golden, copy)
    before = (copy / "estimates.csv").read_bytes()
    fails(capsys, ["replay", str(BUNDLED), "--config", "t2", "--out", str(copy), "--force", "--compare", str(copy)],
          str(copy))
    assert (copy / "estimates.csv").read_bytes() == before


def test_the_run_record_names_the_bag_span_and_configuration(golden):
    run = json.loads((golden / "run.json").read_text())
    assert run["bag"]["messages_read"] == run["bag"]["messages_used"] == 4920
    assert run["bag"]["start"] is None and run["bag"]["strict"] is True and len(run["bag"]["input_sha256"]) == 64
    assert run["parameters"]["estimator.lag_span"] == 1.0 and run["parameters"]["topics.imu"] == "imu"
    assert run["models"] == ["CZ", "Cm"] and run["period_ns"] == 20_000_000


def test_another_openblas_kernel_is_equal_within_the_default_tolerance(golden, tmp_path):
    """The reference was made with this machine's kernels; Prescott's (any x86-64 CPU has them)
    round differently (on this machine the CSVs differ in their last bits), within 1e-6."""
    env = {**os.environ, "OPENBLAS_CORETYPE": "Prescott"}
    run = subprocess.run([sys.executable, "-m", "rls_uncertainty.cli", "replay", str(BUNDLED), "--config", "t2",
                          "--out", str(tmp_path / "r"), "--no-figures", "--quiet", "--compare", str(golden)],
                         env=env, capture_output=True, text=True, timeout=300)
    assert run.returncode == 0, run.stdout + run.stderr
    assert "equal:" in run.stdout


@pytest.fixture(scope="module")
def golden_both(tmp_path_factory):
    out = tmp_path_factory.mktemp("golden_both") / "golden"
    replay(BUNDLED, {**load_parameters_file("t2"), "estimator.method": "both"}, out, progress=False, plots=False)
    return out


def _count(path):
    with open(path, newline="") as fh:
        return sum(1 for _ in csv.DictReader(fh))


def test_both_methods_results_are_compared(golden_both, tmp_path, capsys):
    assert cli.main(["replay", str(BUNDLED), "--config", "t2", "--method", "both", "--out", str(tmp_path / "r"),
                     "--no-figures", "--quiet", "--compare", str(golden_both)]) == 0
    n = _count(golden_both / "estimates.csv") + _count(golden_both / "estimates_frequency.csv")
    assert _count(golden_both / "estimates_frequency.csv") > 0
    assert f"equal: {5 * n} values ({n} samples x parameters)" in capsys.readouterr().out


def test_a_frequency_domain_value_beyond_the_tolerance_is_named_with_its_method(golden_both, tmp_path):
    here = tmp_path / "here"
    shutil.copytree(golden_both, here)
    with open(golden_both / "estimates_frequency.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))
    r = rows[len(rows) // 2]
    s = abs(float(r["estimate"])) + float(r["std_error"])
    r["estimate"] = repr(float(r["estimate"]) + 3 * DEFAULT_RTOL * s)
    with open(here / "estimates_frequency.csv", "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    cmp = compare_replays(here, golden_both)
    assert not cmp.equal and cmp.beyond == 1 and cmp.largest == pytest.approx(3, rel=1e-6)
    assert [(d.parameter, d.quantity) for d in cmp.worst] == [(f"{r['parameter']} [frequency]", "estimate")]


def test_a_method_only_one_run_has_is_a_difference_with_its_rows_counted(golden, golden_both, tmp_path):
    cmp = compare_replays(golden_both, golden)
    assert not cmp.equal and cmp.beyond == 0 and cmp.only_there == 0
    assert cmp.only_here == _count(golden_both / "estimates_frequency.csv") > 0
    assert any(note.startswith("estimator.method: 'both' here, 'time' in the reference") for note in cmp.notes)
    assert f"estimates_frequency.csv ({cmp.only_here} rows) only in this run" in cmp.report()


def test_runs_with_no_estimation_method_in_common_are_not_comparable(golden, tmp_path, capsys):
    # A frequency-domain replay against a time-domain reference: no results file to pair, said
    # before the bag is read (not "DIFFERENT: 0 of 0 values").
    fails(capsys, ["replay", str(BUNDLED), "--config", "t2", "--method", "frequency", "--out", str(tmp_path / "f"),
                   "--no-figures", "--quiet", "--compare", str(golden)],
          "no estimation method in common: estimator.method 'frequency' here (estimates_frequency.csv), "
          "'time' in the reference (estimates.csv)")
    assert not (tmp_path / "f").exists()
    run = read_run(golden)
    frequency = {**run, "parameters": {**run["parameters"], "estimator.method": "frequency"}}
    both = {**run, "parameters": {**run["parameters"], "estimator.method": "both"}}
    with pytest.raises(NotComparable, match=r"'time' here \(estimates\.csv\), 'frequency' in the reference"):
        comparable(run, frequency)
    assert comparable(frequency, both) and comparable(run, both)  # a method in common: comparable, noted


# A damaged reference: every kind is made here from the golden replay's own files, and must be
# refused (exit 2) in one line naming the file, the line and the column (or run.json's field),
# before the bag is read; never compared, never "equal".

ROW = 100  # a row in the middle of the maneuver: line ROW + 2 of the file (the header is line 1)


def _rewrite(directory, change):
    """``change(header, rows)`` applied to the cells of ``directory``'s estimates.csv."""
    with open(directory / "estimates.csv", newline="") as fh:
        header, *rows = list(csv.reader(fh))
    header, rows = change(header, rows)
    with open(directory / "estimates.csv", "w", newline="") as fh:
        csv.writer(fh, lineterminator="\n").writerows([header, *rows])


def _cell(column, value, row=None):
    def change(header, rows):
        i = header.index(column)
        for k, r in enumerate(rows):
            if row is None or k == row:
                r[i] = value
        return header, rows
    return lambda d: _rewrite(d, change)


def _rows_edit(edit):
    def change(header, rows):
        edit(header, rows)
        return header, rows
    return lambda d: _rewrite(d, change)


def _drop_column(column):
    def change(header, rows):
        i = header.index(column)
        return header[:i] + header[i + 1:], [r[:i] + r[i + 1:] for r in rows]
    return lambda d: _rewrite(d, change)


def _swap(rows):
    rows[ROW], rows[ROW + 1] = rows[ROW + 1], rows[ROW]


def _run(edit):
    def mutate(directory):
        run = json.loads((directory / "run.json").read_text())
        edit(run)
        (directory / "run.json").write_text(json.dumps(run))
    return mutate


def _fifo(name):
    def mutate(directory):
        (directory / name).unlink()
        os.mkfifo(directory / name)
    return mutate


LINE = f"line {ROW + 2}"
DAMAGED = {
    # values that are not finite, or not a standard error
    "every estimate NaN": (_cell("estimate", "nan"), "line 2, column estimate: nan is not finite"),
    "one estimate NaN": (_cell("estimate", "nan", ROW), f"{LINE}, column estimate: nan is not finite"),
    "one estimate -inf": (_cell("estimate", "-inf", ROW), f"{LINE}, column estimate: -inf is not finite"),
    "every std_error inf": (_cell("std_error", "inf"), "line 2, column std_error: inf is not finite"),
    "one std_error -inf": (_cell("std_error", "-inf", ROW), f"{LINE}, column std_error: -inf is not finite"),
    "one conventional SE NaN": (_cell("std_error_conventional", "NaN", ROW),
                                f"{LINE}, column std_error_conventional: NaN is not finite"),
    "a negative std_error": (_cell("std_error", "-5", ROW), f"{LINE}, column std_error: -5 is negative"),
    # malformed
    "a cell abc": (_cell("estimate", "abc", ROW), f'{LINE}, column estimate: "abc" is not a number'),
    "an empty cell": (_cell("std_error", "", ROW), f'{LINE}, column std_error: "" is not a number'),
    "a missing column": (_drop_column("std_error_conventional"), "line 1: no column std_error_conventional"),
    "a row one cell short": (_rows_edit(lambda h, rows: rows[ROW].pop()), f"{LINE}: 7 cells, expected 8"),
    "a time that is not a stamp": (_cell("time", "12.5", ROW), f'{LINE}, column time: "12.5" is not a stamp'),
    "a flag of 2": (_cell("converged", "2", ROW), f'{LINE}, column converged: "2" is not 0 or 1'),
    "a lag count x": (_cell("lags", "x", ROW), f'{LINE}, column lags: "x" is not a whole number'),
    "an unknown parameter": (_cell("parameter", "Cm_beta", ROW), f'{LINE}, column parameter: "Cm_beta" of model'),
    "binary garbage": (lambda d: (d / "estimates.csv").write_bytes(bytes(range(256)) * 64),
                       "estimates.csv: line 1: no column time"),
    "not UTF-8": (lambda d: (d / "estimates.csv").write_bytes(b"time,model\n\xff\xfe\n"),
                  "estimates.csv: line 1: no column parameter"),
    "an empty file": (lambda d: (d / "estimates.csv").write_bytes(b""), "estimates.csv: empty (no header line)"),
    "a FIFO as estimates.csv": (_fifo("estimates.csv"), "estimates.csv: a FIFO, not a regular file"),
    # inconsistent
    "two rows swapped": (_rows_edit(lambda h, rows: _swap(rows)), f"line {ROW + 3}: "),
    "a row repeated": (_rows_edit(lambda h, rows: rows.insert(ROW, list(rows[ROW]))),
                       f"line {ROW + 3}: "),
    "no estimates.csv": (lambda d: (d / "estimates.csv").unlink(), "estimator.method 'time' writes estimates.csv"),
    "run.json without period_ns": (_run(lambda r: r.pop("period_ns")), "run.json: period_ns: missing"),
    "run.json period_ns 0": (_run(lambda r: r.update(period_ns=0)),
                             "run.json: period_ns: 0 is not a whole number of nanoseconds > 0"),
    "run.json period_ns 20ms": (_run(lambda r: r.update(period_ns="20ms")), 'run.json: period_ns: "20ms" is not'),
    "run.json period_ns NaN": (_run(lambda r: r.update(period_ns=float("nan"))), "run.json: period_ns: NaN is not"),
    "run.json without models": (_run(lambda r: r.pop("models")), "run.json: models: missing"),
    "run.json models of other length": (_run(lambda r: r["parameter_names"].pop()),
                                        "run.json: parameter_names: 1 lists for 2 models"),
    "run.json bag []": (_run(lambda r: r.update(bag=[])), "run.json: bag: [] is not a mapping"),
    "run.json bag digest 12": (_run(lambda r: r["bag"].update(input_sha256=12)),
                               "run.json: bag.input_sha256: 12 is not a SHA-256 digest"),
    "run.json strict yes": (_run(lambda r: r["bag"].update(strict="yes")), 'run.json: bag.strict: "yes" is not'),
    "run.json method bogus": (_run(lambda r: r["parameters"].update({"estimator.method": "bogus"})),
                              'run.json: parameters.estimator.method: "bogus" is not one of time, frequency, both'),
    "run.json not JSON": (lambda d: (d / "run.json").write_text("{period_ns: 1"), "run.json: not valid JSON"),
    "run.json a list": (lambda d: (d / "run.json").write_text("[]"), "run.json: not a run record of this version"),
    "run.json a FIFO": (_fifo("run.json"), "run.json: a FIFO, not a regular file"),
}


@pytest.fixture(params=list(DAMAGED))
def damaged(request, golden, tmp_path):
    """The golden replay's outputs with one kind of damage (:data:`DAMAGED`), and the message."""
    mutate, message = DAMAGED[request.param]
    reference = tmp_path / "damaged"
    shutil.copytree(golden, reference)
    mutate(reference)
    return reference, message


def test_a_damaged_reference_is_refused_naming_the_file_line_and_column(golden, damaged):
    reference, message = damaged
    with pytest.raises(NotComparable) as checked:
        check_reference(reference)
    assert str(checked.value).startswith(str(reference / "")) and message in str(checked.value)
    with pytest.raises(NotComparable) as compared:  # and as the comparison reads it
        compare_replays(golden, reference)
    assert str(compared.value) == str(checked.value)


def test_the_command_refuses_a_damaged_reference_in_one_line_before_reading_the_bag(damaged, tmp_path, capsys):
    reference, message = damaged
    line = fails(capsys, ["replay", str(BUNDLED), "--config", "t2", "--out", str(tmp_path / "r"), "--no-figures",
                          "--quiet", "--compare", str(reference)], message)
    assert "\n" not in line and not (tmp_path / "r").exists()


def test_an_intact_reference_passes_every_check(golden):
    """The control of the damaged ones: the golden replay itself, as written."""
    assert check_reference(golden) == json.loads((golden / "run.json").read_text())


@pytest.mark.parametrize("value", ["nan", "inf", "-inf"])
@pytest.mark.parametrize("column", ["estimate", "std_error", "std_error_conventional"])
def test_a_value_of_this_run_that_is_not_finite_is_a_difference_never_equality(golden, tmp_path, column, value):
    here = tmp_path / "here"
    shutil.copytree(golden, here)
    _cell(column, value, ROW)(here)
    rows = _rows(golden)
    cmp = compare_replays(here, golden, rtol=1e6)  # a tolerance a million times |estimate| + SE
    assert not cmp.equal and cmp.beyond == 1 and cmp.rows == len(rows)
    [d] = cmp.categorical
    assert (d.parameter, d.quantity, d.value, d.reference) == (rows[ROW]["parameter"], column, value, rows[ROW][column])
    assert "DIFFERENT: 1 of" in cmp.report() and "differs" in cmp.report()


def test_an_infinite_tolerance_is_refused_and_one_that_overflows_never_passes(golden, tmp_path, capsys):
    for rtol, atol in ((math.inf, 0.0), (1e-6, math.inf), (math.nan, 0.0), (-1.0, 0.0)):
        with pytest.raises(ConfigError, match="must be a finite number >= 0"):
            compare_replays(golden, golden, rtol=rtol, atol=atol)
    fails(capsys, ["replay", str(BUNDLED), "--out", str(tmp_path / "r"), "--compare", str(golden), "--rtol", "inf"],
          "--rtol: must be a finite number >= 0")
    # rtol 1e308 is finite, but rtol * s is infinite where s = |estimate| + SE exceeds 1.8: those
    # tolerances pass nothing (not even an identical value); the others pass it.
    rows = _rows(golden)
    s = [abs(float(r["estimate"])) + float(r["std_error"]) for r in rows]
    infinite = sum(math.isinf(1e308 * x) for x in s) + 2 * sum(math.isinf(2 * x * (1e308 * x)) for x in s)
    assert 0 < infinite < 3 * len(rows)
    cmp = compare_replays(golden, golden, rtol=1e308)
    assert cmp.beyond == infinite and cmp.rows == len(rows)
