"""``bfr run``: run an executable of a workspace package, as ``ros2 run`` does.

``ros2 run <pkg> <exe>`` (ros2cli, not available from PyPI) looks the package up in the
ament index (``AMENT_PREFIX_PATH``) and executes ``<prefix>/lib/<pkg>/<exe>``. This module
does the same, so the workspace's executables start here exactly as they would on a real
ROS 2 Jazzy install. The process is replaced by the executable (``exec``), so signals such
as SIGINT reach the node directly.
"""

from __future__ import annotations

import os
import shlex
import sys
from collections.abc import Sequence
from pathlib import Path

USAGE = """\
usage: bfr run [--prefix CMD] <package> <executable> [args...]

Run <prefix>/lib/<package>/<executable> of a package found in AMENT_PREFIX_PATH, like
`ros2 run`. Everything after <executable> is passed to it unchanged (including --help and
`--ros-args ...`). With only <package>, list its executables.

options:
  -h, --help    show this help and exit
  --prefix CMD  prepend CMD to the command line (e.g. --prefix 'python3 -X importtime')
"""


def package_prefix(package: str) -> Path:
    """Return the install prefix of ``package`` from the ament index.

    Parameters
    ----------
    package : str
        ROS package name.

    Returns
    -------
    pathlib.Path
        The first prefix in ``AMENT_PREFIX_PATH`` that registers the package.

    Raises
    ------
    LookupError
        If no prefix registers the package.
    """
    for prefix in os.environ.get("AMENT_PREFIX_PATH", "").split(os.pathsep):
        if not prefix:
            continue
        marker = Path(prefix, "share", "ament_index", "resource_index", "packages", package)
        if marker.is_file():
            return Path(prefix)
    raise LookupError(
        f"package '{package}' not found in AMENT_PREFIX_PATH "
        "(build the workspace with scripts/setup and run through scripts/bfr, or source "
        "scripts/env.sh)"
    )


def list_executables(package: str) -> list[str]:
    """Return the names of the executables in ``<prefix>/lib/<package>/``.

    Parameters
    ----------
    package : str
        ROS package name.

    Returns
    -------
    list of str
        Sorted executable file names; empty if the package has none.
    """
    libdir = package_prefix(package) / "lib" / package
    if not libdir.is_dir():
        return []
    return sorted(p.name for p in libdir.iterdir() if p.is_file() and os.access(p, os.X_OK))


def executable_path(package: str, executable: str) -> Path:
    """Return the path of ``executable`` of ``package``.

    Parameters
    ----------
    package : str
        ROS package name.
    executable : str
        File name in ``<prefix>/lib/<package>/``.

    Returns
    -------
    pathlib.Path
        Path of an executable file.

    Raises
    ------
    LookupError
        If the package or the executable does not exist; the message lists the package's
        executables.
    """
    path = package_prefix(package) / "lib" / package / executable
    if not (path.is_file() and os.access(path, os.X_OK)):
        names = ", ".join(list_executables(package)) or "none"
        raise LookupError(
            f"no executable '{executable}' in package '{package}' (executables: {names})"
        )
    return path


def main(argv: Sequence[str] | None = None) -> int:
    """Run ``bfr run [--prefix CMD] <package> <executable> [args...]``.

    Parameters
    ----------
    argv : sequence of str, optional
        Arguments after ``run``; ``sys.argv[1:]`` when omitted.

    Returns
    -------
    int
        Only returned on errors (2: usage, 1: not found) or when listing executables;
        otherwise the process is replaced by the executable.
    """
    args = list(sys.argv[1:] if argv is None else argv)
    prefix: list[str] = []
    while args and args[0].startswith("-"):
        option = args.pop(0)
        if option in ("-h", "--help"):
            sys.stdout.write(USAGE)
            return 0
        if option == "--prefix" and args:
            prefix = shlex.split(args.pop(0))
        elif option.startswith("--prefix="):
            prefix = shlex.split(option.split("=", 1)[1])
        else:
            sys.stderr.write(f"bfr run: unknown option '{option}'\n\n{USAGE}")
            return 2
    if not args:
        sys.stderr.write(USAGE)
        return 2
    package = args[0]
    try:
        if len(args) == 1:
            names = list_executables(package)
            sys.stdout.write("".join(f"{package} {name}\n" for name in names))
            return 0
        path = executable_path(package, args[1])
    except LookupError as exc:
        sys.stderr.write(f"bfr run: {exc}\n")
        return 1
    command = [*prefix, str(path), *args[2:]]
    sys.stdout.flush()
    sys.stderr.flush()
    try:
        os.execvp(command[0], command)
    except OSError as exc:
        sys.stderr.write(f"bfr run: cannot execute {shlex.join(command)}: {exc}\n")
        return 1
    return 1  # pragma: no cover - execvp does not return


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
