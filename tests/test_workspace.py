"""The workspace: layout, ament install layout, environment, entry points, set-up."""

from __future__ import annotations

import importlib.metadata
import os
import shutil
import subprocess
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest
import rosutil

ROOT = rosutil.WORKSPACE
INSTALL = rosutil.INSTALL
PYTHON_PACKAGES = ("bfr_model", "bfr_ros", "bfr_camera", "bfr_control", "bfr_sim",
                   "bfr_diagnose", "bfr_tools")
PACKAGES = ("bfr_interfaces", *PYTHON_PACKAGES)


def run(command: list[str], env: dict[str, str] | None = None, timeout: float = 600.0,
        cwd: Path = ROOT) -> subprocess.CompletedProcess[str]:
    """Run a command, capturing its output as text."""
    return subprocess.run(
        command, cwd=cwd, env=env, capture_output=True, text=True, timeout=timeout,
        stdin=subprocess.DEVNULL, check=False,
    )  # fmt: skip


def build_type(package: str) -> str:
    root = ET.parse(ROOT / "src" / package / "package.xml").getroot()
    assert root.get("format") == "3"
    return root.findtext("export/build_type") or ""


def test_top_level_layout() -> None:
    for name in ("README.md", "DEVELOPERS.md", "tests", "scripts", ".ci/run",
                 "requirements.in", "requirements.txt"):  # fmt: skip
        assert (ROOT / name).exists(), name
    for package in PACKAGES:
        assert (ROOT / "src" / package / "package.xml").is_file(), package
    assert build_type("bfr_interfaces") == "ament_cmake"
    for package in PYTHON_PACKAGES:
        assert build_type(package) == "ament_python", package


def test_dependency_order_in_package_xml() -> None:
    """The manifests follow DEVELOPERS.md's order (test_architecture checks every import)."""

    def deps(package: str) -> set[str]:
        root = ET.parse(ROOT / "src" / package / "package.xml").getroot()
        return {e.text or "" for e in root if e.tag in ("depend", "exec_depend", "build_depend")}

    assert "rclpy" not in deps("bfr_model")
    assert {"bfr_interfaces", "bfr_model", "bfr_ros", "rclpy"} <= deps("bfr_camera")
    assert {"bfr_model", "bfr_ros", "rclpy"} <= deps("bfr_control")
    assert {"bfr_camera", "bfr_control", "bfr_model", "bfr_ros"} <= deps("bfr_sim")
    assert "bfr_sim" not in deps("bfr_camera") | deps("bfr_control")
    assert "bfr_camera" not in deps("bfr_control")


@pytest.mark.parametrize("package", PACKAGES)
def test_ament_index_marker_and_manifest(package: str) -> None:
    prefix = INSTALL / package
    assert (prefix / "share" / "ament_index" / "resource_index" / "packages" / package).exists()
    assert (prefix / "share" / package / "package.xml").exists()


def test_interface_package_registered_as_rosidl_interfaces() -> None:
    index = INSTALL / "bfr_interfaces" / "share" / "ament_index" / "resource_index"
    registered = (index / "rosidl_interfaces" / "bfr_interfaces").read_text().split()
    for name in ("BallObservation", "ControllerState", "SimTruth"):
        assert f"msg/{name}.msg" in registered
        assert (INSTALL / "bfr_interfaces" / "share" / "bfr_interfaces" / "msg" /
                f"{name}.msg").exists()  # fmt: skip


@pytest.mark.parametrize("package", PYTHON_PACKAGES)
def test_executables_live_in_lib_package(package: str) -> None:
    """Every console script is installed as install/<pkg>/lib/<pkg>/<exe> (ros2 run)."""
    libdir = INSTALL / package / "lib" / package
    assert libdir.is_dir()
    scripts = [
        ep.name for ep in importlib.metadata.distribution(package).entry_points
        if ep.group == "console_scripts"
    ]  # fmt: skip
    for name in scripts:
        assert os.access(libdir / name, os.X_OK), f"{libdir / name} is not executable"
    if package == "bfr_tools":
        assert "bfr" in scripts


@pytest.mark.parametrize("package", PYTHON_PACKAGES)
def test_config_and_launch_folders_are_installed(package: str) -> None:
    share = INSTALL / package / "share" / package
    for sub in ("config", "launch"):
        for src in (ROOT / "src" / package / sub).glob("*.yaml" if sub == "config" else "*.py"):
            assert (share / sub / src.name).exists(), f"{src} is not installed"


def test_rig_parameter_file_is_installed() -> None:
    assert (INSTALL / "bfr_model" / "share" / "bfr_model" / "config" / "rig.yaml").exists()


def test_import_bfr_interfaces_in_the_environment() -> None:
    code = "import bfr_interfaces.msg as m; print(m.BallObservation.__name__)"
    result = run(["bash", "-c", f'. scripts/env.sh && python -c "{code}"'])
    assert result.returncode == 0, result.stderr
    assert result.stdout.strip() == "BallObservation"


def test_env_script_defines_the_environment() -> None:
    result = run(["bash", "-c", ". scripts/env.sh && . scripts/env.sh && env"])
    assert result.returncode == 0, result.stderr
    env = dict(line.split("=", 1) for line in result.stdout.splitlines() if "=" in line)
    assert env["RMW_IMPLEMENTATION"] == "rmw_fastrtps_cpp"
    assert env["ROS_DISTRO"] == "jazzy"
    assert env["VIRTUAL_ENV"] == str(ROOT / ".venv")
    assert env["PATH"].split(":")[0] == str(ROOT / ".venv" / "bin")
    assert str(ROOT / ".venv" / "lib") in env["LD_LIBRARY_PATH"].split(":")
    ament = env["AMENT_PREFIX_PATH"].split(":")
    for package in PACKAGES:
        assert str(INSTALL / package) in ament
    assert len(ament) == len(set(ament)), "sourcing twice duplicated AMENT_PREFIX_PATH entries"


