"""The launch file for ROS installs."""

from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def test_launch_file_is_valid_python():
    import py_compile

    py_compile.compile(str(ROOT / "launch" / "estimator.launch.py"), doraise=True)
