"""Build description of the ament_python package ``bfr_tools``.

Executables are console scripts installed into ``lib/bfr_tools/`` (see setup.cfg), so
``ros2 run bfr_tools <executable>`` finds them. Files in ``config/`` and ``launch/`` are
globbed into ``share/bfr_tools/``: new files there are installed without editing this file.
"""

from glob import glob

from setuptools import find_packages, setup

package_name = "bfr_tools"

setup(
    name=package_name,
    version="0.2.0",
    packages=find_packages(exclude=["test", "test.*"]),
    data_files=[
        ("share/ament_index/resource_index/packages", ["resource/" + package_name]),
        ("share/" + package_name, ["package.xml"]),
        ("share/" + package_name + "/config",
         sorted(glob("config/*.yaml") + glob("config/*.json") + glob("config/*.rviz"))),
        ("share/" + package_name + "/launch", sorted(glob("launch/*.py") + glob("launch/*.xml"))),
        # Keep lib/<package>/ present even before the package registers an executable.
        ("lib/" + package_name, []),
    ],
    install_requires=["setuptools"],
    zip_safe=True,
    maintainer="bfr developers",
    maintainer_email="bfr@example.org",
    description=(
        "Tools of bfr: the bfr command line, the rig launcher and launch file, bench, doctor, "
        "controller and camera evaluations, the seed's perturbation study."
    ),
    license="Apache-2.0",
    entry_points={
        "console_scripts": [
            # "<executable> = bfr_tools.<module>:main",  -> lib/bfr_tools/<executable>
            "bfr = bfr_tools.cli:main",
            "loop_node = bfr_tools.loop_node:main",
        ],
    },
)
