"""ament_python package: rls_uncertainty. Built by colcon (ROS) and by pip (a wheel).

Written once elsewhere and read here: the version and the maintainer (package.xml, the ROS
convention), the dependencies' version ranges (requirements.txt). A wheel carries its data as
package data under ``rls_uncertainty/share`` (the layout of the ROS share directory: config/,
msg_schemas/, the bundled bag, package.xml), found by ``settings.models.package_path`` without a
source tree or a ROS environment, and the dashboard's uPlot files, installed from the npm
registry at build time (package-lock.json's version and hash; never committed, never from a CDN).
"""

import hashlib
import os
import re
import shutil
import subprocess
import tempfile
from glob import glob
from pathlib import Path
from xml.etree import ElementTree

from setuptools import find_packages, setup
from setuptools.command.build_py import build_py

PACKAGE = "rls_uncertainty"
HERE = Path(__file__).resolve().parent
MANIFEST = ElementTree.parse(HERE / "package.xml").getroot()
# `rls-uncertainty --version` prints it from the installed metadata.
VERSION = MANIFEST.findtext("version")
MAINTAINER = MANIFEST.find("maintainer")
URLS = {u.get("type", "website"): (u.text or "").strip() for u in MANIFEST.findall("url")}

# The optional parts, each an extra: requirements.txt's names (their ranges are read from there).
# rls_uncertainty/extras.py maps each extra to the modules it provides, for the one-line error
# when one is missing; test/test_installed_package.py checks that both agree.
EXTRAS = {
    "ros": ("ros-jazzy-rclpy", "ros-jazzy-common-interfaces", "ros-jazzy-rmw-fastrtps-cpp"),
    "figures": ("matplotlib",),
    "dashboard": ("aiohttp",),
    "campaign": ("distributed",),
}
# The share directory's data that the package reads at run time (settings.models.package_path).
SHARE = ("package.xml", "config", "msg_schemas", "bags/t2_maneuver")
# The dashboard's third-party files (dashboard/server.py serves them from here).
UPLOT = "dashboard/node_modules/uplot"
UPLOT_FILES = ("LICENSE", "dist/uPlot.iife.min.js", "dist/uPlot.min.css")


def requirements() -> dict[str, str]:
    """requirements.txt's lines by distribution name (PEP 503 normalized)."""
    out = {}
    for raw in (HERE / "requirements.txt").read_text().splitlines():
        line = raw.split("#", 1)[0].strip()
        if line and not line.startswith("-"):
            name = re.match(r"[A-Za-z0-9_.-]+", line).group(0)
            out[re.sub(r"[-_.]+", "-", name).lower()] = line
    return out


def dependencies() -> tuple[list[str], dict[str, list[str]]]:
    """install_requires and extras_require: every line of requirements.txt is in exactly one."""
    lines = requirements()
    extras = {extra: [lines.pop(name) for name in names] for extra, names in EXTRAS.items()}
    extras["all"] = sorted({line for group in extras.values() for line in group})
    return sorted(lines.values()), extras


