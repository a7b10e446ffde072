"""Readers and writers of recordings (pure Python + numpy, no ``rclpy``).

- :mod:`bfr_model.io.rig_log`: the NTNU rig's terminal logs (``[inf] t=...`` lines).
- :mod:`bfr_model.io.csv_io`: the simulator's CSV format.
- :mod:`bfr_model.io.bag`: ROS 2 bags (rosbag2 directory, MCAP storage; sqlite3 read).
- :mod:`bfr_model.io.account`: what every read used and lost (:class:`ReadAccount`), the
  physical gates, and the one rule on losses (:func:`~bfr_model.io.account.enforce`).
- :mod:`bfr_model.io.output`: outputs written atomically, never over a file without force.
- :mod:`bfr_model.io.rig_conventions`: the analysis that inferred the rig logs' conventions.

:func:`read_recording` picks the reader from the path; :func:`read_runs` reads every run of a
rig log (or the one chosen) and any other recording as one run. Both apply the loss rule:
more than 1 % of the samples lost raises :class:`PartialReadError` unless
``allow_partial``.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from bfr_model.io.account import PartialReadError, ReadAccount, account_of, enforce
from bfr_model.io.bag import read_bag
from bfr_model.io.csv_io import read_csv
from bfr_model.io.rig_log import parse_rig_log, read_rig_log
from bfr_model.recording import Recording, RecordingError

__all__ = ["PartialReadError", "ReadAccount", "account_line", "read_recording", "read_runs"]


def _check_path(p: Path) -> None:
    """One-line errors for a path that cannot be a recording."""
    if not p.exists():
        raise RecordingError(f"{p}: no such file or directory")
    if p.is_file() and p.stat().st_size == 0:
        raise RecordingError(f"{p}: file is empty")


def read_recording(path: str | Path, *, allow_partial: bool = False,
                   **options: Any) -> Recording:
    """Read a recording, choosing the reader from the path.

    ``*.txt``: NTNU rig log; ``*.csv``: simulator CSV; a directory, ``*.mcap`` or
    ``*.db3``: ROS 2 bag. The read's account is in ``meta["read_account"]``.

    Parameters
    ----------
    path : str or Path
        The file or bag directory.
    allow_partial : bool
        Return what was read even when more than 1 % of the samples were lost.
    **options
        Passed to the reader.

    Raises
    ------
    RecordingError
        If the kind of file is not recognised (the readers raise their own errors, all
        subclasses of ValueError); :class:`PartialReadError` for a loss over 1 %.
    """
    p = Path(path)
    _check_path(p)
    suffix = p.suffix.lower()
    if suffix == ".txt":
        options.setdefault("warn", False)
        rec = read_rig_log(p, **options)
    elif suffix == ".csv":
        rec = read_csv(p, **options)
    elif p.is_dir() or suffix in (".mcap", ".db3"):
        rec = read_bag(p, **options)
    else:
        raise RecordingError(f"{p}: unknown recording kind (expected .txt rig log, .csv, or a "
                             f"ROS 2 bag directory / .mcap / .db3)")
    acc = account_of(rec)
    if acc is not None:
        enforce(acc, allow_partial)
    return rec


def read_runs(path: str | Path, run: str | int | None = None, *, allow_partial: bool = False,
              topic_map: dict[str, str] | None = None) -> list[Recording]:
    """The runs of a recording: every run of a rig log (or the one chosen), else the one.

    Parameters
    ----------
    path : str or Path
        The file or bag directory.
    run : int or "all", optional
        Run of a rig log (default: all); only rig logs have several.
    allow_partial : bool
        Use what was read even when more than 1 % of the file's samples were lost (the rule
        is applied to the file: all runs read together).
    topic_map : dict, optional
        Topic per role for a bag (:func:`bfr_model.io.bag.read_bag`).

    Raises
    ------
    RecordingError
        Unreadable input (one line), or :class:`PartialReadError`.
    """
    p = Path(path)
    _check_path(p)
    if p.suffix.lower() != ".txt":
        if run is not None and run != "all":
            raise RecordingError(f"{p}: a run can be chosen in rig logs (.txt) only")
        opts: dict[str, Any] = {"topic_map": topic_map} if topic_map else {}
        return [read_recording(p, allow_partial=allow_partial, **opts)]
    log = parse_rig_log(p, warn=False)
    if run is None or run == "all":
        ks = list(range(len(log.runs)))
    else:
        try:
            ks = [log.run_index(int(run))]
        except ValueError:
            raise RecordingError(f"run {run!r}: expected an index or 'all'") from None
    accounts = [r.account for r in log.runs if r.account is not None]
    if accounts:
        enforce(ReadAccount.combine(accounts), allow_partial)
    out = []
    for k in ks:
        out.append(log.recording(k))
        run = log.runs[k]  # its numbers are in the recording now: free the raw copy
        run.data, run.lines = run.data[:0], run.lines[:0]
        run.ball_off = None if run.ball_off is None else run.ball_off[:0]
    return out


def account_line(recs: list[Recording]) -> str:
    """One line: the account of the recordings read from one source (runs combined)."""
    accounts = [a for a in (account_of(r) for r in recs) if a is not None]
    if not accounts:
        return f"read {len(recs)} recording(s): no account (not read from a file)"
    return ReadAccount.combine(accounts).line()
