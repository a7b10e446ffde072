"""Helpers for ROS 2 integration tests (imported by tests/conftest.py and by tests).

The rules of DEVELOPERS.md, made reusable:

* every test process gets its own ``ROS_DOMAIN_ID`` (claimed with a lock file, so test
  processes running at the same time on this machine never share one) and
  ``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST``: :func:`isolate_ros_environment`;
* wait for matched endpoints before asserting: :meth:`RosHarness.wait_for_match`;
* nodes under test run as subprocesses from the ament layout
  (``install/<pkg>/lib/<pkg>/<exe>``) and are stopped with SIGINT to their own pid:
  :func:`start_node`, :class:`NodeProcess`.

Typical use in a test (fixtures from tests/conftest.py)::

    def test_simulator_publishes(ros_harness, node_processes):
        node = node_processes.start("bfr_sim", "simulator_node", ros_args=["-p", "rate:=100"])
        got = []
        sub = ros_harness.node.create_subscription(SimTruth, "sim_truth", got.append, 10)
        ros_harness.wait_for_match(sub)
        assert ros_harness.spin_until(lambda: len(got) >= 3, timeout=10.0), node.output()
"""

from __future__ import annotations

import importlib
import os
import signal
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable, Iterable, Mapping, Sequence
from pathlib import Path
from typing import Any

from bfr_ros.domain import claim_domain_id

#: Root of the work tree (the folder holding src/, tests/, scripts/).
WORKSPACE = Path(__file__).resolve().parents[1]
#: colcon install base.
INSTALL = WORKSPACE / "install"

def isolate_ros_environment() -> int:
    """Give this process (and the subprocesses it starts) a private ROS 2 graph.

    Sets ``ROS_DOMAIN_ID`` to a claimed id and ``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST``
    in ``os.environ``; removes ``ROS_STATIC_PEERS`` and ``ROS_LOCALHOST_ONLY``. Call it
    before the first ``rclpy.init``.

    Returns
    -------
    int
        The domain id.
    """
    domain = claim_domain_id()
    os.environ["ROS_DOMAIN_ID"] = str(domain)
    os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
    os.environ.pop("ROS_STATIC_PEERS", None)
    os.environ.pop("ROS_LOCALHOST_ONLY", None)
    return domain


def ros_env(extra: Mapping[str, str] | None = None) -> dict[str, str]:
    """Return the environment for a subprocess: this process's, isolated, plus ``extra``.

    Parameters
    ----------
    extra : mapping of str to str, optional
        Variables to add or override.

    Returns
    -------
    dict of str to str
        A new environment mapping.
    """
    isolate_ros_environment()
    env = dict(os.environ)
    env.setdefault("PYTHONUNBUFFERED", "1")
    env.update(extra or {})
    return env


def executable(package: str, name: str) -> Path:
    """Return ``install/<package>/lib/<package>/<name>``, checking that it is executable.

    Parameters
    ----------
    package : str
        ROS package name.
    name : str
        Executable name.

    Returns
    -------
    pathlib.Path
        Path of the executable.

    Raises
    ------
    FileNotFoundError
        If it does not exist or is not executable (run scripts/setup).
    """
    path = INSTALL / package / "lib" / package / name
    if not (path.is_file() and os.access(path, os.X_OK)):
        raise FileNotFoundError(f"{path} is missing or not executable (run scripts/setup)")
    return path


