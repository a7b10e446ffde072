"""Shared pytest set-up: ROS isolation for the whole test process and common fixtures.

The helpers themselves live in tests/rosutil.py (importable as ``rosutil``).
"""

from __future__ import annotations

import re
from collections.abc import Iterator
from typing import TYPE_CHECKING

import pytest
import rosutil

if TYPE_CHECKING:
    from bfr_control.controller import OrbitalController


def pytest_configure(config: pytest.Config) -> None:
    """Give this test process its own ROS domain before any test touches ROS."""
    rosutil.isolate_ros_environment()


@pytest.fixture(scope="session")
def ros_domain_id() -> int:
    """The ROS_DOMAIN_ID of this test process."""
    return rosutil.claim_domain_id()


@pytest.fixture
def ros_harness(request: pytest.FixtureRequest) -> Iterator[rosutil.RosHarness]:
    """A ROS 2 context with one node named after the test, shut down afterwards."""
    name = re.sub(r"\W", "_", request.node.name)[:50] or "test"
    harness = rosutil.RosHarness(f"test_{name}")
    try:
        yield harness
    finally:
        harness.close()


class NodeProcesses:
    """Starts subprocess nodes for one test and stops them all (SIGINT) afterwards."""

    def __init__(self, log_dir: str) -> None:
        self.log_dir = log_dir
        self.started: list[rosutil.NodeProcess] = []

    def start(self, package: str, name: str, **kwargs: object) -> rosutil.NodeProcess:
        """Start ``install/<package>/lib/<package>/<name>``; see ``rosutil.start_node``."""
        kwargs.setdefault("log_dir", self.log_dir)
        proc = rosutil.start_node(package, name, **kwargs)  # type: ignore[arg-type]
        self.started.append(proc)
        return proc

    def start_python(self, script: str, **kwargs: object) -> rosutil.NodeProcess:
        """Start a Python script; see ``rosutil.start_python``."""
        kwargs.setdefault("log_dir", self.log_dir)
        proc = rosutil.start_python(script, **kwargs)  # type: ignore[arg-type]
        self.started.append(proc)
        return proc

    def stop_all(self) -> None:
        """Stop every started process that is still running."""
        for proc in reversed(self.started):
            proc.stop()


@pytest.fixture
def node_processes(tmp_path_factory: pytest.TempPathFactory) -> Iterator[NodeProcesses]:
    """Start subprocess nodes in a test; they are stopped with SIGINT at teardown."""
    procs = NodeProcesses(str(tmp_path_factory.mktemp("nodes")))
    try:
        yield procs
    finally:
        procs.stop_all()


@pytest.fixture(scope="module")
def controller(tmp_path_factory: pytest.TempPathFactory) -> OrbitalController:
    """The controller core with the shipped configuration, its gains solved into a temporary
    cache (one per test module)."""
    from bfr_control.constraint import VirtualConstraint  # noqa: PLC0415 - only when used
    from bfr_control.controller import (  # noqa: PLC0415
        OrbitalController,
        load_controller_config,
    )
    from bfr_control.orbit import PeriodicOrbit  # noqa: PLC0415
    from bfr_control.riccati import compute_gains  # noqa: PLC0415
    from bfr_model.dynamics import RigidModel  # noqa: PLC0415
    from bfr_model.params import load_params  # noqa: PLC0415

    params = load_params()
    config = load_controller_config()
    model = RigidModel(params)
    orbit = PeriodicOrbit(model, VirtualConstraint(model, config.constraint), config.orbit)
    gains = compute_gains(orbit, config.riccati, directory=tmp_path_factory.mktemp("gains"))
    return OrbitalController(params, config, gains=gains)
