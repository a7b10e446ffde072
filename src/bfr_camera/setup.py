"""Build description of the ament_python package ``bfr_camera``.

The node executables are the scripts in ``scripts/``, installed into ``lib/bfr_camera/``
(``ros2 run bfr_camera <executable>`` finds them), not console scripts: their first line
makes SIGINT quiet before any import (bfr_ros.startup). Console scripts (the ``bfr``
command) go to the same folder (setup.cfg). Files in ``config/`` and ``launch/`` are
globbed into ``share/bfr_camera/``: new files there are installed without editing this file.
"""

from glob import glob

from setuptools import find_packages, setup

package_name = "bfr_camera"

setup(
    name=package_name,
    version="0.2.0",
    packages=find_packages(exclude=["test", "test.*"]),
    data_files=[
        ("share/ament_index/resource_index/packages", ["resource/" + package_name]),
        ("share/" + package_name, ["package.xml"]),
        ("share/" + package_name + "/config",
         sorted(glob("config/*.yaml") + glob("config/*.json"))),
        ("share/" + package_name + "/launch", sorted(glob("launch/*.py") + glob("launch/*.xml"))),
        # The node executables: scripts whose first line makes SIGINT quiet
        # (bfr_ros.startup), installed as lib/<package>/<executable> for ros2 run.
        ("lib/" + package_name, sorted(glob("scripts/*"))),
    ],
    install_requires=["setuptools"],
    zip_safe=True,
    maintainer="bfr developers",
    maintainer_email="bfr@example.org",
    description=(
        "Camera model and calibration, the ball detector and the camera node of the bfr "
        "Butterfly robot node suite."
    ),
    license="Apache-2.0",
    entry_points={
        "console_scripts": [
            # "<executable> = bfr_camera.<module>:main",  -> lib/bfr_camera/<executable>
        ],
    },
)
