"""The `rls-uncertainty` command line (rls_uncertainty/cli/): subcommands, outputs, one
vocabulary of setting flags made from the options classes, and every bad input ending in a
one-line error with exit status 2 (programming errors keep their traceback). No DDS."""

import csv
import math
import os
import shutil
from pathlib import Path

import pytest
from bag_samples import fails, fti_bag, tree, write_mapping

from rls_uncertainty import cli
from rls_uncertainty.cli.offline import replay_params
from rls_uncertainty.cli.simulation import simulation_options
from rls_uncertainty.errors import ConfigError
from rls_uncertainty.estimator import EstimatorOptions

ROOT = Path(__file__).resolve().parents[1]
BUNDLED = ROOT / "bags" / "t2_maneuver"


def test_multisine_command_writes_an_orthogonal_input_table(tmp_path, capsys):
    out = tmp_path / "inputs.csv"
    assert cli.main(["multisine", "--period", "12", "--band", "0.2", "2", "--inputs", "3",
                     "--names", "elevator", "aileron", "rudder", "--out", str(out)]) == 0
    with open(out) as fh:
        rows = list(csv.DictReader(fh))
    by_input = {}
    for r in rows:
        by_input.setdefault(r["input"], set()).add(int(r["harmonic"]))
        assert 0.2 - 1e-9 <= float(r["frequency_hz"]) <= 2.0 + 1e-9
    assert set(by_input) == {"elevator", "aileron", "rudder"}
    a, b, c = by_input.values()
    assert not (a & b) and not (a & c) and not (b & c)  # interleaved harmonics: orthogonal inputs
    assert "relative peak factor" in capsys.readouterr().out


# ------------------------------------------------------------------ output directories
def _setup(command, tmp_path):
    """The command's arguments without --out, and the directory holding its inputs."""
    inputs = tmp_path / "inputs"
    inputs.mkdir()
    if command == "make-bag":
        return ["make-bag", "--noise", "5"], inputs
    if command == "convert":
        src = fti_bag(inputs, "rec")
        return ["convert", str(src), "--mapping", str(write_mapping(inputs))], inputs
    bag = inputs / "t2_maneuver"
    shutil.copytree(BUNDLED, bag)
    return ["replay", str(bag), "--config", "t2", "--models", "CZ", "--no-figures", "--quiet"], inputs


def _expected_outputs(command, out):
    if command == "replay":
        return {"estimates.csv", "estimates_wide.csv", "estimates.mcap", "models.json", "parameters.csv", "run.json",
                "summary.txt"}
    return {f"{out.name}.mcap", "metadata.yaml"}


@pytest.mark.parametrize("command", ["make-bag", "convert", "replay"])
def test_a_non_empty_output_is_refused_and_replaced_with_force(tmp_path, capsys, command):
    args, _inputs = _setup(command, tmp_path)
    out = tmp_path / "out"
    out.mkdir()
    (out / "notes.txt").write_bytes(b"someone's notes")
    before = tree(tmp_path)
    fails(capsys, [*args, "--out", str(out)], str(out), "not empty", "--force")
    assert tree(tmp_path) == before
    assert cli.main([*args, "--out", str(out), "--force"]) == 0
    assert {p.name for p in out.iterdir()} == _expected_outputs(command, out)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["inputs", "out"]  # no temporary left


@pytest.mark.parametrize("command", ["convert", "replay"])
@pytest.mark.parametrize("force", [[], ["--force"]])
def test_the_input_bag_is_never_the_output(tmp_path, capsys, command, force):
    args, inputs = _setup(command, tmp_path)
    bag = Path(args[1])
    (inputs / "sub").mkdir()
    before = tree(tmp_path)
    for out in (bag, inputs / "sub" / "..", bag / "estimates", inputs):
        fails(capsys, [*args, "--out", str(out), *force], "input")
        assert tree(tmp_path) == before


def test_the_mapping_and_parameter_files_are_inputs_too(tmp_path, capsys):
    args, _inputs = _setup("convert", tmp_path)
    out = tmp_path / "out"
    out.mkdir()
    mapping = out / "mapping.yaml"
    mapping.write_bytes(Path(args[3]).read_bytes())
    args[3] = str(mapping)
    before = tree(tmp_path)
    fails(capsys, [*args, "--out", str(out), "--force"], "mapping.yaml")
    assert tree(tmp_path) == before
    config = out / "t2.yaml"
    config.write_bytes((ROOT / "config" / "t2.yaml").read_bytes())
    before = tree(tmp_path)
    fails(capsys, ["replay", str(BUNDLED), "--config", str(config), "--out", str(out), "--force", "--quiet"],
          "t2.yaml")
    assert tree(tmp_path) == before


