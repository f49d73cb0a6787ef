"""The launch file for ROS installs. ``launch`` and ``launch_ros`` are not installable from the
package index, so the file runs here against stand-ins that record what it builds (the names
and signatures of launch's public API that it uses); on a ROS install `ros2 launch` runs it.
Checked: the four arguments with their defaults, and the node they configure (executable, name,
namespace, log level, parameter file, use_sim_time)."""

from __future__ import annotations

import importlib.util
import sys
import types
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
LAUNCH_FILE = ROOT / "launch" / "estimator.launch.py"


class _Recorded:
    def __init__(self, *args, **kwargs) -> None:
        self.args, self.kwargs = args, kwargs


class LaunchConfiguration(_Recorded):
    @property
    def name(self) -> str:
        return self.args[0]


def _stand_ins(monkeypatch) -> None:
    def module(name: str, **attrs) -> None:
        m = types.ModuleType(name)
        m.__dict__.update(attrs)
        monkeypatch.setitem(sys.modules, name, m)

    module("launch")
    module("launch.actions", DeclareLaunchArgument=type("DeclareLaunchArgument", (_Recorded,), {}))
    module("launch.launch_description", LaunchDescription=type("LaunchDescription", (_Recorded,), {}))
    module("launch.substitutions", LaunchConfiguration=LaunchConfiguration)
    module("launch_ros")
    module("launch_ros.actions", Node=type("Node", (_Recorded,), {}))
    module("ament_index_python")
    module("ament_index_python.packages", get_package_share_directory=lambda pkg: f"/opt/share/{pkg}")


def _description(monkeypatch):
    _stand_ins(monkeypatch)
    spec = importlib.util.spec_from_file_location("estimator_launch", LAUNCH_FILE)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module.generate_launch_description()


def test_the_launch_file_declares_namespace_log_level_params_file_and_use_sim_time(monkeypatch):
    (entities,) = _description(monkeypatch).args
    declared = {e.args[0]: e.kwargs["default_value"] for e in entities if type(e).__name__ == "DeclareLaunchArgument"}
    assert declared == {"namespace": "", "log_level": "info",
                        "params_file": "/opt/share/rls_uncertainty/config/t2.yaml", "use_sim_time": "false"}
    assert all(e.kwargs.get("description") for e in entities if type(e).__name__ == "DeclareLaunchArgument")


def test_the_node_takes_every_argument(monkeypatch):
    (entities,) = _description(monkeypatch).args
    (node,) = [e for e in entities if type(e).__name__ == "Node"]
    kw = node.kwargs
    assert (kw["package"], kw["executable"], kw["name"]) == ("rls_uncertainty", "estimator_node", "rls_estimator")
    assert kw["namespace"].name == "namespace"
    flag, level = kw["ros_arguments"]
    assert flag == "--log-level" and level.name == "log_level"
    params_file, overrides = kw["parameters"]
    assert params_file.name == "params_file" and overrides["use_sim_time"].name == "use_sim_time"
    # every declared argument is used by the node
    declared = {e.args[0] for e in entities if type(e).__name__ == "DeclareLaunchArgument"}
    used = {kw["namespace"].name, level.name, params_file.name, overrides["use_sim_time"].name}
    assert used == declared


def test_the_node_name_is_the_one_the_package_uses():
    from rls_uncertainty.settings import NODE_NAME

    assert f'name="{NODE_NAME}"' in LAUNCH_FILE.read_text()
