"""The start of every node executable: SIGINT or SIGTERM at any moment exits quietly.

Python turns SIGINT into ``KeyboardInterrupt``; a node stopped within its first second (an
operator's Ctrl-C, a launch file or ``bfr rig`` shutting down at once) printed that
exception's traceback from whatever it was importing. The convention of every bfr node
executable (``lib/<pkg>/<exe>``): **a node stopped by SIGINT or SIGTERM exits with status 0
and no traceback, whatever the moment.** The moments, and what a signal does in each:

1. the interpreter's core start, before the executable's first line (about 10 ms here): the
   kernel's and Python's defaults, which no program can change (killed by the signal);
   the executables run ``python3 -S`` so that this moment does not also hold the
   site-packages' ``.pth`` hooks (30-80 ms here, where a Ctrl-C was a "Fatal Python error"
   from ``site``): :func:`run_executable` runs ``site`` itself, after point 2;
2. from the executable's first line through the imports (numpy, rclpy, OpenCV, numba;
   about a second) until ``rclpy.init``: :func:`exit_quietly_on_signals` makes the process
   exit at once with status 0 (nothing to clean up: no DDS participant, no file yet);
3. creating the nodes (parameters, the controller's gains, numba kernels loaded from their
   cache or compiled): :func:`bfr_ros.node_common.run_nodes` stops the start at the next
   Python bytecode (a numba compile is Python code between LLVM calls), destroys the nodes
   made so far and returns 0;
4. running: the node's loop sees the stop flag, shuts down cleanly (a last zero torque, the
   bag closed) and returns 0.

The executables are scripts (``src/<pkg>/scripts/<exe>``, installed into ``lib/<pkg>/``),
not setuptools console scripts, whose wrapper spends ~75 ms in ``importlib.metadata``
before it imports anything of the node. This module's first statements use only modules
built into the interpreter (``_signal``, ``posix``), so that the handlers are in force a
fraction of a millisecond after the executable's first line.
"""

import _signal  # the C module under ``signal``: built in, no import cost
import posix
import sys

__all__ = ["exit_quietly_on_signals", "run_executable"]


def _exit_now(signum, frame):  # noqa: ANN001, ANN202 - a signal handler
    """Leave at once with status 0 (the start was interrupted before anything existed)."""
    posix._exit(0)


def exit_quietly_on_signals() -> None:
    """Until :func:`bfr_ros.node_common.init_ros` takes over: SIGINT/SIGTERM exit with 0.

    Also restores SIGINT where the process inherited it ignored (a background job of a
    non-interactive shell): a node is always stoppable with SIGINT.
    """
    _signal.signal(_signal.SIGINT, _exit_now)
    _signal.signal(_signal.SIGTERM, _exit_now)


def run_executable(module: str) -> None:
    """The body of a node executable: quiet signals, ``site``, then ``module.main()``.

    Parameters
    ----------
    module : str
        Module whose ``main(argv=None) -> int`` is the node's entry point.

    Raises
    ------
    SystemExit
        Always, with ``main``'s exit status.
    """
    exit_quietly_on_signals()
    if sys.flags.no_site:  # started with python3 -S (the executables' shebang): site now
        import site  # noqa: PLC0415 - only when started without it (python3 -S)

        site.main()
    import importlib  # noqa: PLC0415 - after the signal handlers and site

    raise SystemExit(importlib.import_module(module).main())