@pytest.mark.parametrize("command", ["make-bag", "convert", "replay"])
def test_dir_sub_dotdot_is_the_directory_itself(tmp_path, capsys, command):
    args, inputs = _setup(command, tmp_path)
    (inputs / "sub").mkdir()
    before = tree(tmp_path)
    fails(capsys, [*args, "--out", str(inputs / "sub" / "..")], "inputs/sub/..")
    assert tree(tmp_path) == before


@pytest.mark.parametrize("command", ["make-bag", "convert", "replay"])
@pytest.mark.parametrize("force", [[], ["--force"]])
def test_an_existing_file_as_output_is_refused_and_nothing_is_left_behind(tmp_path, capsys, command, force):
    args, _inputs = _setup(command, tmp_path)
    (tmp_path / "out").write_bytes(b"a file")
    before = tree(tmp_path)
    fails(capsys, [*args, "--out", str(tmp_path / "out"), *force], "not a directory")
    assert tree(tmp_path) == before  # in particular no out.partial or .out.*.partial


def test_a_file_system_error_is_one_line_too(tmp_path, capsys):
    (tmp_path / "file").write_bytes(b"a file")
    fails(capsys, ["replay", str(BUNDLED), "--out", str(tmp_path / "file" / "out"), "--quiet"], "file")
    assert (tmp_path / "file").read_bytes() == b"a file"


def test_multisine_never_overwrites_a_file_without_force(tmp_path, capsys):
    out = tmp_path / "inputs.csv"
    out.write_bytes(b"a flight-test card")
    args = ["multisine", "--period", "12", "--band", "0.2", "2", "--inputs", "2", "--out", str(out)]
    fails(capsys, args, str(out), "--force")
    assert out.read_bytes() == b"a flight-test card"
    fails(capsys, [*args[:-1], str(tmp_path)], "is a directory")
    assert cli.main([*args, "--force"]) == 0
    assert out.read_text().startswith("input,harmonic,frequency_hz,relative_amplitude,phase_rad\n")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["inputs.csv"]


def test_montecarlo_refuses_a_non_empty_output_before_running(tmp_path, capsys):
    (tmp_path / "table3.csv").write_bytes(b"last week's table")
    fails(capsys, ["montecarlo", "--runs", "2", "--levels", "5", "--out", str(tmp_path), "--workers", "1"],
          "not empty", "--force")
    assert [p.name for p in tmp_path.iterdir()] == ["table3.csv"]
    assert (tmp_path / "table3.csv").read_bytes() == b"last week's table"


