"""Build description of the ament_python package ``bfr_model``.

Executables are console scripts installed into ``lib/bfr_model/`` (see setup.cfg), so
``ros2 run bfr_model <executable>`` finds them. Files in ``config/`` and ``launch/`` are
globbed into ``share/bfr_model/``: new files there are installed without editing this file.
"""

from glob import glob

from setuptools import find_packages, setup

package_name = "bfr_model"

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
        # Keep lib/<package>/ present even before the package registers an executable.
        ("lib/" + package_name, []),
    ],
    install_requires=["setuptools"],
    zip_safe=True,
    maintainer="bfr developers",
    maintainer_email="bfr@example.org",
    description=(
        "The model of the Butterfly robot rig, pure numpy (no rclpy): parameters and "
        "parameter files, exact geometry, rigid dynamics, integrators, perturbations, the "
        "force-based contact model, recordings and their readers and writers (rig logs, CSV, "
        "ROS 2 bags)."
    ),
    license="Apache-2.0",
    entry_points={
        "console_scripts": [
            # "<executable> = bfr_model.<module>:main",  -> lib/bfr_model/<executable>

        ],
    },
)
