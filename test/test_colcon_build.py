"""The package builds with colcon as a ROS 2 ament_python package and its executable runs."""

from __future__ import annotations

import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
COLCON = Path(sys.executable).with_name("colcon")


@pytest.mark.skipif(not COLCON.exists(), reason="colcon is installed by scripts/setup.sh")
def test_colcon_build_installs_a_runnable_executable(tmp_path):
    src = tmp_path / "src" / "rls_uncertainty"
    files = subprocess.run(
        ["git", "ls-files", "-co", "--exclude-standard"], cwd=ROOT, capture_output=True, text=True, check=True
    ).stdout.split()
    for rel in files:
        if (ROOT / rel).is_file():
            (src / rel).parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(ROOT / rel, src / rel)
    env = dict(os.environ, PATH=f"{COLCON.parent}{os.pathsep}{os.environ['PATH']}")
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
    assert (tmp_path / "install" / "share" / "ament_index" / "resource_index" / "packages" / "rls_uncertainty").exists() or (
        install / "share" / "ament_index" / "resource_index" / "packages" / "rls_uncertainty"
    ).exists()
    # Start the installed executable from a sourced workspace, outside the source tree.
    run = subprocess.run(
        ["bash", "-c", f"source {tmp_path}/install/setup.bash && {exe} simulate --noise 5 --lags 11"],
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
        ["bash", "-c", f"source {tmp_path}/install/setup.bash && python -c 'import rls_uncertainty; print(rls_uncertainty.__file__)'"],
        cwd=tmp_path, env=env, capture_output=True, text=True, timeout=60,
    )
    assert str(install) in where.stdout, where.stdout + where.stderr