# ------------------------------------------------------------------ bad arguments
BAD_ARGUMENTS = [
    (["simulate", "--noise", "-5"], "--noise"),
    (["simulate", "--noise", "nan"], "--noise"),
    (["simulate", "--seed", "-1"], "--seed"),
    (["simulate", "--forgetting", "0"], "--forgetting"),
    (["simulate", "--forgetting", "1.5"], "--forgetting"),
    (["simulate", "--forgetting", "0.3"], "argument --forgetting: must be a number in [0.5, 1] (estimator.forgetting)"),
    (["replay", "{bag}", "--out", "{tmp}/r", "--quiet", "--forgetting", "0.3"],
     "argument --forgetting: must be a number in [0.5, 1] (estimator.forgetting)"),
    (["simulate", "--lag-span", "abc"], "--lag-span"),
    (["simulate", "--lag-span", "0.001"], "'estimator.lag_span' = 0.001 s is less than one sample at rate 50 Hz"),
    (["simulate", "--lags", "abc"], "--lags is now --lag-span SECONDS (lags / rate: 50 lags at 50 Hz = 1.0)"),
    (["montecarlo", "--out", "{tmp}/mc", "--runs", "0"], "--runs"),
    (["montecarlo", "--out", "{tmp}/mc", "--levels", "-5"], "--levels"),
    (["montecarlo", "--out", "{tmp}/mc", "--lag-span", "-3"], "--lag-span"),
    (["montecarlo", "--out", "{tmp}/mc", "--lags", "50"], "--lags is now --lag-span"),
    (["montecarlo", "--out", "{tmp}/mc", "--workers", "0"], "--workers"),
    (["montecarlo", "--out", "{tmp}/mc", "--jobs", "2"], "--jobs is now --workers"),
    (["montecarlo", "--out", "{tmp}/mc", "--burn-in-span", "-1"], "--burn-in-span"),
    (["montecarlo", "--out", "{tmp}/mc", "--burn-in", "20"], "--burn-in is now --burn-in-span SECONDS"),
    (["simulate", "--burn-in-span", "few"], "--burn-in-span"),
    (["replay", "{bag}", "--out", "{tmp}/r", "--quiet", "--no-plots"], "--no-plots is now --no-figures"),
    (["campaign", "{bag}", "--out", "{tmp}/c", "--quiet", "--no-plots"], "--no-plots is now --no-figures"),
    (["replay", "{bag}", "--out", "{tmp}/r", "--quiet", "--burn-in-span", "few"], "--burn-in-span"),
    (["replay", "{bag}", "--out", "{tmp}/r", "--quiet", "--burn-in-span", "2001"],
     "estimator.residual_burn_in_span"),
    (["replay", "{bag}", "--out", "{tmp}/r", "--quiet", "--burn-in", "20"],
     "--burn-in is now --burn-in-span SECONDS (samples / rate)"),
    (["multisine", "--period", "nan", "--band", "0.2", "2", "--inputs", "3", "--out", "{tmp}/ms.csv"], "--period"),
    (["multisine", "--period", "12", "--band", "2", "0.2", "--inputs", "3", "--out", "{tmp}/ms.csv"], "band"),
    (["multisine", "--period", "12", "--band", "0.2", "2", "--inputs", "0", "--out", "{tmp}/ms.csv"], "--inputs"),
    (["multisine", "--period", "12", "--band", "0.2", "2", "--inputs", "3", "--amplitude", "inf",
      "--out", "{tmp}/ms.csv"], "--amplitude"),
    (["multisine", "--period", "2", "--band", "0.5", "1", "--inputs", "3", "--out", "{tmp}/ms.csv"], "harmonics"),
    (["make-bag", "--out", "{tmp}/bag", "--noise", "nan"], "--noise"),
    (["make-bag", "--out", "{tmp}/bag", "--seed", "-1"], "--seed"),
    (["replay", "{bag}", "--out", "{tmp}/r", "--quiet", "--start", "inf"], "--start"),
    (["replay", "{bag}", "--out", "{tmp}/r", "--quiet", "--start", "nan"], "--start"),
    (["replay", "{bag}", "--out", "{tmp}/r", "--quiet", "--start", "-1"], "--start"),
    (["replay", "{bag}", "--out", "{tmp}/r", "--quiet", "--end", "nan"], "--end"),
    (["replay", "{bag}", "--out", "{tmp}/r", "--quiet", "--start", "5", "--end", "2"],
     "end (2 s) must be after start (5 s)"),
    (["replay", "{bag}", "--out", "{tmp}/r", "--quiet", "--start", "3", "--end", "3"], "must be after start"),
    (["replay", "{bag}", "--out", "{tmp}/r", "--quiet", "--start", "100"],
     "start 100 s is after the bag's last message: the bag spans 0 to 11.995 s from its start"),
    (["replay", "{bag}", "--out", "{tmp}/r", "--quiet", "--end", "300"],
     "end 300 s is after the bag's last message: the bag spans 0 to 11.995 s from its start"),
    (["replay", "{bag}", "--out", "{tmp}/r", "--quiet", "--start", "2", "--end", "12"], "0 to 11.995 s"),
    (["replay", "{bag}", "--out", "{tmp}/r", "--quiet", "--lag-span", "abc"], "--lag-span"),
    (["replay", "{bag}", "--out", "{tmp}/r", "--quiet", "--lag-span", "-5"], "--lag-span"),
    (["replay", "{bag}", "--out", "{tmp}/r", "--quiet", "--lag-span", "0.001"],
     "'estimator.lag_span' = 0.001 s is less than one sample at rate 50 Hz"),
    (["replay", "{bag}", "--out", "{tmp}/r", "--quiet", "--lags", "50"],
     "--lags is now --lag-span SECONDS (lags / rate: 50 lags at 50 Hz = 1.0)"),
    (["replay", "{bag}", "--out", "{tmp}/r", "--quiet", "--max-lags", "50"], "--max-lags is now --max-lag-span"),
    (["replay", "{bag}", "--out", "{tmp}/r", "--quiet", "--max-lag-span", "0"], "--max-lag-span"),
    (["montecarlo", "--out", "{tmp}/mc", "--lag-span", "none"], "--lag-span"),
    (["replay", "{bag}", "--out", "{tmp}/r", "--quiet", "--forgetting", "nan"], "estimator.forgetting"),
    (["replay", "{bag}", "--out", "{tmp}/r", "--quiet", "--models", "XX"], "'XX'"),
    (["replay", "{bag}", "--out", "{tmp}/r", "--quiet", "--config", "{tmp}/missing.yaml"], "missing.yaml"),
    (["replay", "{tmp}/missing_bag", "--out", "{tmp}/r", "--quiet"], "no such bag"),
    (["replay", "{bag}", "--quiet"], "--out"),
    (["replay", "{bag}", "--out", "{tmp}/r", "--quiet", "--figures", "png,gif"], "--figures"),
    (["replay", "{bag}", "--out", "{tmp}/r", "--quiet", "--dpi", "20"], "--dpi"),
    (["replay", "{bag}", "--out", "{tmp}/r", "--quiet", "--dpi", "high"], "--dpi"),
    (["play", "{bag}", "--rate", "-1"], "--rate"),
    (["play", "{bag}", "--rate", "nan"], "--rate"),
    (["play", "{bag}", "--delay", "-1"], "--delay"),
    (["play", "{bag}", "--wait", "-1"], "--wait"),
    (["play", "{bag}", "--wait", "inf"], "--wait"),
    (["play", "{bag}", "--subscribers", "-1"], "--subscribers"),
    (["play", "{bag}", "--subscribers", "1.5"], "--subscribers"),
    (["play", "{bag}", "--loop", "0"], "--loop"),
    (["play", "{bag}", "--loop", "1.5"], "--loop"),
    (["play", "{bag}", "--window", "0"], "--window"),
    (["play", "{bag}", "--ack-timeout", "-1"], "--ack-timeout"),
    (["play", "{bag}", "--ack-timeout", "nan"], "--ack-timeout"),
    (["demo", "--rate", "inf"], "--rate"),
    (["nonsense"], "nonsense"),
]


