"""The package as pip installs it: a wheel built from a plain copy of the source tree, installed
into fresh virtual environments outside the checkout, run from there with no source tree, no
PYTHONPATH and no ROS environment (AMENT_PREFIX_PATH unset).

* The wheel: the data the commands read (config/, msg_schemas/, the bundled bag, package.xml) and
  the dashboard's uPlot files are in it; its metadata names the version of package.xml, the
  dependencies of requirements.txt (the optional ones under their extra) and the rest.
* Without extras (a venv with only the base dependencies, installed by pip from the index at
  constraints.txt's versions): ``replay --no-figures`` of the bundled bag works, and every
  command that needs an extra says in one line which one, exit status 2.
* With every extra: a venv that sees the project's own environment (as ``--system-site-packages``
  would, through a .pth file: installing the ROS stack again would take minutes) runs
  ``estimator_node`` on its installed parameter file, ``replay`` of the bundled bag with its
  figures and ``dashboard --replay`` serving the page and uPlot.
"""

from __future__ import annotations

import email.parser
import os
import re
import subprocess
import sys
import sysconfig
import time
import urllib.request
import zipfile
from pathlib import Path

import pytest

from rls_uncertainty.extras import EXTRAS
from rls_uncertainty.ros.player import stop_process

from source_tree import copy_source

ROOT = Path(__file__).resolve().parents[1]
VERSION = re.search(r"<version>(.+)</version>", (ROOT / "package.xml").read_text()).group(1)
BAG = "rls_uncertainty/share/bags/t2_maneuver"
DATA = ["rls_uncertainty/share/package.xml", "rls_uncertainty/share/config/t2.yaml",
        "rls_uncertainty/share/config/aircraft/t2.yaml", "rls_uncertainty/share/msg_schemas/fti_msgs/mapping.yaml",
        "rls_uncertainty/share/msg_schemas/fti_msgs/msg/AirData.msg", f"{BAG}/metadata.yaml",
        f"{BAG}/t2_maneuver.mcap", "rls_uncertainty/dashboard/static/index.html",
        "rls_uncertainty/dashboard/node_modules/uplot/dist/uPlot.iife.min.js",
        "rls_uncertainty/dashboard/node_modules/uplot/dist/uPlot.min.css",
        "rls_uncertainty/dashboard/node_modules/uplot/LICENSE", "rls_uncertainty/py.typed"]
# The environment of every command run from an installed package: nothing of the checkout's.
OUTSIDE = ("PYTHONPATH", "AMENT_PREFIX_PATH", "COLCON_PREFIX_PATH", "PYTEST_ADDOPTS", "VIRTUAL_ENV")


def _run(cmd: list[str], cwd: Path, env: dict[str, str], timeout: float = 300) -> subprocess.CompletedProcess:
    return subprocess.run(cmd, cwd=cwd, env=env, capture_output=True, text=True, timeout=timeout)


def _clean_env() -> dict[str, str]:
    env = {k: v for k, v in os.environ.items() if k not in OUTSIDE}
    env["PIP_DISABLE_PIP_VERSION_CHECK"] = "1"
    return env


@pytest.fixture(scope="module")
def wheel(tmp_path_factory) -> Path:
    """The wheel pip builds from a copy of the checkout (its own build directories stay in the copy)."""
    work = tmp_path_factory.mktemp("wheel")
    copy_source(work / "src")
    build = _run([sys.executable, "-m", "pip", "wheel", "--no-deps", "-w", str(work / "dist"), str(work / "src")],
                 work, _clean_env(), timeout=600)
    assert build.returncode == 0, build.stdout[-3000:] + build.stderr[-3000:]
    wheels = list((work / "dist").glob("rls_uncertainty-*.whl"))
    assert len(wheels) == 1, wheels
    return wheels[0]


def _venv(path: Path) -> Path:
    """A new virtual environment (of the interpreter the project's .venv was made from)."""
    base = Path(getattr(sys, "_base_executable", sys.executable))
    made = _run([str(base), "-m", "venv", str(path)], path.parent, _clean_env())
    assert made.returncode == 0, made.stderr
    return path / "bin"


