"""The house: one dependency order between the packages, checked on every import of src/.

The order is written once, in DEVELOPERS.md ("Layout and dependency order"); this test reads
it from there and parses every Python file of every package (module-level and
function-level imports, launch files included). It fails on

- an import that runs up the order (a package importing one after it), hence on any cycle;
- a function-local import of a project package, or a function-local import without its
  reason (``# noqa: PLC0415 - <reason>``: only optional heavy dependencies are imported late);
- ROS imports (rclpy, message packages) in the pure cores: the model anywhere, the camera,
  controller and simulator outside their ``*_node.py`` modules;
- a package.xml whose project dependencies differ from what its code imports.
"""

from __future__ import annotations

import ast
import re
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
SRC = ROOT / "src"
ROS_MODULES = ("rclpy", "rcl_interfaces", "sensor_msgs", "std_msgs", "std_srvs",
               "rosgraph_msgs", "builtin_interfaces", "bfr_interfaces", "launch", "launch_ros",
               "visualization_msgs", "geometry_msgs")
#: Packages whose non-node modules must not import ROS (pure numpy cores).
PURE_CORES = ("bfr_model", "bfr_camera", "bfr_control", "bfr_sim", "bfr_diagnose")


def documented_order() -> list[str]:
    """The dependency order line of DEVELOPERS.md: ``bfr_interfaces <- bfr_model <- ...``."""
    text = (ROOT / "DEVELOPERS.md").read_text()
    lines = [ln.strip() for ln in text.splitlines()
             if re.fullmatch(r"\s*bfr_\w+(\s*<-\s*bfr_\w+)+\s*", ln)]
    assert len(lines) == 1, f"expected one dependency-order line in DEVELOPERS.md, got {lines}"
    return [p.strip() for p in lines[0].split("<-")]


@dataclass(frozen=True)
class Import:
    """One import statement of a project file."""

    path: Path
    line: int
    module: str
    local: bool      # inside a function
    text: str        # the source line


def imports_of(path: Path) -> list[Import]:
    """Every absolute import of a file, with whether it sits inside a function."""
    src = path.read_text()
    lines = src.splitlines()
    out: list[Import] = []

    def visit(node: ast.AST, in_function: bool) -> None:
        for child in ast.iter_child_nodes(node):
            inner = in_function or isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef,
                                                      ast.Lambda))
            if isinstance(child, ast.Import):
                out.extend(Import(path, child.lineno, a.name, in_function,
                                  lines[child.lineno - 1]) for a in child.names)
            elif isinstance(child, ast.ImportFrom) and child.level == 0 and child.module:
                out.append(Import(path, child.lineno, child.module, in_function,
                                  lines[child.lineno - 1]))
            visit(child, inner)

    visit(ast.parse(src, str(path)), False)
    return out


def python_files(package: str) -> list[Path]:
    root = SRC / package
    return sorted(p for p in root.rglob("*.py")
                  if "__pycache__" not in p.parts and p.name != "setup.py")


ORDER = documented_order()
PYTHON_PACKAGES = [p for p in ORDER if (SRC / p / p).is_dir()]


def test_order_names_every_package() -> None:
    on_disk = sorted(p.parent.name for p in SRC.glob("*/package.xml"))
    assert sorted(ORDER) == on_disk


@pytest.mark.parametrize("package", PYTHON_PACKAGES)
def test_imports_follow_the_order(package: str) -> None:
    rank = {p: i for i, p in enumerate(ORDER)}
    bad = []
    for imp in (i for f in python_files(package) for i in imports_of(f)):
        top = imp.module.split(".")[0]
        if top in rank and rank[top] > rank[package]:
            bad.append(f"{imp.path.relative_to(ROOT)}:{imp.line}: {package} imports {top}, "
                       f"which comes after it")
    assert not bad, "\n".join(bad)


@pytest.mark.parametrize("package", PYTHON_PACKAGES)
def test_function_local_imports_are_justified(package: str) -> None:
    bad = []
    for imp in (i for f in python_files(package) for i in imports_of(f) if i.local):
        where = f"{imp.path.relative_to(ROOT)}:{imp.line}"
        if imp.module.split(".")[0] in ORDER:
            bad.append(f"{where}: project module {imp.module} imported inside a function")
        elif not re.search(r"#\s*noqa:\s*PLC0415\s+-\s+\S", imp.text):
            bad.append(f"{where}: function-local import of {imp.module} without a reason "
                       f"(# noqa: PLC0415 - <why>)")
    assert not bad, "\n".join(bad)


@pytest.mark.parametrize("package", [p for p in PURE_CORES if p in PYTHON_PACKAGES])
def test_pure_cores_import_no_ros(package: str) -> None:
    bad = []
    for f in python_files(package):
        if f.name.endswith("_node.py") and package != "bfr_model":
            continue
        for imp in imports_of(f):
            if imp.module.split(".")[0] in ROS_MODULES:
                bad.append(f"{f.relative_to(ROOT)}:{imp.line}: {imp.module}")
    assert not bad, "ROS imports in a pure core:\n" + "\n".join(bad)


@pytest.mark.parametrize("package", PYTHON_PACKAGES)
def test_package_xml_declares_what_the_code_imports(package: str) -> None:
    root = ET.parse(SRC / package / "package.xml").getroot()
    declared = {e.text for e in root if e.tag in ("depend", "exec_depend")
                and (e.text or "").startswith("bfr_")}
    used = {i.module.split(".")[0] for f in python_files(package) for i in imports_of(f)}
    used = {u for u in used if u.startswith("bfr_") and u != package}
    if package == "bfr_model":
        used.add("bfr_interfaces")  # its .msg files: the message definitions of the bags
    if package == "bfr_tools":  # subcommands are imported by name when called
        from bfr_tools.cli import SUBCOMMANDS  # noqa: PLC0415

        used |= {mod.split(".")[0] for mod, _, _ in SUBCOMMANDS.values()} - {package}
    assert declared == used, (f"package.xml declares {sorted(declared)}, the code imports "
                              f"{sorted(used)}")