def _case_id(args):
    return " ".join(a for a in args if "{" not in a and a not in ("--out", "--quiet"))


@pytest.mark.parametrize("args,needle", BAD_ARGUMENTS, ids=[_case_id(a) for a, _ in BAD_ARGUMENTS])
def test_a_bad_argument_is_one_line_with_exit_status_2_and_no_output(tmp_path, capsys, args, needle):
    args = [a.format(tmp=tmp_path, bag=BUNDLED) for a in args]
    if args[0] == "nonsense":
        with pytest.raises(SystemExit) as exc:
            cli.main(args)
        err = capsys.readouterr().err
        assert exc.value.code == 2 and len(err.splitlines()) == 1 and needle in err, err
        return
    fails(capsys, args, needle)
    assert list(tmp_path.iterdir()) == []


def test_bad_text_in_parameter_and_aircraft_files_is_one_line(tmp_path, capsys):
    (tmp_path / "binary.yaml").write_bytes(b"\xff\xfe\x00")
    fails(capsys, ["replay", str(BUNDLED), "--config", str(tmp_path / "binary.yaml"), "--out", str(tmp_path / "r"),
                   "--quiet"], "binary.yaml", "not UTF-8")
    (tmp_path / "air.yaml").write_text(
        f"rls_estimator:\n  ros__parameters:\n    aircraft: {tmp_path / 'binary.yaml'}\n")
    fails(capsys, ["replay", str(BUNDLED), "--config", str(tmp_path / "air.yaml"), "--out", str(tmp_path / "r"),
                   "--quiet"], "aircraft", "binary.yaml", "not UTF-8")
    (tmp_path / "broken.yaml").write_text("rls_estimator:\n  ros__parameters: [1\n")
    fails(capsys, ["replay", str(BUNDLED), "--config", str(tmp_path / "broken.yaml"), "--out", str(tmp_path / "r"),
                   "--quiet"], "broken.yaml", "not valid YAML")
    assert not (tmp_path / "r").exists()