def test_bfr_help_lists_subcommands() -> None:
    from bfr_tools.cli import SUBCOMMANDS  # noqa: PLC0415

    result = run(["bash", "scripts/bfr", "--help"])
    assert result.returncode == 0, result.stderr
    for name, (_, _, help_text) in SUBCOMMANDS.items():
        assert name in result.stdout
        assert help_text in result.stdout
    assert "run" in SUBCOMMANDS


def test_bfr_run_finds_executables_like_ros2_run() -> None:
    result = run(["bash", "scripts/bfr", "run", "bfr_tools", "bfr", "--help"])
    assert result.returncode == 0, result.stderr
    assert "subcommands:" in result.stdout
    listing = run(["bash", "scripts/bfr", "run", "bfr_tools"])
    assert "bfr_tools bfr" in listing.stdout.splitlines()


def test_bfr_run_reports_what_is_missing() -> None:
    result = run(["bash", "scripts/bfr", "run", "no_such_package", "x"])
    assert result.returncode == 1
    assert "package 'no_such_package' not found" in result.stderr
    result = run(["bash", "scripts/bfr", "run", "bfr_control", "no_such_exe"])
    assert result.returncode == 1
    assert "no executable 'no_such_exe' in package 'bfr_control'" in result.stderr


def test_bfr_doctor_passes() -> None:
    result = run(["bash", "scripts/bfr", "doctor"], env=rosutil.ros_env())
    assert result.returncode == 0, result.stdout + result.stderr
    assert "FAIL" not in result.stdout


def test_cli_errors_name_the_problem(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    from bfr_tools import cli  # noqa: PLC0415

    assert cli.main(["no_such_subcommand"]) == 2
    assert "unknown subcommand 'no_such_subcommand'" in capsys.readouterr().err
    monkeypatch.setitem(cli.SUBCOMMANDS, "broken", ("bfr_no_such_module", "main", "broken"))
    assert cli.main(["broken"]) == 1
    assert "importing module 'bfr_no_such_module' failed" in capsys.readouterr().err
    monkeypatch.setitem(cli.SUBCOMMANDS, "nofunc", ("bfr_tools.cli", "nope", "nofunc"))
    assert cli.main(["nofunc"]) == 1
    assert "module 'bfr_tools.cli' has no function 'nope'" in capsys.readouterr().err
    assert cli.main([]) == 2
    assert cli.main(["--help"]) == 0
    assert "subcommands:" in capsys.readouterr().out


def test_setup_second_run_changes_nothing() -> None:
    stamps = [ROOT / ".venv" / ".bfr-setup-stamp", ROOT / "install" / ".bfr-setup-stamp"]
    built = sorted((INSTALL / "bfr_interfaces" / "lib").glob("*.so"))
    before = [p.stat().st_mtime_ns for p in stamps + built]
    result = run(["bash", "scripts/setup"])
    assert result.returncode == 0, result.stdout + result.stderr
    assert "setup: up to date: nothing installed or rebuilt" in result.stdout
    assert "colcon build" not in result.stdout
    assert "installing" not in result.stdout
    assert [p.stat().st_mtime_ns for p in stamps + built] == before


def _scratch_workspace(tmp_path: Path, venv: Path | None) -> Path:
    """Copy scripts/, requirements and bfr_interfaces into a scratch work tree."""
    ws = tmp_path / "ws"
    shutil.copytree(ROOT / "scripts", ws / "scripts")
    shutil.copy(ROOT / "requirements.txt", ws)
    shutil.copytree(ROOT / "src" / "bfr_interfaces", ws / "src" / "bfr_interfaces")
    if venv is not None:
        (ws / ".venv").symlink_to(venv)
    return ws


def test_setup_names_the_package_whose_build_failed(tmp_path: Path) -> None:
    """A broken package stops set-up with a message naming it (reuses the built .venv)."""
    ws = _scratch_workspace(tmp_path, ROOT / ".venv")
    msg = ws / "src" / "bfr_interfaces" / "msg" / "SimTruth.msg"
    msg.write_text(msg.read_text() + "no_such_type broken_field\n")
    env = {k: v for k, v in os.environ.items() if not k.startswith(("AMENT_", "COLCON_"))}
    env.pop("PYTHONPATH", None)
    result = run(["bash", "scripts/setup"], cwd=ws, env=env)
    assert result.returncode != 0
    assert "colcon build failed for bfr_interfaces" in result.stderr, result.stderr
    assert not (ws / "install" / ".bfr-setup-stamp").exists()


def test_setup_names_a_failed_dependency_install(tmp_path: Path) -> None:
    """An uninstallable pin stops set-up with a message naming requirements.txt."""
    ws = _scratch_workspace(tmp_path, None)
    (ws / "requirements.txt").write_text("bfr-no-such-distribution==0.0.0\n")
    env = dict(os.environ, BFR_PYTHON=getattr(sys, "_base_executable", sys.executable))
    result = run(["bash", "scripts/setup"], cwd=ws, env=env, timeout=300)
    assert result.returncode != 0
    assert "pip install of requirements.txt failed" in result.stderr, result.stderr
    assert not (ws / ".venv" / ".bfr-setup-stamp").exists()
