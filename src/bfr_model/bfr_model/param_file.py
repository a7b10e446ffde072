"""Parameter files: where they are, how they are read, how a value is checked (no rclpy).

The project's YAML files are both physics/sensor/controller sources and node parameter files
(ROS 2 parameter-file format, ``/**: ros__parameters: ...``). This module is the one place
that

- finds a package's shipped file (:func:`share_path`, :func:`config_path`): the installed
  ``share/<package>/...`` of an ament package (what ``ros2 pkg prefix`` points at), else the
  source tree beside this package (a checkout that was not built);
- reads a parameter file (:func:`load_ros_parameters`, :func:`ros_parameters`);
- checks a value (:func:`check`, :func:`finite`, :func:`positive`, :func:`nonnegative`,
  :func:`integer`, :func:`in_range`, :func:`one_of`), raising :class:`ParameterError`
  whose message names the parameter. Every configuration dataclass validates its fields
  with these in ``__post_init__``, so a bad value is refused the same way whether it came
  from a file, a ``-p name:=value`` override or code.
"""

from __future__ import annotations

import math
from collections.abc import Collection, Mapping
from pathlib import Path
from typing import Any

import yaml

__all__ = [
    "ParameterError",
    "check",
    "config_path",
    "finite",
    "in_range",
    "integer",
    "load_ros_parameters",
    "nonnegative",
    "one_of",
    "positive",
    "ros_parameters",
    "share_path",
]

#: ``src/`` of a source checkout (this file is ``src/bfr_model/bfr_model/param_file.py``).
_SOURCE_ROOT = Path(__file__).resolve().parents[2]


class ParameterError(ValueError):
    """A parameter file or value is invalid; the message names the offending entry."""


# -- where ------------------------------------------------------------------------------------
def share_path(package: str, *parts: str) -> Path:
    """A file or folder a package ships in ``share/<package>/`` (e.g. ``config/rig.yaml``).

    The installed package (found through the ament index, as ``ros2 pkg prefix`` finds it) is
    preferred; a source checkout that was not built falls back to ``src/<package>/<parts>``.

    Raises
    ------
    ParameterError
        If neither exists (both places are named).
    """
    tried = []
    try:
        from ament_index_python.packages import (  # noqa: PLC0415 - optional: ament index
            PackageNotFoundError,
            get_package_share_directory,
        )

        try:
            installed = Path(get_package_share_directory(package), *parts)
            if installed.exists():
                return installed
            tried.append(str(installed))
        except PackageNotFoundError:
            tried.append(f"share/{package} (package not installed)")
    except ImportError:  # pragma: no cover - ament_index_python not installed
        tried.append("ament index (ament_index_python not installed)")
    source = _SOURCE_ROOT.joinpath(package, *parts)
    if source.exists():
        return source
    tried.append(str(source))
    raise ParameterError(f"{'/'.join(parts)} of {package} not found; looked in {tried}")


def config_path(package: str, name: str) -> Path:
    """The shipped ``config/<name>`` of ``package`` (see :func:`share_path`)."""
    return share_path(package, "config", name)


# -- reading ----------------------------------------------------------------------------------
def ros_parameters(doc: Any, source: str, error: type[Exception] = ParameterError
                   ) -> dict[str, Any]:
    """The ``ros__parameters`` mapping of a parsed parameter file.

    Accepts a bare ``ros__parameters`` mapping or the first node entry (``/**`` or a node
    name) holding one; anything else raises ``error`` naming ``source``.
    """
    if not isinstance(doc, Mapping) or not doc:
        raise error(f"{source}: not a ROS 2 parameter file (expected a mapping)")
    if "ros__parameters" in doc:
        body = doc["ros__parameters"]
    else:
        node_name, body = next(iter(doc.items()))
        if not (isinstance(body, Mapping) and "ros__parameters" in body):
            raise error(f"{source}: node entry {node_name!r} has no ros__parameters")
        body = body["ros__parameters"]
    if not isinstance(body, Mapping):
        raise error(f"{source}: ros__parameters must be a mapping, got {type(body).__name__}")
    return dict(body)


def load_ros_parameters(path: str | Path, error: type[Exception] = ParameterError
                        ) -> dict[str, Any]:
    """Read and parse a parameter file; unreadable or invalid YAML raises ``error``."""
    p = Path(path)
    try:
        doc = yaml.safe_load(p.read_text())
    except OSError as exc:
        raise error(f"cannot read parameter file {p}: {exc.strerror or exc}") from exc
    except yaml.YAMLError as exc:
        where = getattr(exc, "problem_mark", None)
        at = f" at line {where.line + 1}" if where is not None else ""
        raise error(f"{p}: invalid YAML{at}: {getattr(exc, 'problem', exc)}") from exc
    return ros_parameters(doc, str(p), error)


# -- checking ---------------------------------------------------------------------------------
def check(cond: bool, name: str, msg: str) -> None:
    """Raise :class:`ParameterError` ``"parameter <name>: <msg>"`` unless ``cond``."""
    if not cond:
        raise ParameterError(f"parameter {name}: {msg}")


def finite(name: str, value: Any) -> None:
    """``value`` is a finite real number (not a bool)."""
    check(isinstance(value, (int, float)) and not isinstance(value, bool)
          and math.isfinite(value), name, f"must be a finite number, got {value!r}")


def positive(name: str, value: Any) -> None:
    """``value`` is a finite number > 0."""
    finite(name, value)
    check(value > 0.0, name, f"must be > 0, got {value!r}")


def nonnegative(name: str, value: Any) -> None:
    """``value`` is a finite number >= 0."""
    finite(name, value)
    check(value >= 0.0, name, f"must be >= 0, got {value!r}")


def integer(name: str, value: Any, minimum: int | None = None) -> None:
    """``value`` is an integer (``2.0`` counts), at least ``minimum`` when given."""
    check(isinstance(value, (int, float)) and not isinstance(value, bool)
          and math.isfinite(value) and float(value) == int(value), name,
          f"must be an integer, got {value!r}")
    if minimum is not None:
        check(value >= minimum, name, f"must be >= {minimum}, got {value!r}")


def one_of(name: str, value: Any, choices: Collection[Any]) -> None:
    """``value`` is one of ``choices``."""
    check(value in choices, name,
          f"must be one of {', '.join(map(str, choices))}; got {value!r}")


def in_range(name: str, value: Any, low: float, high: float, *, high_open: bool = False
             ) -> None:
    """``value`` is a finite number in ``[low, high]`` (``[low, high)`` with ``high_open``)."""
    finite(name, value)
    ok = low <= value < high if high_open else low <= value <= high
    check(ok, name, f"must be within [{low}, {high}{')' if high_open else ']'}, got {value!r}")