class NodeProcess:
    """A subprocess (usually a ROS node) whose output goes to a log file.

    Parameters
    ----------
    command : sequence of str
        Command line.
    env : mapping of str to str, optional
        Environment; :func:`ros_env` when omitted.
    name : str, optional
        Label used in messages and in the log file name.
    log_dir : path-like, optional
        Folder for the log file; a temporary folder when omitted.
    """

    def __init__(
        self,
        command: Sequence[str],
        env: Mapping[str, str] | None = None,
        name: str | None = None,
        log_dir: str | os.PathLike[str] | None = None,
    ) -> None:
        self.command = [str(c) for c in command]
        self.name = name or Path(self.command[0]).name
        folder = Path(log_dir) if log_dir is not None else Path(tempfile.mkdtemp(prefix="bfr-"))
        folder.mkdir(parents=True, exist_ok=True)
        self.log_path = folder / f"{self.name}-{os.getpid()}-{time.monotonic_ns()}.log"
        self._log = self.log_path.open("wb")
        self.process = subprocess.Popen(
            self.command,
            env=dict(env) if env is not None else ros_env(),
            stdin=subprocess.DEVNULL,
            stdout=self._log,
            stderr=subprocess.STDOUT,
        )

    @property
    def pid(self) -> int:
        """Process id of the subprocess."""
        return self.process.pid

    @property
    def alive(self) -> bool:
        """Whether the subprocess is still running."""
        return self.process.poll() is None

    def output(self) -> str:
        """Return everything the subprocess has printed so far (stdout and stderr)."""
        self._log.flush()
        return self.log_path.read_text(errors="replace")

    def stop(self, timeout: float = 10.0) -> int:
        """Stop the subprocess with SIGINT to its own pid and wait for it.

        Falls back to SIGTERM, then SIGKILL, if it does not exit within ``timeout``.

        Parameters
        ----------
        timeout : float
            Seconds to wait after SIGINT [s].

        Returns
        -------
        int
            The exit status (negative: killed by that signal).
        """
        if self.alive:
            self.process.send_signal(signal.SIGINT)
            try:
                self.process.wait(timeout=timeout)
            except subprocess.TimeoutExpired:
                self.process.terminate()
                try:
                    self.process.wait(timeout=5.0)
                except subprocess.TimeoutExpired:
                    self.process.kill()
                    self.process.wait()
        self._log.close()
        return int(self.process.returncode)

    def __enter__(self) -> NodeProcess:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.stop()

    def __repr__(self) -> str:
        return f"NodeProcess({self.name!r}, pid={self.pid}, alive={self.alive})"


def start_node(
    package: str,
    name: str,
    args: Iterable[str] = (),
    ros_args: Iterable[str] | None = None,
    env: Mapping[str, str] | None = None,
    log_dir: str | os.PathLike[str] | None = None,
) -> NodeProcess:
    """Start ``install/<package>/lib/<package>/<name>`` as ``ros2 run`` would.

    Parameters
    ----------
    package : str
        ROS package name.
    name : str
        Executable name.
    args : iterable of str
        Arguments for the executable.
    ros_args : iterable of str, optional
        Arguments placed after ``--ros-args`` (e.g. ``["-p", "rate:=100", "-r",
        "__node:=sim"]``).
    env : mapping of str to str, optional
        Extra environment variables (on top of :func:`ros_env`).
    log_dir : path-like, optional
        Folder for the output log.

    Returns
    -------
    NodeProcess
        The running process.
    """
    command = [str(executable(package, name)), *args]
    if ros_args is not None:
        command += ["--ros-args", *ros_args]
    return NodeProcess(command, env=ros_env(env), name=f"{package}.{name}", log_dir=log_dir)


def start_python(
    script: str | os.PathLike[str],
    args: Iterable[str] = (),
    env: Mapping[str, str] | None = None,
    log_dir: str | os.PathLike[str] | None = None,
) -> NodeProcess:
    """Start a Python script with this interpreter in the isolated environment.

    Parameters
    ----------
    script : path-like
        Script to run.
    args : iterable of str
        Its arguments.
    env : mapping of str to str, optional
        Extra environment variables.
    log_dir : path-like, optional
        Folder for the output log.

    Returns
    -------
    NodeProcess
        The running process.
    """
    command = [sys.executable, str(script), *args]
    return NodeProcess(command, env=ros_env(env), name=Path(script).stem, log_dir=log_dir)