def test_the_player_functions_refuse_bad_numbers_before_starting_dds():
    from rls_uncertainty.ros import demo, player
    for kwargs in ({"rate": math.nan}, {"rate": -1.0}, {"rate": math.inf}, {"start_delay": -0.5},
                   {"subscribers": -1}, {"subscribers": 1.5}, {"wait": math.nan}, {"wait": -1.0}, {"loops": 0},
                   {"loops": True}, {"window": 0}, {"ack_timeout": -1.0}, {"ack_timeout": math.inf}):
        with pytest.raises(ConfigError):
            player.play(BUNDLED, **kwargs)
    with pytest.raises(ConfigError, match="rate"):
        demo.demo(rate=math.nan)


def test_play_leaves_dds_discovery_to_the_environment(monkeypatch):
    """The product never pins ROS_AUTOMATIC_DISCOVERY_RANGE (a control room spans machines):
    `play` starts DDS with the caller's environment, whatever it is."""
    import rclpy

    from rls_uncertainty.ros import player
    class Started(Exception):
        pass

    seen = []

    def init(*_args, **_kwargs):
        seen.append(os.environ.get("ROS_AUTOMATIC_DISCOVERY_RANGE", "<unset>"))
        raise Started

    monkeypatch.setattr(rclpy, "init", init)
    monkeypatch.delenv("ROS_AUTOMATIC_DISCOVERY_RANGE", raising=False)
    with pytest.raises(Started):
        player.play(BUNDLED)
    assert seen == ["<unset>"] and "ROS_AUTOMATIC_DISCOVERY_RANGE" not in os.environ
    monkeypatch.setenv("ROS_AUTOMATIC_DISCOVERY_RANGE", "SUBNET")
    with pytest.raises(Started):
        player.play(BUNDLED)
    assert seen[-1] == "SUBNET"


# ------------------------------------------------------------------ programming errors
WORKERS = [
    ("rls_uncertainty.offline.replay.replay", ["replay", "{bag}", "--out", "{tmp}/r", "--quiet"]),
    ("rls_uncertainty.offline.bags.convert", ["convert", "{bag}", "--mapping", "m.yaml", "--out", "{tmp}/c"]),
    ("rls_uncertainty.offline.bags.write_t2_bag", ["make-bag", "--out", "{tmp}/b"]),
    ("rls_uncertainty.simulation.multisine.design_multisines",
     ["multisine", "--period", "12", "--band", "0.2", "2", "--inputs", "2", "--out", "{tmp}/m.csv"]),
    ("rls_uncertainty.ros.player.play", ["play", "{bag}"]),
    ("rls_uncertainty.ros.demo.demo", ["demo"]),
]


@pytest.mark.parametrize("error", [KeyError, ValueError])
@pytest.mark.parametrize("worker,args", WORKERS, ids=[w.rsplit(".", 1)[1] for w, _ in WORKERS])
def test_a_programming_error_keeps_its_traceback(tmp_path, capsys, monkeypatch, worker, args, error):
    """Only the package's errors and OSError become one-line messages: a KeyError (or a plain
    ValueError, the built-in base of ConfigError) is a bug and propagates out of main."""

    def bug(*_args, **_kwargs):
        raise error("a bug")

    monkeypatch.setattr(worker, bug)
    with pytest.raises(error, match="a bug"):
        cli.main([a.format(tmp=tmp_path, bag=BUNDLED) for a in args])
    assert "error:" not in capsys.readouterr().err


# ------------------------------------------------------------------ simulate
def test_simulate_prints_every_t2_parameter_with_its_true_value(capsys):
    from rls_uncertainty.simulation.t2 import T2_MODELS, T2_TRUE

    assert cli.main(["simulate", "--noise", "10", "--seed", "3"]) == 0
    lines = capsys.readouterr().out.splitlines()
    head = lines.index(next(line for line in lines if line.startswith("parameter")))
    assert lines[head].split() == ["parameter", "true", "estimate", "SE", "conv.", "SE", "corr.", "corr/conv"]
    names = [n for m in T2_MODELS for n in m.parameter_names]
    rows = [line.split() for line in lines[head + 2:head + 2 + len(names)]]
    assert [r[0] for r in rows] == names
    for name, true, est, se_conv, se_corr, ratio in rows:
        assert true == (f"{T2_TRUE[name]:.3f}" if name in T2_TRUE else "-")
        # The ratio is of the unrounded errors: the printed ones' within their rounding (5e-5
        # each) and the ratio's own (0.005).
        r, c = float(se_corr) / float(se_conv), float(se_conv)
        assert float(ratio) == pytest.approx(r, abs=0.005 + 5e-5 * (1 + r) / c + 1e-9)
        if name in T2_TRUE:  # 10% noise: every estimate within a few corrected standard errors
            assert abs(float(est) - T2_TRUE[name]) < 0.5 * abs(T2_TRUE[name]) + 4 * float(se_corr)


