"""rls_uncertainty/progress.py: the bars of the long commands on stderr, with the count, the rate
and the time left; drawn on a terminal by default, always or never when asked; never on stdout."""

from __future__ import annotations

import io
import sys

import pytest

from rls_uncertainty import cli
from rls_uncertainty.progress import Progress, track


class Terminal(io.StringIO):
    def isatty(self):
        return True


@pytest.mark.parametrize(("stream", "mode", "drawn"), [
    (io.StringIO, None, False), (Terminal, None, True), (io.StringIO, True, True), (Terminal, False, False)])
def test_when_a_bar_is_drawn(monkeypatch, stream, mode, drawn):
    err = stream()
    monkeypatch.setattr(sys, "stderr", err)
    items = list(track(range(7), 7, "work", " items", mode))
    assert items == list(range(7))
    text = err.getvalue()
    assert bool(text) == drawn
    if drawn:  # the last frame: everything done, the count, the rate and the elapsed time
        last = text.rstrip("\n").split("\r")[-1]
        assert last.startswith("work: 100%") and "7/7" in last and "items/s" in last, text


def test_set_to_moves_the_bar_to_a_reported_count(monkeypatch):
    err = Terminal()
    monkeypatch.setattr(sys, "stderr", err)
    with Progress(10, "campaign", " maneuvers", None) as bar:
        assert bar.drawn
        bar.set_to(4)
        bar.set_to(10)
    assert "10/10" in err.getvalue().split("\r")[-1]


def test_progress_and_quiet_exclude_each_other(capsys, tmp_path):
    with pytest.raises(SystemExit) as exc:
        cli.main(["replay", "bag", "--out", str(tmp_path / "r"), "--progress", "--quiet"])
    assert exc.value.code == 2 and "not allowed with argument" in capsys.readouterr().err


def test_make_bag_campaign_progress_goes_to_stderr_only(capsys, tmp_path):
    """--progress draws into a pipe (here: captured stderr); stdout has the result line only."""
    assert cli.main(["make-bag", "--campaign", "2", "--gust-intensity", "light", "--out", str(tmp_path / "c"),
                     "--progress"]) == 0
    out, err = capsys.readouterr()
    assert out.startswith("wrote 2 replay bags") and len(out.splitlines()) == 1
    assert "make-bag: 100%" in err and "2/2" in err
    assert cli.main(["make-bag", "--campaign", "2", "--gust-intensity", "light", "--out", str(tmp_path / "d")]) == 0
    assert capsys.readouterr().err == ""  # not a terminal: no bar by default
