"""The optional dependencies (rls_uncertainty/extras.py): a missing module of an extra is one
line naming the pip extra, for the library call and for every command that needs one; any
other missing module keeps its traceback. A module is made missing by ``sys.modules[name] =
None`` (Python's own way to block an import), in the process or in a child process."""

from __future__ import annotations

import importlib
import re
import subprocess
import sys
from pathlib import Path

import pytest

from rls_uncertainty.errors import MissingExtra, RlsUncertaintyError
from rls_uncertainty.extras import EXTRAS, optional, require

ROOT = Path(__file__).resolve().parents[1]
BAG = ROOT / "bags" / "t2_maneuver"


def test_a_missing_module_of_an_extra_names_the_extra(monkeypatch):
    monkeypatch.setitem(sys.modules, "matplotlib", None)
    with pytest.raises(MissingExtra) as caught, optional("figures", what="drawing the figures",
                                                         instead="give --no-figures"):
        import matplotlib  # noqa: F401
    assert str(caught.value) == ("drawing the figures needs matplotlib: pip install 'rls_uncertainty[figures]' "
                                 "(or give --no-figures)")
    assert isinstance(caught.value, RlsUncertaintyError) and isinstance(caught.value, ImportError)
    assert (caught.value.extra, caught.value.module) == ("figures", "matplotlib")


def test_the_extra_is_the_one_that_provides_the_module(monkeypatch):
    monkeypatch.setitem(sys.modules, "std_srvs", None)
    with pytest.raises(MissingExtra, match=r"std_srvs is not installed: pip install 'rls_uncertainty\[ros\]' \(or "
                                           r"source a ROS 2 Jazzy installation\)"), optional("dashboard", "ros"):
        import std_srvs.srv  # noqa: F401


def test_other_import_errors_pass_unchanged(monkeypatch):
    name = "some_module_of_no_extra"
    monkeypatch.setitem(sys.modules, name, None)
    with pytest.raises(ModuleNotFoundError) as caught, optional("figures"):
        importlib.import_module(name)
    assert not isinstance(caught.value, MissingExtra)
    # A module of another extra than those named is not this block's to explain either.
    monkeypatch.setitem(sys.modules, "aiohttp", None)
    with pytest.raises(ModuleNotFoundError) as caught, optional("figures"):
        import aiohttp  # noqa: F401
    assert not isinstance(caught.value, MissingExtra)


def test_require_imports_the_main_module_now(monkeypatch):
    require("figures")  # installed here: nothing said
    monkeypatch.setitem(sys.modules, "distributed", None)
    with pytest.raises(MissingExtra, match=r"--scheduler needs distributed: pip install 'rls_uncertainty\[campaign\]'"):
        require("campaign", what="--scheduler")


def test_an_unknown_extra_is_a_programming_error():
    with pytest.raises(TypeError, match="unknown extra"), optional("plots"):
        pass
    with pytest.raises(TypeError, match="unknown extra"), optional():
        pass


def test_the_extras_are_setup_py_s():
    """setup.py's EXTRAS (distributions) and extras.EXTRAS (the modules they provide) name the
    same extras; the wheel's metadata is checked in test_installed_package.py."""
    text = (ROOT / "setup.py").read_text()
    block = text[text.index("EXTRAS = {"):]
    block = block[: block.index("\n}\n")]
    assert set(re.findall(r'^    "(\w+)":', block, re.M)) == set(EXTRAS)


def _blocked(modules: list[str], argv: list[str], tmp_path: Path) -> subprocess.CompletedProcess:
    """``rls-uncertainty ARGV`` (or ``estimator_node`` for ``["estimator_node"]``) in a child
    process in which ``modules`` cannot be imported."""
    call = "estimator_node()" if argv == ["estimator_node"] else f"main({argv!r})"
    code = (f"import sys\nfor m in {modules!r}: sys.modules[m] = None\n"
            f"from rls_uncertainty.cli import main, estimator_node\nsys.exit({call})")
    return subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120, cwd=tmp_path)


@pytest.mark.parametrize(("modules", "argv", "extra"), [
    (["rclpy"], ["estimator_node"], "ros"),
    (["rclpy"], ["play", str(BAG)], "ros"),
    (["rclpy"], ["status", "--once"], "ros"),
    (["rclpy"], ["reset"], "ros"),
    (["rclpy"], ["dashboard"], "ros"),
    (["aiohttp"], ["dashboard", "--replay", "x"], "dashboard"),
    (["matplotlib"], ["replay", str(BAG), "--config", "t2", "--out", "out"], "figures"),
    (["distributed"], ["campaign", str(BAG), "--scheduler", "tcp://127.0.0.1:9", "--out", "out"], "campaign"),
], ids=lambda v: v if isinstance(v, str) else " ".join(v)[:40])
def test_each_command_names_the_extra_it_misses(modules, argv, extra, tmp_path):
    run = _blocked(modules, argv, tmp_path)
    assert run.returncode == 2, run.stdout + run.stderr
    lines = run.stderr.strip().splitlines()
    assert len(lines) == 1 and f"{modules[0]}" in lines[0] and f"pip install 'rls_uncertainty[{extra}]'" in lines[0], \
        run.stderr
    assert not (tmp_path / "out").exists()  # said before any work
