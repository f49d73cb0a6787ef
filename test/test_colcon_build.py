"""The package builds with colcon as a ROS 2 ament_python package from a plain copy of the
source tree (no .git: a tarball, a `cp -r` into a workspace), its executables run from the
sourced workspace, and `colcon test` works there."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest

from source_tree import copy_source

ROOT = Path(__file__).resolve().parents[1]
COLCON = Path(sys.executable).with_name("colcon")
# Run by `colcon test` in the copy: the manifest check and the flight-data tests, which must
# be skipped there (the copy has no ../shared), plus the skip policy's own tests.
COLCON_TESTS = ["test/test_package_xml.py", "test/test_flight_data.py"]


@pytest.mark.skipif(not COLCON.exists(), reason="colcon is installed by scripts/setup.sh")
def test_colcon_build_and_test_from_a_copy_without_git(tmp_path):
    src = tmp_path / "src" / "rls_uncertainty"
    copy_source(src)
    assert (src / "package.xml").is_file() and (src / "rls_uncertainty").is_dir()
    assert not (src / ".git").exists() and not (src / ".venv").exists()
    # Nothing of the outer run may leak into the workspace's: no flight-data requirement (the
    # copy has no ../shared, so those tests must skip), no pytest options of an outer colcon.
    outer = ("RLS_REQUIRE_FLIGHT_DATA", "RLS_FLIGHT_DATA", "PYTEST_ADDOPTS")
    env = {k: v for k, v in os.environ.items() if k not in outer}
    env["PATH"] = f"{COLCON.parent}{os.pathsep}{os.environ['PATH']}"
    build = subprocess.run(
        [str(COLCON), "build", "--event-handlers", "console_direct-"],
        cwd=tmp_path, env=env, capture_output=True, text=True, timeout=300,
    )
    assert build.returncode == 0, build.stdout + build.stderr
    install = tmp_path / "install" / "rls_uncertainty"
    exe = install / "lib" / "rls_uncertainty" / "rls-uncertainty"
    assert exe.is_file()
    share = install / "share" / "rls_uncertainty"
    assert (share / "package.xml").is_file()
    assert (share / "config" / "aircraft" / "t2.yaml").is_file()
    index = Path("share") / "ament_index" / "resource_index" / "packages" / "rls_uncertainty"
    assert (tmp_path / "install" / index).exists() or (install / index).exists()
    site = list(install.glob("lib/python3*/site-packages/rls_uncertainty"))
    assert len(site) == 1 and (site[0] / "py.typed").is_file(), site
    # Start the installed executable from a sourced workspace, outside the source tree.
    run = subprocess.run(
        ["bash", "-c", f"source {tmp_path}/install/setup.bash && {exe} simulate --noise 5 --lag-span 0.22"],
        cwd=tmp_path, env=env, capture_output=True, text=True, timeout=300,
    )
    assert run.returncode == 0, run.stderr
    assert "Cm_q" in run.stdout and "SE corr." in run.stdout
    # The node's console script: starts from the installed parameter file, stops on SIGINT.
    node_exe = install / "lib" / "rls_uncertainty" / "estimator_node"
    assert node_exe.is_file()
    assert (share / "config" / "t2.yaml").is_file() and (share / "launch" / "estimator.launch.py").is_file()
    assert (share / "msg_schemas" / "fti_msgs" / "msg" / "AirData.msg").is_file()
    log = tmp_path / "node.log"
    with open(log, "w") as fh:
        node = subprocess.Popen(
            ["bash", "-c", f"source {tmp_path}/install/setup.bash && exec {node_exe} --ros-args "
                           f"--params-file {share}/config/t2.yaml"],
            cwd=tmp_path, env=env, stdout=fh, stderr=subprocess.STDOUT,
        )
        deadline = time.monotonic() + 60
        while "estimating CZ(3), Cm(4)" not in log.read_text() and time.monotonic() < deadline and node.poll() is None:
            time.sleep(0.2)
        node.send_signal(signal.SIGINT)
        assert node.wait(30) == 0, log.read_text()
    assert "aircraft T-2" in log.read_text()
    where = subprocess.run(
        ["bash", "-c", f"source {tmp_path}/install/setup.bash && "
                       "python -c 'import rls_uncertainty; print(rls_uncertainty.__file__)'"],
        cwd=tmp_path, env=env, capture_output=True, text=True, timeout=60,
    )
    assert str(install) in where.stdout, where.stdout + where.stderr
    # `colcon test` in the workspace: pytest runs in the copied source directory.
    test = subprocess.run(
        [str(COLCON), "test", "--packages-select", "rls_uncertainty", "--return-code-on-test-failure",
         "--event-handlers", "console_direct-", "--pytest-args", *COLCON_TESTS],
        cwd=tmp_path, env=env, capture_output=True, text=True, timeout=300,
    )
    result = tmp_path / "build" / "rls_uncertainty" / "pytest.xml"
    report = result.read_text() if result.is_file() else "(no pytest.xml)"
    assert test.returncode == 0, test.stdout + test.stderr + report
    suite = ET.parse(result).getroot()
    suite = suite if suite.tag == "testsuite" else suite.find("testsuite")
    assert suite is not None, report
    counts = {k: int(suite.get(k, "0")) for k in ("tests", "failures", "errors", "skipped")}
    assert counts["failures"] == counts["errors"] == 0, report
    skips = [s.get("message", "") for s in suite.iter("skipped")]
    missing = src.parent / "shared" / "flight_data"
    assert len(skips) >= 6 and all(f"flight recordings not found at {missing}" in s for s in skips), skips
    assert counts["tests"] - counts["skipped"] >= 8, counts
