"""Build description of the ament_python package ``bfr_camera``.

Executables are console scripts installed into ``lib/bfr_camera/`` (see setup.cfg), so
``ros2 run bfr_camera <executable>`` finds them. Files in ``config/`` and ``launch/`` are
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
        # Keep lib/<package>/ present even before the package registers an executable.
        ("lib/" + package_name, []),
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
            "camera_node = bfr_camera.camera_node:main",
        ],
    },
)