def test_replay_reads_its_config_as_the_node_does(tmp_path, capsys):
    """--config takes the sections for the node in any namespace and the wildcard ones; a typo'd
    section or parameter is refused, and what the node would ignore is one warning line."""
    (tmp_path / "typo.yaml").write_text("rls_estimatr:\n  ros__parameters:\n    rate: 50.0\n")
    fails(capsys, ["replay", str(BUNDLED), "--config", str(tmp_path / "typo.yaml"), "--out", str(tmp_path / "r"),
                   "--quiet"], "no section for node rls_estimator", "did you mean rls_estimator?")
    (tmp_path / "lag.yaml").write_text("/**:\n  ros__parameters:\n    estimator.lag: 20\n")
    fails(capsys, ["replay", str(BUNDLED), "--config", str(tmp_path / "lag.yaml"), "--out", str(tmp_path / "r"),
                   "--quiet"], "unknown parameter 'estimator.lag'", "did you mean estimator.lag_span?")
    config = (ROOT / "config" / "t2.yaml").read_text() + "planner:\n  ros__parameters:\n    speed: 3\n"
    (tmp_path / "multi.yaml").write_text(config)
    assert cli.main(["replay", str(BUNDLED), "--config", str(tmp_path / "multi.yaml"), "--out", str(tmp_path / "r"),
                     "--quiet", "--no-figures", "--models", "CZ"]) == 0
    err = capsys.readouterr().err
    assert err == f"rls-uncertainty replay: warning: parameter file {tmp_path / 'multi.yaml'}: sections for other " \
                  "nodes ignored: planner\n"


def test_every_command_that_runs_the_estimator_takes_its_spans_in_seconds():
    """simulate and montecarlo (the T-2 simulation's 50 Hz) and replay take one --lag-span, in
    seconds as estimator.lag_span: 0.4 s is 20 lags at 50 Hz, all is -1 (Eq. 20), auto the
    lag selection; --burn-in-span likewise ('default': 1 s with auto lags, 0 with fixed)."""
    parser = cli.build_parser()
    for head in (["simulate"], ["montecarlo", "--out", "o"]):
        for given, lags in (([], 50), (["0"], 0), (["0.4"], 20), (["1"], 50), (["all"], "all"), (["auto"], "auto")):
            options = simulation_options(parser.parse_args([*head, *(["--lag-span", *given] if given else [])]))
            assert options.lags == lags and options.max_lags == 50, (head, given)
        for given, burn_in in ((["--burn-in-span", "0.4"], 20), (["--burn-in-span", "default"], 50), ([], 50)):
            assert simulation_options(parser.parse_args([*head, "--lag-span", "auto", *given])).burn_in == burn_in
        assert simulation_options(parser.parse_args([*head, "--max-lag-span", "0.5", "--lag-span", "auto"])) \
            .max_lags == 25
    for given, span in (("0", 0.0), ("1", 1.0), ("0.25", 0.25), ("all", -1.0)):
        assert replay_params(parser.parse_args(["replay", "bag", "--out", "o", "--lag-span", given])) \
            ["estimator.lag_span"] == span


def test_the_setting_flags_are_made_from_the_options_classes():
    """Each command that runs the estimator has one flag per estimator setting that declares
    one, named, bounded and explained by the declaration (schema.option on
    EstimatorOptions): a value beyond the setting's range is refused naming the parameter,
    and the help gives the setting's meaning and default."""
    from rls_uncertainty.cli.flags import RENAMED_FLAGS
    from rls_uncertainty.schema import settings
    from rls_uncertainty.settings.parameters import PARAMETER_NAMES

    declared = [s.ros for _f, s in settings(EstimatorOptions) if s.cli]
    assert sorted(declared) == sorted(["estimator.lag_span", "estimator.max_lag_span", "estimator.publish_lag_windows",
                                       "estimator.residual_burn_in_span", "estimator.window", "estimator.forgetting"])
    commands = {"simulate": [], "montecarlo": ["--out", "o"], "replay": ["bag", "--out", "o"],
                "campaign": ["bag", "--out", "o"]}
    sub = next(a for a in cli.build_parser()._actions if a.dest == "command").choices
    for command, head in commands.items():
        actions = {a.dest: a for a in sub[command]._actions}
        for name in declared:
            p = PARAMETER_NAMES[name]
            assert actions[name].option_strings == [p.flag] and p.description in actions[name].help, (command, name)
            if p.high is not None:
                with pytest.raises(SystemExit) as exc:
                    sub[command].parse_args([*head, p.flag, str(2 * p.high)])
                assert exc.value.code == 2
        for old in ("--lags", "--max-lags", "--burn-in"):
            assert old in {o for a in sub[command]._actions for o in a.option_strings}, (command, old)
    assert RENAMED_FLAGS["--jobs"] == "--workers" and RENAMED_FLAGS["--no-plots"] == "--no-figures"


