"""package.xml declares what the code imports, and nothing it does not: on a ROS install,
`rosdep install` reads only package.xml, so a missing entry is a node that fails to start on
someone else's machine. No DDS."""

from __future__ import annotations

import ast
import itertools
import re
import sys
import xml.etree.ElementTree as ET
from collections.abc import Collection
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = "rls_uncertainty"
# Installed code: the package and the launch file (ros2 launch imports it).
INSTALLED = ("rls_uncertainty", "launch")
TESTS = "test"

# Import root (or interface package named in a type string such as "sensor_msgs/msg/Imu")
# -> its name in package.xml: a rosdep key from ros/rosdistro rosdep/python.yaml (python3-*)
# or a ROS package of the Jazzy distribution (which rosdep resolves to ros-jazzy-*).
DEPENDENCY = {
    "numpy": "python3-numpy",
    "scipy": "python3-scipy",
    "yaml": "python3-yaml",
    "matplotlib": "python3-matplotlib",
    "pytest": "python3-pytest",
    "statsmodels": "python3-statsmodels",
    "hypothesis": "python3-hypothesis",
    "rclpy": "rclpy",
    "rcl_interfaces": "rcl_interfaces",
    "builtin_interfaces": "builtin_interfaces",
    "std_msgs": "std_msgs",
    "sensor_msgs": "sensor_msgs",
    "geometry_msgs": "geometry_msgs",
    "diagnostic_msgs": "diagnostic_msgs",
    "std_srvs": "std_srvs",
    "rosgraph_msgs": "rosgraph_msgs",
    "ament_index_python": "ament_index_python",
    "launch": "launch",
    "launch_ros": "launch_ros",
    "aiohttp": "python3-aiohttp",
    "tqdm": "python3-tqdm",
}
# Import roots without a rosdep key (checked in rosdep/python.yaml): package.xml cannot
# declare them, so its comments must name them (with the pip command in docs/ros_install.md).
NO_ROSDEP_KEY = {
    "rosbags": "rosbags",
    "mcap": "mcap",
    "distributed": "distributed",
}
# Test-only imports without a rosdep key: named in a package.xml comment and pinned in
# requirements-dev.txt (the tests that use them skip without them, unless told to require them).
TEST_NO_ROSDEP_KEY = {
    "playwright": "playwright",
}
# Roots that are part of this checkout: the package, the bundled fti_msgs schemas (registered
# into rosbags' type store from msg_schemas/, never imported), pytest's conftest.
BUNDLED = {PACKAGE, "fti_msgs", "conftest"}
# exec_depends needed at run time without an import.
USED_WITHOUT_IMPORT = {
    "ros2launch": "provides the `ros2 launch` verb that runs launch/estimator.launch.py",
}

_TYPE_NAME = re.compile(r"^([a-z][a-z0-9_]*)/(?:msg|srv|action)/[A-Z][A-Za-z0-9_]*$")


