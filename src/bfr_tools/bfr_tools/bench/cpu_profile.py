"""Run a Python script under cProfile timed by its main thread's CPU clock.

``python -m bfr_tools.bench.cpu_profile OUT SCRIPT [ARGS...]`` runs ``SCRIPT`` as
``__main__`` with ``ARGS`` and writes the profile to ``OUT`` (``pstats`` format) when it
exits. The timer is ``time.thread_time`` (the main thread's user + system CPU time), not
the wall clock of ``python -m cProfile``: a node spends most of its wall time waiting for
messages, and a wall-clock profile of it shows the wait, the preemption inside system calls
(a publisher's wake-up of its readers) and the machine's other load as if they were work.
``bfr bench --only loop --profile DIR`` runs the loop's nodes this way. The Python
interpreter's overhead per call still inflates call-heavy code against compiled code, and
the DDS middleware's own threads are not in the profile (read them in /proc/<pid>/task).
"""

from __future__ import annotations

import cProfile
import runpy
import sys
import time

__all__ = ["main"]


def main(argv: list[str] | None = None) -> int:
    """Profile ``argv[1]`` (run as ``__main__`` with ``argv[2:]``) into ``argv[0]``."""
    args = list(sys.argv[1:] if argv is None else argv)
    if len(args) < 2 or args[0] in ("-h", "--help"):
        print("usage: python -m bfr_tools.bench.cpu_profile OUT SCRIPT [ARGS...]",
              file=sys.stderr)
        return 2
    out, script = args[0], args[1]
    sys.argv = args[1:]
    prof = cProfile.Profile(time.thread_time)
    status = 0
    prof.enable()
    try:
        runpy.run_path(script, run_name="__main__")
    except SystemExit as exc:
        status = exc.code if isinstance(exc.code, int) else 0
    finally:
        prof.disable()
        prof.dump_stats(out)
    return status


if __name__ == "__main__":  # pragma: no cover
    raise SystemExit(main())