def test_the_wheel_holds_the_data_and_the_metadata(wheel):
    with zipfile.ZipFile(wheel) as zf:
        names = set(zf.namelist())
        metadata = email.parser.Parser().parsestr(zf.read(f"rls_uncertainty-{VERSION}.dist-info/METADATA").decode())
        entry_points = zf.read(f"rls_uncertainty-{VERSION}.dist-info/entry_points.txt").decode()
    assert wheel.name.startswith(f"rls_uncertainty-{VERSION}-")
    missing = [name for name in DATA if name not in names]
    assert not missing, missing
    assert not any("node_modules/.package-lock" in n or n.endswith("package.json") for n in names)
    assert metadata["Version"] == VERSION and metadata["Requires-Python"] == ">=3.11"
    assert metadata["License"] == "Apache-2.0" and metadata["Author"] and metadata["Author-email"]
    assert "License :: OSI Approved :: Apache Software License" in metadata.get_all("Classifier")
    assert "rls_uncertainty" in metadata.get_payload()  # the README as the long description
    assert set(metadata.get_all("Provides-Extra")) == {*EXTRAS, "all"}
    # Every line of requirements.txt is a requirement: the extras' under their marker.
    requires = [r.replace(" ", "") for r in metadata.get_all("Requires-Dist")]
    lines = [line.split("#", 1)[0].strip() for line in (ROOT / "requirements.txt").read_text().splitlines()]
    for line in filter(None, lines):
        name, spec = re.match(r"([A-Za-z0-9_.-]+)(.*)", line).groups()
        ranges = sorted(spec.replace(" ", "").split(","))
        assert any(r.startswith(name) and sorted(r[len(name):].split(";")[0].split(",")) == ranges for r in requires), \
            (line, requires)
    assert "estimator_node = rls_uncertainty.cli:estimator_node" in entry_points
    assert "rls-uncertainty = rls_uncertainty.cli:main" in entry_points


def test_without_extras_replay_works_and_every_extra_is_named(wheel, tmp_path):
    bin_dir = _venv(tmp_path / "venv")
    env = _clean_env()
    install = _run([str(bin_dir / "python"), "-m", "pip", "install", "--quiet", "-c", str(ROOT / "constraints.txt"),
                    str(wheel)], tmp_path, env, timeout=900)
    assert install.returncode == 0, install.stdout[-3000:] + install.stderr[-3000:]
    cli = str(bin_dir / "rls-uncertainty")
    version = _run([cli, "--version"], tmp_path, env)
    assert version.stdout.strip() == f"rls-uncertainty {VERSION}", version.stdout + version.stderr
    site = Path(_run([str(bin_dir / "python"), "-c", "import rls_uncertainty; print(rls_uncertainty.__file__)"],
                     tmp_path, env).stdout.strip()).parent
    assert site.is_relative_to(tmp_path / "venv"), site
    replay = _run([cli, "replay", str(site / "share/bags/t2_maneuver"), "--config", "t2", "--out", "out",
                   "--no-figures"], tmp_path, env)
    assert replay.returncode == 0, replay.stderr
    assert "599 samples formed, 591 used" in replay.stdout and (tmp_path / "out" / "estimates.mcap").is_file()
    needs = {
        "ros": [[str(bin_dir / "estimator_node")], [cli, "demo"], [cli, "status", "--once"]],
        "figures": [[cli, "replay", str(site / "share/bags/t2_maneuver"), "--config", "t2", "--out", "fig"]],
        "dashboard": [[cli, "dashboard", "--replay", "out"]],
        "campaign": [[cli, "campaign", "out", "--scheduler", "tcp://127.0.0.1:9", "--out", "c", "--no-figures"]],
    }
    for extra, commands in needs.items():
        for cmd in commands:
            run = _run(cmd, tmp_path, env)
            assert run.returncode == 2, (cmd, run.stdout, run.stderr)
            lines = run.stderr.strip().splitlines()
            assert len(lines) == 1 and f"pip install 'rls_uncertainty[{extra}]'" in lines[0], (cmd, run.stderr)
    assert not (tmp_path / "fig").exists() and not (tmp_path / "c").exists()