def references(source: str, type_names: bool = True) -> set[str]:
    """Top-level names of the modules a Python source uses: absolute imports, constant
    importlib.import_module() arguments, and (with ``type_names``) ROS interface type names
    ("pkg/msg/Name", which the package imports on demand or resolves in a bag type store)."""
    found: set[str] = set()
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Import):
            found.update(alias.name.split(".")[0] for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            found.add(node.module.split(".")[0])
        elif (
            isinstance(node, ast.Call)
            and isinstance(node.func, ast.Attribute)
            and node.func.attr == "import_module"
            and node.args
            and isinstance(node.args[0], ast.Constant)
            and isinstance(node.args[0].value, str)
        ):
            found.add(node.args[0].value.split(".")[0])
        elif type_names and isinstance(node, ast.Constant) and isinstance(node.value, str):
            match = _TYPE_NAME.match(node.value)
            if match:
                found.add(match.group(1))
    return found


def third_party(dirs: tuple[str, ...], local: Collection[str] = (), type_names: bool = True) -> dict[str, list[str]]:
    """Third-party roots referenced under ``dirs`` -> the files that reference them."""
    out: dict[str, list[str]] = {}
    for d in dirs:
        for path in sorted((ROOT / d).rglob("*.py")):
            for root in references(path.read_text(encoding="utf-8"), type_names):
                if root in sys.stdlib_module_names or root == "__future__" or root in BUNDLED or root in local:
                    continue
                out.setdefault(root, []).append(str(path.relative_to(ROOT)))
    return out


def manifest() -> tuple[ET.Element, str]:
    """package.xml's root element and the text of all its comments."""
    parser = ET.XMLParser(target=ET.TreeBuilder(insert_comments=True))
    root = ET.parse(ROOT / "package.xml", parser).getroot()
    comments = " ".join(el.text or "" for el in root.iter() if el.tag is ET.Comment)
    return root, comments


def declared(root: ET.Element, *tags: str) -> set[str]:
    return {(el.text or "").strip() for tag in tags for el in root.findall(tag)}


def _missing(roots: dict[str, list[str]], allowed: set[str], comments: str, tag: str) -> list[str]:
    problems = []
    for name, files in sorted(roots.items()):
        where = ", ".join(files)
        if name in NO_ROSDEP_KEY:
            if NO_ROSDEP_KEY[name] not in comments:
                problems.append(
                    f"{name} ({where}) has no rosdep key: name it in a package.xml comment and document "
                    "its pip install in docs/ros_install.md"
                )
        elif name not in DEPENDENCY:
            problems.append(
                f"unmapped import {name!r} ({where}): add it to DEPENDENCY in test/test_package_xml.py with its "
                f"rosdep key (ros/rosdistro rosdep/python.yaml, e.g. python3-{name}) or ROS package name, and "
                f"<{tag}>KEY</{tag}> to package.xml; if no key exists, add it to NO_ROSDEP_KEY instead and "
                "name it in a package.xml comment"
            )
        elif DEPENDENCY[name] not in allowed:
            problems.append(f"{name} ({where}): add <{tag}>{DEPENDENCY[name]}</{tag}> to package.xml")
    return problems


def test_manifest_names_the_package_and_its_build_type():
    root, _ = manifest()
    assert root.get("format") == "3"
    assert root.findtext("name") == PACKAGE
    assert root.findtext("export/build_type") == "ament_python"
    assert (ROOT / "resource" / PACKAGE).is_file()


def test_every_third_party_import_of_the_installed_code_is_an_exec_depend():
    root, comments = manifest()
    run = declared(root, "exec_depend", "depend")
    problems = _missing(third_party(INSTALLED), run, comments, "exec_depend")
    assert not problems, "package.xml misses run-time dependencies:\n  " + "\n  ".join(problems)


def test_every_third_party_import_of_the_tests_is_declared():
    root, comments = manifest()
    local = {p.stem for p in (ROOT / TESTS).glob("*.py")}
    run_or_test = declared(root, "exec_depend", "depend", "test_depend")
    # Imports only: the tests make up interface types of their own (bags of invented messages).
    roots = third_party((TESTS,), local, type_names=False)
    problems = []
    for name, key in TEST_NO_ROSDEP_KEY.items():
        roots.pop(name, None)
        dev = (ROOT / "requirements-dev.txt").read_text(encoding="utf-8")
        if key not in comments or not re.search(rf"^{re.escape(key)}\b", dev, re.M):
            problems.append(f"{name} has no rosdep key: name it in a package.xml comment and in requirements-dev.txt")
    problems += _missing(roots, run_or_test, comments, "test_depend")
    assert not problems, "package.xml misses test dependencies:\n  " + "\n  ".join(problems)


def test_every_declared_dependency_is_used():
    root, _ = manifest()
    installed = {DEPENDENCY.get(name) for name in third_party(INSTALLED)}
    local = {p.stem for p in (ROOT / TESTS).glob("*.py")}
    tested = {DEPENDENCY.get(name) for name in third_party((TESTS,), local, type_names=False)}
    unused = sorted(declared(root, "exec_depend", "depend") - installed - set(USED_WITHOUT_IMPORT))
    assert not unused, (
        f"exec_depend entries that nothing in {', '.join(INSTALLED)} imports: {unused}; remove them, or list "
        "them in USED_WITHOUT_IMPORT in test/test_package_xml.py with the reason"
    )
    unused_test = sorted(declared(root, "test_depend") - tested - installed)
    assert not unused_test, f"test_depend entries that no test imports: {unused_test}"


def test_packages_without_rosdep_key_are_the_pip_requirements():
    requirements = (ROOT / "requirements.txt").read_text(encoding="utf-8")
    for name in NO_ROSDEP_KEY.values():
        assert re.search(rf"^{re.escape(name)}\b", requirements, re.M), f"{name} missing from requirements.txt"
        assert name in (ROOT / "docs" / "ros_install.md").read_text(encoding="utf-8")


def test_references_cover_imports_import_module_and_interface_type_names():
    source = """
import os, numpy.linalg
from yaml import safe_load
from . import sibling
from .aero import x
import importlib
importlib.import_module("std_srvs.srv")
TYPES = {"imu": "sensor_msgs/msg/Imu", "srv": "example_interfaces/srv/AddTwoInts", "doc": "not/a/Type name"}
"""
    assert references(source) == {"os", "numpy", "yaml", "importlib", "std_srvs", "sensor_msgs", "example_interfaces"}
    assert references(source, type_names=False) == {"os", "numpy", "yaml", "importlib", "std_srvs"}


def test_the_version_is_written_once_in_package_xml():
    """setup.py reads package.xml's version, and the installed package carries it (what
    `rls-uncertainty --version` prints)."""
    from importlib.metadata import version

    written = ET.parse(ROOT / "package.xml").getroot().findtext("version")
    assert re.fullmatch(r"\d+\.\d+\.\d+", written)
    setup_py = (ROOT / "setup.py").read_text()
    assert "version=VERSION" in setup_py and written not in setup_py
    assert version(PACKAGE) == written


def _requirements(path: Path) -> list[str]:
    lines = (line.split("#", 1)[0].strip() for line in path.read_text(encoding="utf-8").splitlines())
    return [line for line in lines if line and not line.startswith("-")]


def _canonical(name: str) -> str:
    return re.sub(r"[-_.]+", "-", name).lower()  # PEP 503


def _release(version: str) -> tuple[int, ...]:
    return tuple(int(x) for x in version.split("."))


_COMPARE = {"==": tuple.__eq__, "!=": tuple.__ne__, ">=": tuple.__ge__, "<=": tuple.__le__, ">": tuple.__gt__,
            "<": tuple.__lt__}


def test_the_constraints_pin_every_requirement_within_its_range():
    """scripts/setup.sh installs constraints.txt's exact versions by default: each requirement of
    requirements*.txt is pinned there, to a version its range accepts (every version here is
    numeric: compared as tuples of integers)."""
    pins = {}
    for line in _requirements(ROOT / "constraints.txt"):
        name, sep, version = line.partition("==")
        assert sep and re.fullmatch(r"\d+(\.\d+)*", version), f"constraints.txt: {line!r} is not NAME==VERSION"
        pins[_canonical(name)] = _release(version)
    for path in (ROOT / "requirements.txt", ROOT / "requirements-dev.txt"):
        for line in _requirements(path):
            name = re.match(r"[A-Za-z0-9_.-]+", line).group(0)
            pinned = pins.get(_canonical(name))
            assert pinned is not None, f"{name} ({path.name}) is not pinned in constraints.txt"
            for op, version in re.findall(r"(==|!=|>=|<=|>|<)\s*([0-9.]+)", line[len(name):]):
                assert _COMPARE[op](pinned, _release(version)), f"{name} pinned to {pinned}, outside {line!r}"


def test_the_license_file_is_the_one_package_xml_declares():
    root, _ = manifest()
    assert root.findtext("license") == "Apache-2.0"
    text = (ROOT / "LICENSE").read_text(encoding="utf-8")
    assert text.split()[:4] == ["Apache", "License", "Version", "2.0,"] and "END OF TERMS AND CONDITIONS" in text


def test_the_changelog_is_in_the_ros_format_and_names_this_version():
    """catkin_generate_changelog's layout: the title, then 'Forthcoming' and 'X.Y.Z (YYYY-MM-DD)'
    sections, each underlined, with bullets; the newest release is package.xml's version."""
    root, _ = manifest()
    lines = (ROOT / "CHANGELOG.rst").read_text(encoding="utf-8").splitlines()
    assert lines[1] == f"Changelog for package {PACKAGE}" and set(lines[0]) == set(lines[2]) == {"^"}
    headings = [line for line, under in itertools.pairwise(lines)
                if under and set(under) == {"-"} and len(under) == len(line)]
    assert headings[0] == "Forthcoming"
    releases = headings[1:]
    assert all(re.fullmatch(r"\d+\.\d+\.\d+ \(\d{4}-\d{2}-\d{2}\)", h) for h in releases), releases
    assert releases[0].split()[0] == root.findtext("version")
