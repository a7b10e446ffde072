"""The ``bfr`` command line: one entry point, subcommands registered by name.

Each subcommand is a module with ``main(argv: list[str] | None = None) -> int``. It is
registered in :data:`SUBCOMMANDS` and imported only when it is called, so a slow or broken
subcommand does not affect the others. To add one, write the module and add one line::

    "simulate": ("bfr_sim.simulate_cli", "main", "simulate the rig offline"),

Run it in the workspace environment with ``scripts/bfr <subcommand> ...``.
"""

from __future__ import annotations

import importlib
import sys
from collections.abc import Callable, Sequence

PROG = "bfr"

#: Subcommand name -> (module path, function name, one-line help). Only what exists.
SUBCOMMANDS: dict[str, tuple[str, str, str]] = {
    "run": (
        "bfr_tools.run",
        "main",
        "run an executable of a workspace package, like `ros2 run <pkg> <exe>`",
    ),
    "doctor": (
        "bfr_tools.doctor",
        "main",
        "check the environment: Python, ROS 2, RMW, messages, a DDS round trip",
    ),
    "simulate": (
        "bfr_sim.simulate_cli",
        "main",
        "simulate the rigid model, open loop or with the controller (--controller)",
    ),
    "diagnose": (
        "bfr_diagnose.cli",
        "main",
        "locate, name and model what the nominal model leaves out of a recording",
    ),
    "blindtest": (
        "bfr_diagnose.blindtest",
        "main",
        "prove bfr diagnose on recordings with hidden effects (confusion matrix, accuracy)",
    ),
    "limits": (
        "bfr_tools.limits",
        "main",
        "detection limits: randomized blind test on Dask beside PySINDy (run, report)",
    ),
    "rig": (
        "bfr_tools.rig",
        "main",
        "run the emulated rig: simulator, camera, controller and recorder nodes; summary",
    ),
    "control-eval": (
        "bfr_tools.control_eval",
        "main",
        "controller's region of attraction and robustness figures (closed-loop simulation)",
    ),
    "camera-eval": ("bfr_tools.camera_eval", "main", "ball detector: accuracy and speed figures"),
    "bench": ("bfr_tools.bench", "main", "performance figures side by side, with budgets"),
    "warm": ("bfr_tools.warm", "main",
             "compile and cache the nodes' kernels and gains (scripts/setup runs it)"),
    "video": (
        "bfr_tools.video",
        "main",
        "render a recording (bag, CSV, rig log) as a video of the rig seen from the front",
    ),
    "read": (
        "bfr_tools.read",
        "main",
        "read recordings and print what each reader used and lost, by cause",
    ),
    "analyze": (
        "bfr_tools.analysis.cli",
        "main",
        "the seed's perturbation study: energy (ch. 2) and bounce/slip (ch. 3-4) figures",
    ),
}


def format_help() -> str:
    """Return the top-level help text listing every registered subcommand.

    Returns
    -------
    str
        Usage, description and one line per subcommand, sorted by name.
    """
    width = max((len(name) for name in SUBCOMMANDS), default=0)
    lines = [
        f"usage: {PROG} <subcommand> [args...]",
        "",
        "Command line of bfr, the ROS 2 Jazzy emulation of the NTNU Butterfly robot rig.",
        "",
        "subcommands:",
    ]
    lines += [f"  {name:<{width}}  {SUBCOMMANDS[name][2]}" for name in sorted(SUBCOMMANDS)]
    lines += [
        "",
        "options:",
        "  -h, --help  show this help and exit",
        "",
        f"`{PROG} <subcommand> --help` shows the options of a subcommand.",
    ]
    return "\n".join(lines) + "\n"


def load_subcommand(name: str) -> Callable[[list[str]], int | None]:
    """Import a registered subcommand and return its entry function.

    Parameters
    ----------
    name : str
        Key of :data:`SUBCOMMANDS`.

    Returns
    -------
    callable
        The subcommand's ``main(argv)``.

    Raises
    ------
    KeyError
        If ``name`` is not registered.
    RuntimeError
        If the module cannot be imported or lacks the function; the message names both.
    """
    module_name, function_name, _ = SUBCOMMANDS[name]
    try:
        module = importlib.import_module(module_name)
    except Exception as exc:  # any import failure is reported the same way
        raise RuntimeError(
            f"subcommand '{name}' is unavailable: importing module '{module_name}' failed: "
            f"{type(exc).__name__}: {exc}"
        ) from exc
    function = getattr(module, function_name, None)
    if not callable(function):
        raise RuntimeError(
            f"subcommand '{name}' is unavailable: module '{module_name}' has no function "
            f"'{function_name}'"
        )
    return function


def main(argv: Sequence[str] | None = None) -> int:
    """Dispatch ``bfr <subcommand> [args...]``.

    Parameters
    ----------
    argv : sequence of str, optional
        Arguments after the program name; ``sys.argv[1:]`` when omitted.

    Returns
    -------
    int
        Exit status: the subcommand's, 0 for ``--help``, 2 for a usage error, 1 when the
        subcommand cannot be loaded.
    """
    args = list(sys.argv[1:] if argv is None else argv)
    if not args:
        sys.stderr.write(format_help())
        return 2
    if args[0] in ("-h", "--help"):
        sys.stdout.write(format_help())
        return 0
    if args[0] == "help":
        if len(args) == 1:
            sys.stdout.write(format_help())
            return 0
        args = [args[1], "--help"]
    name, rest = args[0], args[1:]
    if name not in SUBCOMMANDS:
        sys.stderr.write(f"{PROG}: unknown subcommand '{name}'\n\n{format_help()}")
        return 2
    try:
        function = load_subcommand(name)
    except RuntimeError as exc:
        sys.stderr.write(f"{PROG}: error: {exc}\n")
        return 1
    status = function(rest)
    return int(status or 0)


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
