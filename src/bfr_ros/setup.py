"""Build description of the ament_python package ``bfr_ros``.

Executables are console scripts installed into ``lib/bfr_ros/`` (see setup.cfg), so
``ros2 run bfr_ros <executable>`` finds them. Files in ``config/`` and ``launch/`` are
globbed into ``share/bfr_ros/``: new files there are installed without editing this file.
"""

from glob import glob

from setuptools import find_packages, setup

package_name = "bfr_ros"

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
        "ROS 2 plumbing shared by the bfr nodes: QoS of the topic contract, parameters "
        "mirrored from the YAML files, time stamps, image conversion, the node main loop."
    ),
    license="Apache-2.0",
    entry_points={
        "console_scripts": [
            # "<executable> = bfr_ros.<module>:main",  -> lib/bfr_ros/<executable>

        ],
    },
)