def _project_env(bin_dir: Path) -> dict[str, str]:
    """The project's environment seen from the venv of ``bin_dir`` through a .pth file (after
    the venv's own site-packages, where the wheel is), with the ROS wheels' libraries on the
    loader's path as their bootstrapper would set them."""
    project_site = Path(sysconfig.get_paths()["purelib"])
    venv_site = next(bin_dir.parent.glob("lib/python3*/site-packages"))
    (venv_site / "project_environment.pth").write_text(f"{project_site}\n")
    env = _clean_env()
    libs = [str(p) for p in sorted(project_site.glob("ros_*.libs")) if p.is_dir()]
    libs.append(str(Path(sys.prefix) / "lib"))
    env["LD_LIBRARY_PATH"] = os.pathsep.join([*libs, env.get("LD_LIBRARY_PATH", "")]).rstrip(os.pathsep)
    env["_ROS_WHEELS_BOOTSTRAP_COMPLETE"] = "1"
    env["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
    return env


def _wait_for(path: Path, text: str, proc: subprocess.Popen, seconds: float = 90) -> bool:
    deadline = time.monotonic() + seconds
    while time.monotonic() < deadline and proc.poll() is None:
        if text in path.read_text():
            return True
        time.sleep(0.2)
    return text in path.read_text()


def test_with_every_extra_the_node_replay_and_dashboard_run(wheel, tmp_path):
    bin_dir = _venv(tmp_path / "venv")
    env = _project_env(bin_dir)
    # Every requirement of [all] is met by what the venv sees (no index: nothing downloaded).
    install = _run([str(bin_dir / "python"), "-m", "pip", "install", "--no-index", f"{wheel}[all]"], tmp_path, env)
    assert install.returncode == 0, install.stdout[-3000:] + install.stderr[-3000:]
    where = _run([str(bin_dir / "python"), "-c", "import rls_uncertainty; from rls_uncertainty.settings import "
                  "config_dir; print(rls_uncertainty.__file__); print(config_dir())"], tmp_path, env)
    package, config = (Path(p) for p in where.stdout.split())
    assert package.is_relative_to(tmp_path / "venv") and config == package.parent / "share" / "config", where.stdout
    bag = package.parent / "share" / "bags" / "t2_maneuver"

    log = tmp_path / "node.log"
    with open(log, "w") as fh:
        node = subprocess.Popen([str(bin_dir / "estimator_node"), "--ros-args", "--params-file",
                                 str(config / "t2.yaml")], cwd=tmp_path, env=env, stdout=fh, stderr=subprocess.STDOUT)
        try:
            started = _wait_for(log, "estimating CZ(3), Cm(4)", node)
        finally:
            stopped = stop_process(node, timeout=30)
    assert started and stopped and node.returncode == 0, log.read_text()
    assert "aircraft T-2" in log.read_text()

    replay = _run([str(bin_dir / "rls-uncertainty"), "replay", str(bag), "--config", "t2", "--out", "out",
                   "--dpi", "50"], tmp_path, env)
    assert replay.returncode == 0, replay.stderr
    assert "599 samples formed, 591 used" in replay.stdout
    assert (tmp_path / "out" / "Cm_estimates.png").is_file() and (tmp_path / "out" / "CZ_fit.png").is_file()

    log = tmp_path / "dashboard.log"
    with open(log, "w") as fh:
        page = subprocess.Popen([str(bin_dir / "rls-uncertainty"), "dashboard", "--replay", "out", "--port", "0"],
                                cwd=tmp_path, env=env, stdout=fh, stderr=subprocess.STDOUT)
        try:
            assert _wait_for(log, "serving http://", page), log.read_text()
            url = re.search(r"serving (http://\S+/)", log.read_text()).group(1)
            with urllib.request.urlopen(url, timeout=30) as response:
                assert response.status == 200 and b"uPlot" in response.read()
            with urllib.request.urlopen(url + "static/uPlot.iife.min.js", timeout=30) as response:
                assert response.status == 200 and len(response.read()) > 10_000
        finally:
            stop_process(page, timeout=30)