class RosHarness:
    """The test process's own ROS 2 participant: a context, one node and an executor.

    Parameters
    ----------
    name : str
        Node name.
    """

    def __init__(self, name: str = "test_harness") -> None:
        import rclpy  # noqa: PLC0415 - keep this module importable without ROS
        from rclpy.executors import SingleThreadedExecutor  # noqa: PLC0415

        isolate_ros_environment()
        self.context = rclpy.Context()
        rclpy.init(context=self.context)
        self.node = rclpy.create_node(name, context=self.context)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)

    def spin_for(self, duration: float) -> None:
        """Process callbacks for ``duration`` seconds [s]."""
        deadline = time.monotonic() + duration
        while time.monotonic() < deadline:
            self.executor.spin_once(timeout_sec=min(0.02, max(0.0, deadline - time.monotonic())))

    def spin_until(self, predicate: Callable[[], bool], timeout: float = 10.0) -> bool:
        """Process callbacks until ``predicate()`` is true or ``timeout`` [s] passes.

        Parameters
        ----------
        predicate : callable
            Condition checked between callbacks.
        timeout : float
            Time limit [s].

        Returns
        -------
        bool
            Whether the predicate became true.
        """
        deadline = time.monotonic() + timeout
        while not predicate():
            if time.monotonic() > deadline:
                return False
            self.executor.spin_once(timeout_sec=0.02)
        return True

    def wait_for_match(self, endpoint: Any, count: int = 1, timeout: float = 10.0) -> None:
        """Wait until a publisher or subscription has at least ``count`` matched peers.

        Parameters
        ----------
        endpoint : rclpy.publisher.Publisher or rclpy.subscription.Subscription
            The local endpoint.
        count : int
            Matched remote endpoints required.
        timeout : float
            Time limit [s].

        Raises
        ------
        TimeoutError
            If the endpoints do not match in time.
        """
        if hasattr(endpoint, "get_subscription_count"):
            matched = endpoint.get_subscription_count
        else:
            matched = endpoint.get_publisher_count
        if not self.spin_until(lambda: matched() >= count, timeout):
            raise TimeoutError(
                f"{endpoint.topic_name}: {matched()} matched endpoint(s), expected {count} "
                f"within {timeout} s (ROS_DOMAIN_ID={os.environ.get('ROS_DOMAIN_ID')})"
            )

    def close(self) -> None:
        """Destroy the node and shut the context down."""
        import rclpy  # noqa: PLC0415

        self.executor.shutdown()
        self.node.destroy_node()
        if self.context.ok():
            rclpy.shutdown(context=self.context)


def message_class(type_name: str) -> type:
    """Return the message class of a type name such as ``bfr_interfaces/msg/SimTruth``.

    Parameters
    ----------
    type_name : str
        ``<package>/msg/<Type>`` (``<package>/<Type>`` is accepted too).

    Returns
    -------
    type
        The generated message class.
    """
    parts = type_name.split("/")
    package, name = parts[0], parts[-1]
    return getattr(importlib.import_module(f"{package}.msg"), name)


_FLOATS = {"float", "double"}
_INTS = set("octet char byte uint8 int8 uint16 int16 uint32 int32 uint64 int64".split())


def fill_message(msg: Any, seed: int = 1) -> Any:
    """Set every field of a message (recursively) to a distinct, non-default value.

    Floats become ``seed + k + 0.25``, integers small distinct numbers, booleans true,
    strings ``"<field>_<k>"``; nested messages are filled the same way; numeric arrays and
    sequences get two (or their fixed number of) elements.

    Parameters
    ----------
    msg : ROS message
        Message to fill in place.
    seed : int
        Offset that makes messages filled with different seeds differ.

    Returns
    -------
    ROS message
        ``msg``.
    """
    for k, (name, kind) in enumerate(msg.get_fields_and_field_types().items(), start=1):
        value = getattr(msg, name)
        base = kind.split("[")[0].removeprefix("sequence<").rstrip(">").split(",")[0]
        is_array = "[" in kind or kind.startswith("sequence<")
        if is_array and base in _FLOATS | _INTS | {"boolean"}:
            n = len(value) if "[" in kind and not kind.endswith("[]") else 2
            if base in _FLOATS:
                items: list[Any] = [seed + k + 0.25 + i for i in range(n)]
            elif base == "boolean":
                items = [True] * n
            else:
                items = [(seed + k + i) % 100 for i in range(n)]
            setattr(msg, name, items)
        elif base in _FLOATS:
            setattr(msg, name, seed + k + 0.25)
        elif base in _INTS:
            setattr(msg, name, (seed + k) % 100 + 1)
        elif base == "boolean":
            setattr(msg, name, True)
        elif base in ("string", "wstring"):
            setattr(msg, name, f"{name}_{seed + k}")
        elif hasattr(value, "get_fields_and_field_types"):
            fill_message(value, seed + 10 * k)
    return msg


def message_diff(a: Any, b: Any, prefix: str = "") -> list[str]:
    """List the fields (dotted paths) in which two messages of one type differ.

    Parameters
    ----------
    a, b : ROS message
        Messages to compare.
    prefix : str
        Path prefix for nested fields.

    Returns
    -------
    list of str
        ``"path: a_value != b_value"`` for every differing leaf field.
    """
    out: list[str] = []
    for name in a.get_fields_and_field_types():
        va, vb = getattr(a, name), getattr(b, name)
        if hasattr(va, "get_fields_and_field_types"):
            out += message_diff(va, vb, f"{prefix}{name}.")
            continue
        if hasattr(va, "__len__") and not isinstance(va, str):
            va, vb = list(va), list(vb)  # arrays: numpy arrays or array.array
        if va != vb:
            out.append(f"{prefix}{name}: {va!r} != {vb!r}")
    return out