class BuildWithData(build_py):
    """build_py, then the share data and uPlot into the built package (not for an editable
    install, which reads the source tree's)."""

    def run(self) -> None:
        super().run()
        if getattr(self, "editable_mode", False):
            return
        package = Path(self.build_lib) / PACKAGE
        for item in SHARE:
            source, target = HERE / item, package / "share" / item
            if source.is_dir():
                shutil.copytree(source, target, dirs_exist_ok=True, ignore=shutil.ignore_patterns("__pycache__"))
            else:
                target.parent.mkdir(parents=True, exist_ok=True)
                shutil.copy2(source, target)
        self._uplot(package / UPLOT)

    def _uplot(self, target: Path) -> None:
        if os.environ.get("RLS_BUILD_WITHOUT_DASHBOARD_ASSETS") == "1":
            return  # the dashboard then names the missing files and refuses to start
        dashboard = HERE / PACKAGE / "dashboard"
        lock = (dashboard / "package-lock.json").read_text()
        source = dashboard / "node_modules" / "uplot"
        stamp = dashboard / "node_modules" / ".rls_installed"
        want = hashlib.sha256(lock.encode()).hexdigest()
        if not (stamp.is_file() and stamp.read_text().strip() == want
                and all((source / f).is_file() for f in UPLOT_FILES)):
            source = self._npm_ci(dashboard)
        for name in UPLOT_FILES:
            (target / name).parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(source / name, target / name)

    def _npm_ci(self, dashboard: Path) -> Path:
        """uPlot from the npm registry at package-lock.json's version and integrity hash, in a
        build directory (the source tree is left as it is)."""
        npm = shutil.which("npm")
        if npm is None:
            raise SystemExit("rls_uncertainty build: the dashboard's uPlot comes from the npm registry and npm was "
                             "not found: install npm (apt-get install npm), or build without the dashboard's "
                             "assets with RLS_BUILD_WITHOUT_DASHBOARD_ASSETS=1")
        temp = Path(self.get_finalized_command("build").build_temp)
        temp.mkdir(parents=True, exist_ok=True)
        work = Path(tempfile.mkdtemp(prefix="uplot_", dir=temp))
        for name in ("package.json", "package-lock.json"):
            shutil.copy2(dashboard / name, work / name)
        subprocess.run([npm, "ci", "--ignore-scripts", "--no-audit", "--no-fund", "--omit=dev", "--loglevel=error"],
                       cwd=work, check=True)
        return work / "node_modules" / "uplot"


INSTALL_REQUIRES, EXTRAS_REQUIRE = dependencies()

setup(
    name=PACKAGE,
    version=VERSION,
    description="Recursive least squares with colored-residual parameter uncertainty.",
    long_description=(HERE / "README.md").read_text(encoding="utf-8"),
    long_description_content_type="text/markdown",
    author=MAINTAINER.text.strip(),
    author_email=MAINTAINER.get("email"),
    maintainer=MAINTAINER.text.strip(),
    maintainer_email=MAINTAINER.get("email"),
    url=URLS.get("website"),
    project_urls={k.capitalize(): v for k, v in URLS.items() if k != "website"},
    license=MANIFEST.findtext("license"),
    classifiers=[
        "Development Status :: 4 - Beta",
        "Intended Audience :: Science/Research",
        "License :: OSI Approved :: Apache Software License",
        "Operating System :: POSIX :: Linux",
        "Programming Language :: Python :: 3",
        "Programming Language :: Python :: 3 :: Only",
        "Programming Language :: Python :: 3.11",
        "Programming Language :: Python :: 3.12",
        "Topic :: Scientific/Engineering :: Physics",
        "Typing :: Typed",
    ],
    keywords=["recursive least squares", "parameter estimation", "aircraft", "system identification", "ROS 2"],
    python_requires=">=3.11",
    packages=find_packages(exclude=["test", "test.*"]),
    cmdclass={"build_py": BuildWithData},
    data_files=[
        ("share/ament_index/resource_index/packages", [f"resource/{PACKAGE}"]),
        (f"share/{PACKAGE}", ["package.xml"]),
        (f"share/{PACKAGE}/config", glob("config/*.yaml")),
        (f"share/{PACKAGE}/config/aircraft", glob("config/aircraft/*.yaml")),
        (f"share/{PACKAGE}/launch", glob("launch/*.py")),
        (f"share/{PACKAGE}/layouts", glob("layouts/*")),
        (f"share/{PACKAGE}/bags/t2_maneuver", glob("bags/t2_maneuver/*")),
        (f"share/{PACKAGE}/msg_schemas/fti_msgs", glob("msg_schemas/fti_msgs/*.yaml")),
        (f"share/{PACKAGE}/msg_schemas/fti_msgs/msg", glob("msg_schemas/fti_msgs/msg/*.msg")),
    ],
    # py.typed: the package ships its annotations (PEP 561) to mypy users of rls_uncertainty.
    # The dashboard's page; uPlot's files and the share data are added by BuildWithData.
    package_data={PACKAGE: ["py.typed", "ros/fastdds_player.xml", "dashboard/static/*"]},
    install_requires=INSTALL_REQUIRES,
    extras_require=EXTRAS_REQUIRE,
    zip_safe=False,
    tests_require=["pytest"],
    entry_points={
        "console_scripts": [
            "rls-uncertainty = rls_uncertainty.cli:main",
            "estimator_node = rls_uncertainty.cli:estimator_node",
        ],
    },
)