def test_replay_lag_span_sets_the_lag_parameters_whatever_the_file_says(tmp_path):
    (tmp_path / "auto.yaml").write_text("/**:\n  ros__parameters:\n    estimator.lag_selection: auto\n")
    parser = cli.build_parser()
    expected = {"0.4": {"estimator.lag_selection": "fixed", "estimator.lag_span": 0.4},
                "all": {"estimator.lag_selection": "fixed", "estimator.lag_span": -1.0},
                "auto": {"estimator.lag_selection": "auto"}}
    for given, want in expected.items():
        args = parser.parse_args(["replay", "bag", "--out", "o", "--config", str(tmp_path / "auto.yaml"), "--lag-span",
                                  given])
        params = replay_params(args)
        assert {k: v for k, v in params.items() if k in ("estimator.lag_selection", "estimator.lag_span")} == want


def test_version_is_package_xml_s(capsys):
    import xml.etree.ElementTree as ET

    version = ET.parse(ROOT / "package.xml").getroot().findtext("version")
    with pytest.raises(SystemExit) as exc:
        cli.main(["--version"])
    assert exc.value.code == 0 and capsys.readouterr().out == f"rls-uncertainty {version}\n"


def test_replay_with_no_estimate_says_why_and_exits_1(tmp_path, capsys):
    """The bundled bag has split elevators; the default surfaces.elevator expects one joint named
    elevator, so every control_surfaces message is refused and no model is ever estimated: the
    run names the joints on both sides and the parameter, and a script sees exit status 1."""
    code = cli.main(["replay", str(BUNDLED), "--out", str(tmp_path / "out"), "--quiet", "--no-figures"])
    out = capsys.readouterr().out
    assert code == 1
    assert "surfaces.elevator expects [elevator]" in out and "elevator_left, elevator_right" in out, out
    # The same bag with its configuration estimates, and exits 0.
    code = cli.main(["replay", str(BUNDLED), "--config", str(ROOT / "config" / "t2.yaml"),
                     "--out", str(tmp_path / "ok"), "--quiet", "--no-figures"])
    assert code == 0


def test_lags_and_burn_in_options_map_onto_the_estimator_parameters():
    parser = cli.build_parser()
    args = parser.parse_args(["replay", "bag", "--out", "o", "--lag-span", "auto", "--max-lag-span", "1.4"])
    params = replay_params(args)
    assert params["estimator.lag_selection"] == "auto" and params["estimator.max_lag_span"] == 1.4
    assert "estimator.lag_span" not in params
    # The residual burn-in overrides the parameter ('default' is its -1).
    for given, param in ((["--burn-in-span", "0.4"], 0.4), (["--burn-in-span", "default"], -1.0), ([], None)):
        params = replay_params(parser.parse_args(["replay", "bag", "--out", "o", "--lag-span", "auto", *given]))
        assert params.get("estimator.residual_burn_in_span") == param


def test_a_reader_that_stops_reading_ends_the_command_quietly(tmp_path):
    """``rls-uncertainty ... | head``: the output's reader gone is exit status 1 and no error
    line or traceback (the files are written all the same)."""
    import subprocess
    import sys

    read, write = os.pipe()
    os.close(read)  # the reader is gone before anything is printed
    try:
        done = subprocess.run([sys.executable, "-m", "rls_uncertainty.cli", "simulate", "--seed", "1"], stdout=write,
                              stderr=subprocess.PIPE, text=True, timeout=300)
    finally:
        os.close(write)
    assert (done.returncode, done.stderr) == (1, "")
