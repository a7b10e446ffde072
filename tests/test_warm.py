"""``bfr warm``: every group's steps run (the second group in a worker process) and say so.

Run after scripts/setup has warmed the caches, so each step takes seconds; what it checks is
that every step still runs the code it names (a renamed API would fail here, not at a
node's cold start) and that the side-by-side groups report every step.
"""

from __future__ import annotations

import pickle
import subprocess
import sys

import pytest

from bfr_tools import warm


def _run(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "bfr_tools.warm", *args], capture_output=True,
                          text=True, timeout=900, check=False)


def test_every_step_runs_in_two_processes() -> None:
    run = _run("--jobs", "2")
    assert run.returncode == 0, run.stderr[-2000:]
    steps = [name for group in warm.GROUPS.values() for name in group]
    assert len(steps) == 6 and len(warm.GROUPS) == 2
    lines = run.stdout.splitlines()
    for name in steps:
        assert sum(line.startswith(f"warm: {name}: ") for line in lines) == 1, (name, lines)


@pytest.mark.parametrize("jobs", ["0", "-1", "two"])
def test_bad_jobs_is_one_line_and_exit_2(jobs: str) -> None:
    run = _run("--jobs", jobs)
    assert run.returncode == 2 and "--jobs" in run.stderr and "Traceback" not in run.stderr
    assert run.stdout == ""


def test_a_failing_step_is_named_in_one_line_with_exit_1(monkeypatch, capsys) -> None:  # noqa: ANN001
    """``--jobs 1``, in this process; a worker raises the same error, which must survive
    the trip to the parent (pickled)."""
    def broken() -> None:
        raise ValueError("no gains for these parameters")

    monkeypatch.setattr(warm, "GROUPS", {"first": {"fine step": lambda: None},
                                         "second": {"broken step": broken}})
    assert warm.main(["--jobs", "1"]) == 1
    out, err = capsys.readouterr()
    assert out.splitlines() == [line for line in out.splitlines()
                                if line.startswith("warm: fine step: ")] and out
    assert err.strip().splitlines() == [
        "bfr warm: error: broken step: ValueError: no gains for these parameters"], err
    again = pickle.loads(pickle.dumps(warm.WarmError("broken step: ValueError: x")))
    assert isinstance(again, warm.WarmError) and str(again) == "broken step: ValueError: x"
