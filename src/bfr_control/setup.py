"""Build description of the ament_python package ``bfr_control``.

Executables are console scripts installed into ``lib/bfr_control/`` (see setup.cfg), so
``ros2 run bfr_control <executable>`` finds them. Files in ``config/`` and ``launch/`` are
globbed into ``share/bfr_control/``: new files there are installed without editing this file.
"""

from glob import glob

from setuptools import find_packages, setup

package_name = "bfr_control"

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
        "Orbital stabilisation controller of the Butterfly robot (virtual constraint, orbit, "
        "transverse linearisation, periodic Riccati gains, estimator, supervisor) and the "
        "controller node."
    ),
    license="Apache-2.0",
    entry_points={
        "console_scripts": [
            # "<executable> = bfr_control.<module>:main",  -> lib/bfr_control/<executable>
            "controller_node = bfr_control.controller_node:main",
        ],
    },
)
