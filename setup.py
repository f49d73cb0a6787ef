"""ament_python package: rls_uncertainty."""

from glob import glob
from pathlib import Path
from xml.etree import ElementTree

from setuptools import find_packages, setup

PACKAGE = "rls_uncertainty"
# The version is written once, in package.xml (the ROS convention); `rls-uncertainty --version`
# prints it from the installed metadata.
VERSION = ElementTree.parse(Path(__file__).resolve().parent / "package.xml").getroot().findtext("version")

setup(
    name=PACKAGE,
    version=VERSION,
    packages=find_packages(exclude=["test", "test.*"]),
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
    # The dashboard's page, and uPlot's files once scripts/setup_dashboard.sh has installed them.
    package_data={PACKAGE: ["py.typed", "ros/fastdds_player.xml", "dashboard/static/*",
                            "dashboard/node_modules/uplot/LICENSE", "dashboard/node_modules/uplot/dist/uPlot.*.css",
                            "dashboard/node_modules/uplot/dist/uPlot.iife.min.js"]},
    install_requires=["setuptools", "numpy", "scipy", "pyyaml"],
    zip_safe=True,
    maintainer="rls_uncertainty developers",
    maintainer_email="dev@rls-uncertainty.local",
    description="Recursive least squares with colored-residual parameter uncertainty.",
    license="Apache-2.0",
    tests_require=["pytest"],
    entry_points={
        "console_scripts": [
            "rls-uncertainty = rls_uncertainty.cli:main",
            "estimator_node = rls_uncertainty.ros.node:main",
        ],
    },
)
