"""The `rls-uncertainty` command line (rls_uncertainty/cli.py): subcommands, outputs, and
every bad input ending in a one-line error with exit status 2 (programming errors keep
their traceback). No DDS."""

import csv

from rls_uncertainty import cli


def test_multisine_command_writes_an_orthogonal_input_table(tmp_path, capsys):
    out = tmp_path / "inputs.csv"
    assert cli.main(["multisine", "--period", "12", "--band", "0.2", "2", "--inputs", "3",
                     "--names", "elevator", "aileron", "rudder", "--out", str(out)]) == 0
    rows = list(csv.DictReader(open(out)))
    by_input = {}
    for r in rows:
        by_input.setdefault(r["input"], set()).add(int(r["harmonic"]))
        assert 0.2 - 1e-9 <= float(r["frequency_hz"]) <= 2.0 + 1e-9
    assert set(by_input) == {"elevator", "aileron", "rudder"}
    a, b, c = by_input.values()
    assert not (a & b) and not (a & c) and not (b & c)  # interleaved harmonics: orthogonal inputs
    assert "relative peak factor" in capsys.readouterr().out
