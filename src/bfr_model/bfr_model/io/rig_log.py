"""Parser of the NTNU Butterfly rig's terminal logs (``../shared/data/ntnu-rig/*.txt``).

Each data line reads::

    [inf] t=<s>,torque=<N m>,theta=<rad>,phi=<rad>,dtheta=<rad/s>,dphi=<rad/s>,x=<m>,y=<m>

Everything else (``script`` headers, shell prompts, ANSI escape codes, carriage returns,
build output, ``[obs]`` lines, other ``[inf]`` messages) is noise: it is skipped and counted
per reason in :attr:`RigLog.skipped`. ``[inf] initializing hardware..`` starts a new run
(one file may hold several runs whose clocks restart, e.g. ``step_response_tau_001``);
``[inf] ball was lost`` marks the held camera fix as stale.

Every data line is accounted for (:mod:`bfr_model.io.account`): the file is read line by
line (its numbers go straight into float arrays; the text is never held), each run's lines
pass the physical gates, and the run's :class:`~bfr_model.io.account.ReadAccount`
(``RigRun.account``, ``meta["read_account"]``) counts those not used by cause: ``corrupt``
(a line with keys missing or a value that is not a number, a line cut by another, a line
so damaged that only most of its keys are left; the first is named with the fields expected
and found), ``truncated`` (the last line cut off), ``duplicate``, ``out_of_order``,
``out_of_range``, ``non_finite``. Unparseable lines between two data lines of a run (not
a prompt after the program stopped) are ``garbage``: not samples, but counted in the
account and the notes with the first line, and the read refused past 1 % of the lines
(:mod:`bfr_model.io.account`). LF, CRLF and CR-only (old Mac) line ends are read alike
(:func:`parse_rig_log`); stamps counting from an epoch are rebased to the run's first
(:data:`EPOCH_STAMPS`).

Another rig's logger may print the same fields otherwise: another tag or a time stamp before
them (``[dbg] t=...``, ``2021-05-01 18:05:19.123 INFO t=...``, none), the keys in another
order, spaces after the commas, fields of its own (``mode=2``, ``u_ref=0.5``). The data lines'
form is read off the file itself (:class:`LineDialect`, the most common form of the
``key=value`` lines holding every key of :data:`KEYS` among the first lines): the values are
taken by key, other fields are left out, and ``meta["conversions"]`` says which form was
read and which fields were not used. The NTNU rig's own form is read by the fast path above.

The conventions of the format were inferred from the NTNU rig's logs
(docs/ntnu-rig-conventions.md, ``python -m bfr_model.io.rig_conventions``) and are applied by
:func:`run_to_recording`. What is a fact of one rig (its timing) is never assumed: it is
measured on every run (:mod:`bfr_model.io.timing`) and reported in
``meta["sensor_timing"]``.

- ``theta`` has our sign (counter-clockwise positive, theta and phi advance together) and
  its zero agrees with ours modulo pi; it is printed with 6 significant digits, so its
  resolution is 1 mrad for |theta| in [100, 1000) rad and 10 mrad above, unless its changes
  show an encoder lattice coarser than that (:func:`encoder_step`, measured per run and
  named in ``meta["conversions"]``).
- ``torque`` has our sign: a positive command accelerates ``theta`` positive.
- ``x, y`` are the camera's ball centre in the world frame [m] (0, 0 = no ball), held
  between camera frames. Any ratio of log lines to camera fixes is read (the NTNU rig: a
  fix every 5-7 lines of a ~920 Hz loop; another rig may log one line per fix). A camera
  that queued frames since program start replays them faster than it can take them at
  start-up (the NTNU rig: ~0.9 s at the loop rate): such a burst is detected on the fixes'
  own intervals (:func:`bfr_model.io.timing.camera_backlog_end`) and marked invalid.
- The rig's ``phi`` is ``theta[k - L] + atan2(x, y)`` at each new fix k: its software pairs
  each image with the frame angle logged L samples earlier (the NTNU rig: L = 8). L is
  measured on each run (:func:`phi_pairing_lag`; 0 when the log's phi does not follow the
  rule at any lag) and ``phi`` of the recording is recomputed with it (full precision of
  x, y; defined before the rig's phi estimator initialises).
- ``dtheta`` is the servo's velocity estimate; its lag behind the rate of ``theta`` is
  measured per run (:func:`bfr_model.io.timing.velocity_lag`; the NTNU rig: 6.4 ms) and
  reported, not applied here (the recording keeps the logged values). A NaN ``dtheta`` is
  a missing velocity sample: the line is kept and its velocity filled between its
  neighbours (counted in the notes). ``dphi`` is a filtered derivative of ``phi`` updated at
  each fix.

:func:`format_rig_log` and :func:`write_rig_log` write recordings in the same format (one
``initializing hardware`` block per run, numbers with 6 significant digits).

Pure Python + numpy; no ``rclpy``.
"""

from __future__ import annotations

import argparse
import dataclasses
import functools
import io
import json
import math
import re
import time
import warnings
from array import array
from collections import Counter
from collections.abc import Iterable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, BinaryIO

import numpy as np
from numpy.typing import NDArray

from bfr_model.io.account import Gates, ReadAccount, gate_samples
from bfr_model.io.timing import camera_backlog_end, line_rate, velocity_lag
from bfr_model.recording import Recording

__all__ = [
    "KEYS",
    "MAX_PHI_THETA_LAG",
    "LineDialect",
    "RigLog",
    "RigLogError",
    "RigLogWarning",
    "RigRun",
    "format_rig_log",
    "parse_rig_log",
    "parse_rig_log_text",
    "phi_pairing_lag",
    "read_rig_log",
    "run_to_recording",
    "write_rig_log",
]

#: Keys of a data line, in order, with their units.
KEYS = ("t", "torque", "theta", "phi", "dtheta", "dphi", "x", "y")
UNITS = {"t": "s", "torque": "N m", "theta": "rad", "phi": "rad", "dtheta": "rad/s",
         "dphi": "rad/s", "x": "m", "y": "m"}

#: Largest pairing lag of the log's ``phi`` searched [samples] (:func:`phi_pairing_lag`).
MAX_PHI_THETA_LAG = 24

#: Stamps beyond this [s] (3.2 years) count from an epoch (Unix time), not from the program's
#: start: the run's first stamp is subtracted as it is read (the bag reader's rule for
#: ``time_origin="auto"``). At 1.7e9 s a double resolves 0.24 us, but every fit through the
#: stamps (a camera clock's line, a lag) then loses digits to the offset.
EPOCH_STAMPS = 1e8

_DATA_RE = re.compile(
    r"\[inf\] t=([^,]*),torque=([^,]*),theta=([^,]*),phi=([^,]*),"
    r"dtheta=([^,]*),dphi=([^,]*),x=([^,]*),y=([^,]*)")
_ANSI_RE = re.compile(r"\x1b\][^\x07\x1b]*(?:\x07|\x1b\\)?|\x1b\[[0-?]*[ -/]*[@-~]|\x1b[@-_]")
_CTRL_RE = re.compile(r"[\x00-\x08\x0b-\x1f\x7f]")
#: A ``key=value`` line of any form: text without ``=`` before the first key, then fields
#: separated by commas (blanks after a comma allowed). Only for finding a log's form.
_FIELDS_RE = re.compile(
    r"(?P<prefix>[^=]*?)(?P<body>[A-Za-z_]\w*=[^,]*(?:,\s*[A-Za-z_]\w*=[^,]*)+)")
#: Lines (at most, and within the file's first bytes) looked at to find the form of a
#: log's data lines (:func:`LineDialect.find`).
DIALECT_LINES = 5000
DIALECT_BYTES = 1 << 20


@dataclass(frozen=True, kw_only=True)
class LineDialect:
    """The form of a log's data lines when it is not the NTNU rig's (module docstring).

    Attributes
    ----------
    prefix : str or None
        Text before the first key on every data line (``"[dbg] "``, ``""``); None when it
        varies from line to line (a time stamp): any text without ``=``.
    keys : tuple of str
        The keys of a data line in the file's order: every one of :data:`KEYS`, and the
        logger's own fields (not used).
    """

    prefix: str | None
    keys: tuple[str, ...]

    @functools.cached_property
    def regex(self) -> re.Pattern[str]:
        """A data line of this form; one group per key, in the file's order.

        Any text without ``=`` before the first key, whatever the prefix of the lines the
        form was found on (a time stamp that looked constant over the first lines changes
        later: a minute's, a date's).
        """
        fields = r",\s*".join(f"{re.escape(k)}=([^,]*)" for k in self.keys)
        return re.compile(rf"[^=]*?{fields}\s*")

    @functools.cached_property
    def order(self) -> tuple[int, ...]:
        """Group index (0-based) of each of :data:`KEYS`."""
        return tuple(self.keys.index(k) for k in KEYS)

    @property
    def unused(self) -> tuple[str, ...]:
        """The logger's own fields, not read."""
        return tuple(k for k in self.keys if k not in KEYS)

    def describe(self) -> str:
        """What the reader says it did (``meta["conversions"]``)."""
        head = ("a time stamp or other text before the first key" if self.prefix is None
                else f"prefix {self.prefix!r}" if self.prefix else "no prefix")
        unused = (f"; field(s) not used: {', '.join(self.unused)}" if self.unused
                  else "")
        return (f"data lines read by key in this log's form (not the NTNU rig's '[inf] "
                f"t=...,torque=...'): {head}, keys {','.join(self.keys)}{unused}")

    @classmethod
    def find(cls, lines: Iterable[str]) -> LineDialect | None:
        """The form of the data lines among ``lines``; None for the NTNU rig's own form.

        The most common ``key=value`` form whose keys include every one of :data:`KEYS`
        (each once); its prefix is the one all its lines share, else None (any text). None
        also when no line has every key (the reader then says what it found).
        """
        forms: Counter[tuple[str, ...]] = Counter()
        prefixes: dict[tuple[str, ...], set[str]] = {}
        standard = 0
        for raw in lines:
            line = raw.rstrip("\r")
            if _DATA_RE.fullmatch(line):
                standard += 1
                continue
            if line.count("=") < len(KEYS) or len(line) > 4096:  # not one data line
                continue
            clean = _clean_terminal_line(line)
            if _DATA_RE.fullmatch(clean):  # the rig's form behind escape codes
                standard += 1
                continue
            m = _FIELDS_RE.fullmatch(clean)
            if m is None:
                continue
            keys = tuple(f.split("=", 1)[0].strip() for f in m["body"].split(","))
            if len(set(keys)) != len(keys) or not set(KEYS) <= set(keys):
                continue
            forms[keys] += 1
            prefixes.setdefault(keys, set()).add(m["prefix"])
        if not forms:
            return None
        keys, count = forms.most_common(1)[0]
        if standard >= count:
            return None
        seen = prefixes[keys]
        return cls(prefix=next(iter(seen)) if len(seen) == 1 else None, keys=keys)

    def looks_like_data(self, line: str) -> bool:
        """At least half of this form's keys (as ``key=``) in ``line``: a damaged data line."""
        return sum(f"{k}=" in line for k in self.keys) >= len(self.keys) // 2 + 1


class RigLogError(ValueError):
    """A rig log cannot be parsed; the message names the file, line and problem."""


class RigLogWarning(UserWarning):
    """A recoverable oddity in a rig log (e.g. a truncated final line)."""


@dataclass
class RigRun:
    """The raw data lines of one run (between two ``initializing hardware`` markers).

    Attributes
    ----------
    data : ndarray, shape (n, 8)
        Values in the order of :data:`KEYS`, as logged (rig conventions and units), of the
        samples the physical gates kept (:func:`bfr_model.io.account.gate_samples`).
    lines : ndarray of int, shape (n,)
        1-based line number of each sample in the file.
    events : list of (int, str)
        ``(sample index, message)`` of ``[inf]`` messages inside the run (e.g. ``ball was
        lost``); the index is that of the first sample after the message.
    dropped_duplicates : int
        Samples dropped because their timestamp repeated the previous one.
    ball_off : ndarray of bool, shape (n,), optional
        Samples whose held ball position is off the frame (excluded from the ball fields).
    account : ReadAccount, optional
        What the run's lines held and what was used (:mod:`bfr_model.io.account`).
    nan_ball : int
        Kept samples whose ball centre was logged as NaN, read as "no ball" (x = y = 0).
    garbage : tuple of int
        Line numbers of the unparseable lines among the run's data lines (skipped; not
        samples; :class:`~bfr_model.io.account.ReadAccount`'s ``garbage``).
    nan_dtheta : (int, str)
        Kept samples whose servo velocity ``dtheta`` was logged as NaN (their angle, torque
        and fix used), and how their velocity was filled (``data`` holds the filled value).
    time_origin : float
        Stamp [s] subtracted from the run's ``t`` column (its first, when the stamps count
        from an epoch: :data:`EPOCH_STAMPS`; else 0).
    turns : ndarray, shape (n,), optional
        Whole turns [rad] added to ``theta`` and ``phi`` of each sample where the log
        reported its angle within a turn (:func:`bfr_model.turns.unwrap_turns`); None when
        it accumulates, as the format means.
    """

    data: NDArray[np.float64]
    lines: NDArray[np.int64]
    events: list[tuple[int, str]] = field(default_factory=list)
    dropped_duplicates: int = 0
    ball_off: NDArray[np.bool_] | None = None
    account: ReadAccount | None = None
    nan_ball: int = 0
    garbage: tuple[int, ...] = ()
    nan_dtheta: tuple[int, str] = (0, "")
    time_origin: float = 0.0
    turns: NDArray[np.float64] | None = None

    def column(self, key: str) -> NDArray[np.float64]:
        """One raw column by key (see :data:`KEYS`)."""
        return self.data[:, KEYS.index(key)]

    def __len__(self) -> int:
        """Number of samples."""
        return int(self.data.shape[0])


@dataclass
class RigLog:
    """A parsed rig log: its runs, the skipped lines by reason, and warnings.

    Attributes
    ----------
    source : str
        Path (or label) of the parsed text.
    n_lines : int
        Lines in the file.
    n_data : int
        Complete data lines (including samples the gates later dropped).
    skipped : dict of str to int
        Skipped lines per reason: ``empty``, ``terminal`` (prompts, escape codes, build
        output), ``info`` (other ``[inf]`` messages), ``obs`` (``[obs]`` lines),
        ``partial`` (a data line cut short by another line), ``truncated_final`` (the last
        line cut off), ``malformed`` (keys missing, unknown or out of order, or a value that
        is not a number), ``duplicate_time`` (samples dropped for a repeated timestamp),
        ``garbage`` (unparseable lines between two data lines of one run: not what a rig
        writes there; counted in the run's account and notes, the read refused past 1 %).
    warnings : list of str
        Recoverable problems with their line numbers.
    runs : list of RigRun
        Runs in file order.
    conversions : list of str
        What was done to the file as a whole (e.g. CR-only line ends read as line ends);
        added to each recording's ``meta["conversions"]``.
    """

    source: str
    n_lines: int
    n_data: int
    skipped: dict[str, int]
    warnings: list[str]
    runs: list[RigRun]
    conversions: list[str] = field(default_factory=list)

    def run_index(self, run: int | None) -> int:
        """Resolve a run selector: None is the longest run, negative counts from the end."""
        if run is None:
            return int(np.argmax([len(r) for r in self.runs]))
        k = run + len(self.runs) if run < 0 else run
        if not 0 <= k < len(self.runs):
            raise RigLogError(f"{self.source}: run {run} requested but the log holds "
                              f"{len(self.runs)} run(s)")
        return k

    def recording(self, run: int | None = None, **options: Any) -> Recording:
        """The selected run as a :class:`Recording` in our conventions.

        ``meta["read_account"]`` is the run's :class:`~bfr_model.io.account.ReadAccount`.

        Parameters
        ----------
        run : int, optional
            Run index (default: the longest run).
        **options
            Passed to :func:`run_to_recording`.
        """
        k = self.run_index(run)
        rec = run_to_recording(self.runs[k], source=self.source, **options)
        rec.meta.update({
            "run": k,
            "runs": len(self.runs),
            "run_lengths": [len(r) for r in self.runs],
            "lines": self.n_lines,
            "data_lines": self.n_data,
            "skipped": dict(self.skipped),
            "parse_warnings": list(self.warnings),
        })
        rec.meta["conversions"] = list(self.conversions) + rec.meta["conversions"]
        if len(self.runs) > 1:
            rec.meta["notes"].append(
                f"the log holds {len(self.runs)} runs (clock restarts); run {k} selected")
        return rec


def _classify_malformed(line: str) -> tuple[str, str]:
    """Classify a line that starts like a data line but does not match it.

    Returns ``("partial", detail)`` when it is a cut-off prefix of a data line and
    ``("malformed", detail)`` when keys are missing, unknown or out of order.
    """
    body = line[len("[inf] "):]
    parts = body.split(",")
    keys = [p.split("=", 1)[0] for p in parts]
    if len(keys) <= len(KEYS) and keys[:-1] == list(KEYS[: len(keys) - 1]) and \
            KEYS[len(keys) - 1].startswith(keys[-1]):
        return "partial", (f"cut after {len(keys) - 1} complete field(s) of the "
                           f"{len(KEYS)} expected")
    count = f"{len(parts)} field(s) found where {len(KEYS)} expected"
    missing = [k for k in KEYS if k not in keys]
    unknown = [k for k in keys if k not in KEYS]
    if missing:
        return "malformed", f"missing key(s) {', '.join(map(repr, missing))} ({count})"
    if unknown:
        return "malformed", f"unknown key(s) {', '.join(map(repr, unknown))} ({count})"
    return "malformed", f"keys out of order or repeated: {keys} ({count})"


def _clean_terminal_line(line: str) -> str:
    """What a terminal shows of ``line``: escape codes, overwritten text and controls removed.

    Text after the last carriage return is what the terminal shows (unless it is blank, then
    the carriage returns are only dropped); the result is stripped of surrounding blanks.
    """
    clean = _ANSI_RE.sub("", line)
    if "\r" in clean:
        tail = clean.rsplit("\r", 1)[-1]
        clean = tail if tail.strip() else clean.replace("\r", "")
    return _CTRL_RE.sub("", clean).strip()


@dataclass(kw_only=True)
class _RunRows:
    """The data rows of one run as scanned (mutable), values already as floats.

    The values are appended to flat ``array('d')`` buffers (8 per row, 8 bytes each), so a
    run costs its numbers and nothing per line (the log is read line by line).

    Attributes
    ----------
    values : array of float
        The values of each data line, in the order of :data:`KEYS`, row after row.
    lines : array of int
        1-based line number of each row.
    events : list of (int, str)
        ``(row index, message)`` of ``[inf]`` messages, as in :attr:`RigRun.events`.
    lost : dict of str to list of int
        Line numbers of the lines of this run lost before the gates, per account cause
        (``corrupt``: malformed or not a number or cut by another line; ``truncated``: the
        last line cut off).
    details : dict of str to str
        What was wrong with the first line lost of each cause (for the account's actions).
    garbage : list of int
        Line numbers of unparseable lines among this run's data lines
        (:class:`~bfr_model.io.account.ReadAccount`'s ``garbage``).
    """

    values: array = field(default_factory=lambda: array("d"))
    lines: array = field(default_factory=lambda: array("q"))
    events: list[tuple[int, str]] = field(default_factory=list)
    lost: dict[str, list[int]] = field(default_factory=dict)
    details: dict[str, str] = field(default_factory=dict)
    garbage: list[int] = field(default_factory=list)

    def __len__(self) -> int:
        """Number of rows."""
        return len(self.lines)


@dataclass(kw_only=True)
class _LogScan:
    """State of one pass over the lines of a log (mutable): runs so far, skips, warnings.

    Attributes
    ----------
    source : str
        Name used in messages.
    duplicates : str
        Policy for repeated time stamps (see :func:`parse_rig_log_text`).
    gates : Gates or None
        Bounds of the physical gates (None: rig.yaml's).
    current : _RunRows
        The run being filled.
    runs : list of RigRun
        Finished runs in file order (each finished as soon as the next one starts).
    skipped : Counter
        Skipped lines per reason (see :attr:`RigLog.skipped`).
    warnings : list of str
        Recoverable problems with their line numbers.
    new_run_pending : bool
        A restart marker was seen: the next data line starts a new run.
    pending_events : list of str
        Messages after a restart marker, before the next run's first line (they belong to
        that run, at its first sample).
    pending_partial : tuple or None
        ``(line number, detail, run rows)`` of a cut-off data line at the end of its line:
        a ``truncated_final`` line if no non-blank line follows, else ``partial``.
    n_lines, n_data : int
        Lines and complete data lines so far.
    last_nonblank : int
        Line number of the latest non-blank line.
    dropped_runs : list of RigRun
        Runs of which the gates kept no sample (accounted, not returned).
    pending_noise : list of int
        Line numbers of unrecognised (``terminal``) lines since the current run's latest
        data line: garbage if another data line of the run follows, else terminal output
        (a prompt after the program stopped).
    dialect : LineDialect or None
        The form of the data lines when it is not the NTNU rig's.
    """

    source: str
    duplicates: str = "drop"
    gates: Gates | None = None
    dialect: LineDialect | None = None
    current: _RunRows = field(default_factory=_RunRows)
    runs: list[RigRun] = field(default_factory=list)
    skipped: Counter[str] = field(default_factory=Counter)
    warnings: list[str] = field(default_factory=list)
    new_run_pending: bool = False
    pending_events: list[str] = field(default_factory=list)
    pending_partial: tuple[int, str, _RunRows] | None = None
    n_lines: int = 0
    n_data: int = 0
    last_nonblank: int = 0
    dropped_runs: list[RigRun] = field(default_factory=list)
    pending_noise: list[int] = field(default_factory=list)

    def add_noise(self, lineno: int) -> None:
        """Count an unrecognised line: terminal output, or garbage once data follows."""
        self.skipped["terminal"] += 1
        if len(self.current) and not self.new_run_pending:
            self.pending_noise.append(lineno)

    def add_data(self, groups: tuple[str, ...], lineno: int) -> None:
        """Append a data row, first starting a new run after a restart marker.

        A value that is not a number makes the line ``corrupt`` (counted, warned).
        """
        if self.new_run_pending and len(self.current):
            self.finish_current()
        if self.pending_noise and not self.new_run_pending:
            # unrecognised lines between two data lines of one run: garbage, not a prompt
            self.skipped["terminal"] -= len(self.pending_noise)
            self.skipped["garbage"] += len(self.pending_noise)
            self.current.garbage += self.pending_noise
        self.pending_noise = []
        self.new_run_pending = False
        if self.pending_events:
            self.current.events += [(len(self.current), m) for m in self.pending_events]
            self.pending_events = []
        try:
            row = [float(g) for g in groups]
        except ValueError:
            bad = next(k for k, g in zip(KEYS, groups, strict=True) if not _is_float(g))
            msg = (f"{self.source}:{lineno}: value of {bad!r} is not a number: "
                   f"{groups[KEYS.index(bad)]!r}")
            self.lose("corrupt", "malformed", lineno, msg,
                      detail=f"value of {bad!r} is not a number")
            return
        self.n_data += 1
        self.current.values.extend(row)
        self.current.lines.append(lineno)

    def lose(self, cause: str, reason: str, lineno: int, warning: str,
             rows: _RunRows | None = None, detail: str = "") -> None:
        """Count a data line lost before the gates (``cause`` of the account).

        ``detail`` says what was wrong with it (kept for the first line of each cause).
        """
        self.skipped[reason] += 1
        self.warnings.append(warning)
        target = rows or self.current
        target.lost.setdefault(cause, []).append(lineno)
        if detail:
            target.details.setdefault(cause, f"{reason}: {detail}")

    def add_info(self, msg: str) -> None:
        """Count an ``[inf]`` message: a restart marker, or an event of the current run."""
        self.skipped["info"] += 1
        if msg.startswith(("initializing hardware", "stopped")):
            self.new_run_pending = True
            self.pending_noise = []
        elif self.new_run_pending:
            self.pending_events.append(msg)
        else:
            self.current.events.append((len(self.current), msg))

    def resolve_partial(self, final: bool) -> None:
        """Settle a pending cut-off line: ``truncated_final`` at the end, else ``partial``."""
        if self.pending_partial is None:
            return
        lineno, detail, rows = self.pending_partial
        self.pending_partial = None
        if final:
            self.lose("truncated", "truncated_final", lineno,
                      f"{self.source}:{lineno}: truncated final line skipped ({detail})", rows,
                      detail=detail)
        else:
            self.lose("corrupt", "partial", lineno,
                      f"{self.source}:{lineno}: partial data line skipped ({detail})", rows,
                      detail=detail)

    def finish_current(self) -> None:
        """Convert, gate and account the run being filled; start a new one."""
        rows = self.current
        self.current = _RunRows()
        if len(rows) or rows.lost:
            run = _finish_run(rows, self.source, self.duplicates, self.gates)
            if len(run):
                self.runs.append(run)
            else:
                self.warnings.append(f"{self.source}: a run of {run.account.samples_present} "
                                     f"line(s) kept no sample: {run.account.line()}")
                self.dropped_runs.append(run)
            self.skipped["duplicate_time"] += run.dropped_duplicates


def _is_float(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


#: Keys after the first of a data line, as they appear in it.
_LATER_KEYS = tuple(f",{k}=" for k in KEYS[1:])


def _looks_like_data(line: str) -> bool:
    """A line holding at least half of a data line's keys: a damaged data line, not noise.

    One damaged byte (a flipped bit, a stray carriage return or escape) breaks at most one
    key; such a line is lost data and counted ``corrupt``, never skipped as noise.
    """
    return sum(k in line for k in _LATER_KEYS) >= len(_LATER_KEYS) // 2 + 1


def _scan_data_segments(scan: _LogScan, text: str, lineno: int) -> None:
    """Parse ``text``, one or more data lines run together (``[inf] t=...[inf] t=...``).

    Complete segments are added as data. A cut-off segment ending the line may be the
    file's truncated last line (settled by the next non-blank line); other cut-off or
    malformed segments are ``corrupt`` lines, counted and warned.
    """
    segments = [s for s in text.split("[inf] ")[1:] if s]
    for j, seg in enumerate(segments):
        seg_line = "[inf] " + seg
        m = _DATA_RE.fullmatch(seg_line)
        if m is not None:
            scan.add_data(m.groups(), lineno)
            continue
        kind, detail = _classify_malformed(seg_line)
        if kind == "partial" and j == len(segments) - 1:
            scan.pending_partial = (lineno, detail, scan.current)
        elif kind == "partial":
            scan.lose("corrupt", "partial", lineno,
                      f"{scan.source}:{lineno}: partial data line skipped ({detail})",
                      detail=detail)
        else:
            scan.lose("corrupt", "malformed", lineno,
                      f"{scan.source}:{lineno}: malformed data line skipped: {detail}: "
                      f"{seg_line[:120]!r}", detail=detail)


def _scan_line(scan: _LogScan, raw: str, lineno: int) -> None:
    """Sort line ``lineno`` (1-based) into a data row, a run marker or event, or noise.

    Several data lines joined by carriage returns (CR line ends inside a file of LF ones,
    or an LF lost) are each read: a terminal overwrites a line's text at a carriage return
    (what follows the last one is what it shows), but no rig overwrites one data line by
    another, so there a carriage return ends a line.
    """
    line = raw[:-1] if raw.endswith("\r") else raw
    if scan.dialect is not None:
        _scan_dialect_line(scan, scan.dialect, line, lineno)
        return
    m = _DATA_RE.fullmatch(line)
    if m is not None:
        scan.resolve_partial(final=False)
        scan.last_nonblank = lineno
        scan.add_data(m.groups(), lineno)
        return
    if "\r" in line and line.count("[inf] t=") > 1:
        for piece in line.split("\r"):
            if piece.strip():
                _scan_line(scan, piece, lineno)
        return
    # Slow path: noise, or a data line wrapped in escape codes / carriage returns.
    clean = _clean_terminal_line(line)
    rest = "[inf] t=" not in clean and _looks_like_data(line)
    if rest and scan.pending_partial is not None and scan.pending_partial[0] == lineno - 1:
        # the rest of the data line cut off on the line before (a line end inside it): one
        # data line lost, not two
        first, _, rows = scan.pending_partial
        scan.pending_partial = None
        scan.last_nonblank = lineno
        scan.lose("corrupt", "malformed", first,
                  f"{scan.source}:{first}: data line split over lines {first} and {lineno} "
                  "skipped", rows, detail=f"split over lines {first} and {lineno}")
        return
    if clean:
        scan.resolve_partial(final=False)
        scan.last_nonblank = lineno
    m = _DATA_RE.fullmatch(clean)
    if m is not None:
        scan.add_data(m.groups(), lineno)
    elif rest:
        found = sum(k in line for k in _LATER_KEYS)
        detail = (f"its start '[inf] t=' damaged, {found} of the {len(_LATER_KEYS)} later "
                  f"keys found")
        scan.lose("corrupt", "malformed", lineno,
                  f"{scan.source}:{lineno}: damaged data line skipped ({detail}): "
                  f"{line[:120]!r}", detail=detail)
    elif not clean:
        scan.skipped["empty"] += 1
    elif clean.startswith("[obs]"):
        scan.skipped["obs"] += 1
    elif (pos := clean.find("[inf] t=")) >= 0:
        _scan_data_segments(scan, clean[pos:], lineno)
    elif clean.startswith("[inf]") and "[inf] t=".startswith(clean):
        scan.pending_partial = (lineno, "cut inside the line's prefix", scan.current)
    elif clean.startswith("[inf]"):
        scan.add_info(clean[len("[inf]"):].strip())
    elif "[inf] t=".startswith(clean) and line == clean:
        scan.pending_partial = (lineno, "cut inside the line's prefix", scan.current)
    else:
        scan.add_noise(lineno)


def _scan_dialect_line(scan: _LogScan, dialect: LineDialect, line: str, lineno: int) -> None:
    """:func:`_scan_line` for a log whose data lines have another form (:class:`LineDialect`).

    A data line is read by key (escape codes and carriage returns removed as a terminal
    would); a line with half of the keys or more is a damaged data line (``corrupt``, or
    the file's ``truncated`` last line when its keys are the first of a data line's);
    ``[inf]`` / ``[obs]`` lines and other text as in the NTNU rig's logs.
    """
    regex = dialect.regex
    m = regex.fullmatch(line)
    if m is None and "\r" in line:  # data lines joined by carriage returns: each is read
        pieces = [piece for piece in line.split("\r") if piece.strip()]
        if sum(dialect.looks_like_data(piece) for piece in pieces) > 1:
            for piece in pieces:
                _scan_dialect_line(scan, dialect, piece, lineno)
            return
    clean = line if m is not None else _clean_terminal_line(line)
    if m is None:
        m = regex.fullmatch(clean)
    if m is not None:
        scan.resolve_partial(final=False)
        scan.last_nonblank = lineno
        groups = m.groups()
        scan.add_data(tuple(groups[i] for i in dialect.order), lineno)
        return
    if clean:
        scan.resolve_partial(final=False)
        scan.last_nonblank = lineno
    found = _dialect_fields(dialect, clean)
    if not clean:
        scan.skipped["empty"] += 1
    elif (found and len(found) <= len(dialect.keys) and found[:-1] == dialect.keys[:len(found) - 1]
          and dialect.keys[len(found) - 1].startswith(found[-1])):
        scan.pending_partial = (lineno, f"cut after {len(found) - 1} complete field(s) of the "
                                f"{len(dialect.keys)} expected", scan.current)
    elif dialect.looks_like_data(clean):
        detail = f"fields {','.join(found)} where {','.join(dialect.keys)} expected"
        scan.lose("corrupt", "malformed", lineno, f"{scan.source}:{lineno}: malformed data "
                  f"line skipped: {detail}: {clean[:120]!r}", detail=detail)
    elif clean.startswith("[obs]"):
        scan.skipped["obs"] += 1
    elif clean.startswith("[inf]"):
        scan.add_info(clean[len("[inf]"):].strip())
    else:
        scan.add_noise(lineno)


def _dialect_fields(dialect: LineDialect, clean: str) -> tuple[str, ...]:
    """The keys (file order) of a line that may be a cut or damaged data line of ``dialect``.

    Empty when no key (``name=``) is in the line; the fields from the form's prefix on, else
    from the first key.
    """
    if dialect.prefix is not None and clean.startswith(dialect.prefix):
        body = clean[len(dialect.prefix):]
    else:
        m = _FIRST_KEY_RE.search(clean)
        if m is None:
            return ()
        body = clean[m.start():]
    return tuple(f.split("=", 1)[0].strip() for f in body.split(","))


#: Where the fields of a line begin when the prefix varies (a key, then ``=``).
_FIRST_KEY_RE = re.compile(r"(?<![\w.])[A-Za-z_]\w*=")


def _finish_run(raw: _RunRows, source: str, duplicates: str,
                gates: Gates | None = None) -> RigRun:
    """Gate and account the rows of one run (:func:`bfr_model.io.account.gate_samples`).

    Raises
    ------
    RigLogError
        With ``duplicates="error"``, a repeated timestamp.
    """
    lines = np.frombuffer(raw.lines, dtype=np.int64) if len(raw) else np.zeros(0, np.int64)
    data = (np.frombuffer(raw.values, dtype=np.float64).reshape(-1, len(KEYS)) if len(raw)
            else np.zeros((0, len(KEYS))))
    col = {k: data[:, j] for j, k in enumerate(KEYS)}
    # a NaN ball centre is the camera's "no ball" (as x = y = 0), not a sample to drop: the
    # encoder and torque of its line are good. The rig's phi and dphi are not needed (phi
    # is recomputed from theta and the fix, dphi used only where finite).
    no_xy = np.isnan(col["x"]) | np.isnan(col["y"])
    if no_xy.any():
        data = data.copy()
        data[no_xy, KEYS.index("x")] = 0.0
        data[no_xy, KEYS.index("y")] = 0.0
        col = {k: data[:, j] for j, k in enumerate(KEYS)}
    no_ball = (col["x"] == 0.0) & (col["y"] == 0.0)
    # a NaN servo velocity is a missing velocity sample, not a missing line: the angle,
    # torque and fix of the line are good; its dtheta is filled below (_fill_velocity)
    no_dtheta = np.isnan(col["dtheta"])
    g = gate_samples(col["t"], col["theta"], np.where(no_dtheta, 0.0, col["dtheta"]),
                     col["torque"],
                     np.where(no_ball, np.nan, col["x"]), np.where(no_ball, np.nan, col["y"]),
                     rates=(col["dphi"],), gates=gates)
    if g.dropped.get("duplicate") and duplicates == "error":
        k = g.first["duplicate"]
        raise RigLogError(f"{source}:{lines[k]}: duplicate timestamp t={float(col['t'][k])!r} "
                          f"(same as line {lines[k - 1]}); {g.dropped['duplicate']} "
                          f"duplicate(s) in this run")
    keep = g.keep
    turns = None
    if g.wraps:  # an encoder reported within a turn: the accumulating angle (account.py)
        data = data.copy()
        turns = np.nan_to_num(g.theta - data[:, KEYS.index("theta")])
        data[:, KEYS.index("theta")] = g.theta
        data[:, KEYS.index("phi")] += turns  # the rig's phi is on its theta's branch
    events = [(int(np.count_nonzero(keep[:e])), msg) for e, msg in raw.events]
    account = g.account(source=source, kind="rig_log", t=col["t"], lines=lines,
                        lost=raw.lost, unit="line", details=raw.details, garbage=raw.garbage)
    kept = data[keep]
    origin = 0.0
    if kept.shape[0] and abs(float(kept[0, 0])) > EPOCH_STAMPS:
        # an epoch clock: its first stamp subtracted now, in double precision (exact: the
        # stamps lie within a factor 2 of it), before anything fits a line through them
        origin = float(kept[0, 0])
        kept[:, 0] -= origin
    filled = _fill_velocity(kept, no_dtheta[keep])
    if filled[0]:
        first = int(lines[keep][no_dtheta[keep]][0])
        account = dataclasses.replace(account, actions=(
            *account.actions, f"velocity_missing: {filled[0]} line(s) log dtheta as NaN, "
                              f"used with theta_dot {filled[1]}, first at line {first}"))
    return RigRun(data=kept, lines=lines[keep], events=events,
                  dropped_duplicates=int(g.dropped.get("duplicate", 0)), nan_dtheta=filled,
                  time_origin=origin,
                  ball_off=g.ball_off[keep], account=account,
                  nan_ball=int(np.count_nonzero(no_xy[keep])), garbage=tuple(raw.garbage),
                  turns=None if turns is None else turns[keep])


def _fill_velocity(data: NDArray[np.float64], missing: NDArray[np.bool_]) -> tuple[int, str]:
    """Fill the missing (NaN) servo velocities of a run's kept rows in place.

    Linear in time between the nearest logged velocities (held at the ends); when the run
    logs none, the rate of the angle (central differences). Returns how many were filled
    and how (for the recording's notes).
    """
    n = int(np.count_nonzero(missing))
    if n == 0:
        return 0, ""
    t = data[:, KEYS.index("t")]
    j = KEYS.index("dtheta")
    have = ~missing
    if have.any():
        data[missing, j] = np.interp(t[missing], t[have], data[have, j])
        return n, "interpolated linearly in time between the nearest logged values"
    theta = data[:, KEYS.index("theta")]
    data[:, j] = np.gradient(theta, t) if t.size > 1 else 0.0
    return n, "the run logs none: the rate of theta (central differences) instead"


def _scan(lines: Iterable[str], source: str, duplicates: str,
          gates: Gates | None, dialect: LineDialect | None = None) -> RigLog:
    """One pass over ``lines`` (without their newlines); see :func:`parse_rig_log_text`.

    ``dialect``: the data lines' form when it is not the NTNU rig's (:class:`LineDialect`).
    """
    if duplicates not in ("drop", "error"):
        raise ValueError(f"duplicates must be 'drop' or 'error', got {duplicates!r}")
    scan = _LogScan(source=source, duplicates=duplicates, gates=gates, dialect=dialect)
    for lineno, raw in enumerate(lines, start=1):
        scan.n_lines = lineno
        _scan_line(scan, raw, lineno)
    scan.resolve_partial(final=True)
    if scan.n_data == 0:
        if scan.last_nonblank == 0:
            raise RigLogError(f"{source}: file is empty (no data lines)")
        counts = ", ".join(f"{k}: {v}" for k, v in sorted(scan.skipped.items()) if v) or "none"
        raise RigLogError(f"{source}: no data lines ('[inf] t=...,torque=...,...') among "
                          f"{scan.n_lines} line(s); skipped {counts}")
    scan.finish_current()
    if not scan.runs:
        why = scan.dropped_runs[0].account.line() if scan.dropped_runs else "no run"
        raise RigLogError(f"{source}: no sample passed the checks ({why})")
    skipped_out = {k: v for k, v in scan.skipped.items() if v}
    log = RigLog(source=source, n_lines=scan.n_lines, n_data=scan.n_data,
                 skipped=skipped_out, warnings=scan.warnings, runs=scan.runs)
    if dialect is not None:
        log.conversions.append(dialect.describe())
    return log


def parse_rig_log_text(text: str | bytes, source: str = "<text>", *,
                       duplicates: str = "drop", gates: Gates | None = None) -> RigLog:
    """Parse the text of a rig log.

    Every data line is accounted for: each run's
    :class:`~bfr_model.io.account.ReadAccount` (``RigRun.account``) counts the lines that
    were cut, corrupt, duplicate, out of order, out of range or not finite, and the physical
    gates (:func:`bfr_model.io.account.gate_samples`) decide which samples are kept.

    Parameters
    ----------
    text : str or bytes
        The log (bytes are decoded as UTF-8, undecodable bytes replaced).
    source : str
        Name used in messages and ``meta["source"]``.
    duplicates : {"drop", "error"}
        What to do with a sample whose timestamp equals the previous one. The rig prints
        ``t`` with 6 significant digits (0.1 ms above 10 s) and its loop sometimes runs two
        steps within one print quantum, so real logs hold a few (17-35 per file); ``"drop"``
        keeps the first and counts the rest in ``skipped["duplicate_time"]``.
    gates : Gates, optional
        Bounds of the physical gates (default: from rig.yaml).

    Returns
    -------
    RigLog

    Raises
    ------
    RigLogError
        Empty text, no data line, no sample passing the gates or, with
        ``duplicates="error"``, a repeated timestamp. The message names the line.
    """
    if isinstance(text, bytes):
        text = text.decode("utf-8", errors="replace")
    lf = text.count("\n")
    bare_cr = text.count("\r") - text.count("\r\n")
    cr_mode = bare_cr > lf
    lines = re.split(r"\r\n|\r|\n", text) if cr_mode else text.split("\n")
    if lines and lines[-1] == "":
        lines.pop()  # text ended with a newline
    log = _scan(lines, source, duplicates, gates, LineDialect.find(lines[:DIALECT_LINES]))
    if cr_mode:
        log.conversions.append(_cr_conversion(bare_cr, lf))
    return log


def _cr_conversion(bare_cr: int, lf: int) -> str:
    """What :func:`parse_rig_log` says when it read carriage returns as line ends."""
    return (f"line ends: {bare_cr} carriage return(s) alone (CR, old Mac style) and {lf} LF; "
            "CR, LF and CRLF each read as one line end")


def _line_ends(fh: BinaryIO, chunk: int = 1 << 20) -> tuple[int, int]:
    """``(LF count, count of CR not followed by LF)`` of a binary file, read in chunks."""
    lf = cr = crlf = 0
    prev_cr = False
    while block := fh.read(chunk):
        lf += block.count(b"\n")
        cr += block.count(b"\r")
        crlf += block.count(b"\r\n") + (1 if prev_cr and block[:1] == b"\n" else 0)
        prev_cr = block[-1:] == b"\r"
    return lf, cr - crlf


def _file_lines(fh: BinaryIO, cr_mode: bool = False) -> Iterator[str]:
    """The lines of a binary file, decoded one by one (UTF-8, bad bytes replaced).

    ``cr_mode``: CR, LF and CRLF each end a line (a file of CR line ends, old Mac style);
    else LF ends a line and a carriage return is the terminal's (:func:`_scan_line`).
    """
    if cr_mode:
        text = io.TextIOWrapper(fh, encoding="utf-8", errors="replace", newline=None)
        for raw_line in text:
            yield raw_line.rstrip("\n")
        text.detach()
        return
    for raw in fh:
        yield raw.rstrip(b"\n").decode("utf-8", errors="replace")


def parse_rig_log(path: str | Path, *, duplicates: str = "drop",
                  warn: bool = True, gates: Gates | None = None) -> RigLog:
    """Read and parse a rig log file line by line; see :func:`parse_rig_log_text`.

    The file is streamed: memory holds the numbers of the runs (8 floats a line), never
    the text. A first pass counts its line ends: when carriage returns alone outnumber the
    LFs (a file written with CR line ends, old Mac style), CR, LF and CRLF each end a line
    (said in ``meta["conversions"]``); else LF ends a line and a carriage return inside one
    is the terminal's (text after it overwrote text before it).

    Parameters
    ----------
    path : str or Path
        The ``.txt`` terminal log.
    duplicates : {"drop", "error"}
        Policy for repeated timestamps.
    warn : bool
        Emit a :class:`RigLogWarning` for each recoverable problem (truncated final line,
        partial lines); they are always listed in :attr:`RigLog.warnings`.
    gates : Gates, optional
        Bounds of the physical gates (default: from rig.yaml).
    """
    p = Path(path)
    gates = gates if gates is not None else Gates.from_params()
    try:
        with p.open("rb") as fh:
            lf, bare_cr = _line_ends(fh)
            fh.seek(0)
            cr_mode = bare_cr > lf  # most lines end in CR alone: CR is the line end
            head = fh.read(DIALECT_BYTES).decode("utf-8", errors="replace")
            dialect = LineDialect.find(
                (re.split(r"\r\n|\r|\n", head) if cr_mode else head.split("\n"))[:-1]
                [:DIALECT_LINES])
            fh.seek(0)
            log = _scan(_file_lines(fh, cr_mode), str(p), duplicates, gates, dialect)
        if cr_mode:
            log.conversions.append(_cr_conversion(bare_cr, lf))
    except OSError as exc:
        raise RigLogError(f"{p}: cannot read: {exc}") from exc
    if warn:
        for msg in log.warnings:
            warnings.warn(msg, RigLogWarning, stacklevel=2)
    return log


def read_rig_log(path: str | Path, run: int | None = None, *, duplicates: str = "drop",
                 warn: bool = True, **options: Any) -> Recording:
    """Read one run of a rig log as a :class:`Recording` in our conventions.

    Parameters
    ----------
    path : str or Path
        The ``.txt`` terminal log.
    run : int, optional
        Run index when the log holds several (default: the longest).
    duplicates : {"drop", "error"}
        Policy for repeated timestamps (see :func:`parse_rig_log_text`).
    warn : bool
        Emit warnings for recoverable problems.
    **options
        Passed to :func:`run_to_recording` (``rebase_turns``, ``stale_after``,
        ``phi_theta_lag``, ``camera_offset``, ``drop_backlog``).
    """
    return parse_rig_log(path, duplicates=duplicates, warn=warn).recording(run, **options)


def _camera_backlog_end(new_fix_idx: NDArray[np.intp], t: NDArray[np.float64]) -> int:
    """Sample index where a start-up replay of queued camera frames ends (0 if none).

    The burst is found on the fixes' own intervals and the log's line interval
    (:func:`bfr_model.io.timing.camera_backlog_end`; not in a log at the camera's rate or
    slower, where a replayed fix comes on every line as a live one does).
    """
    if not new_fix_idx.size:
        return 0
    steps = np.diff(t)
    end = camera_backlog_end(t[new_fix_idx],
                             line_period=float(np.median(steps)) if steps.size else None)
    return int(new_fix_idx[end]) if end > 0 else 0


@dataclass(frozen=True, kw_only=True)
class _RigColumns:
    """The columns of one raw run, copied, in the rig's conventions (see :data:`KEYS`)."""

    t: NDArray[np.float64]
    torque: NDArray[np.float64]
    theta: NDArray[np.float64]
    phi: NDArray[np.float64]
    dtheta: NDArray[np.float64]
    dphi: NDArray[np.float64]
    x: NDArray[np.float64]
    y: NDArray[np.float64]

    @classmethod
    def of(cls, run: RigRun) -> _RigColumns:
        """Copies of the columns of ``run``."""
        return cls(**{key: run.column(key).copy() for key in KEYS})


@dataclass(frozen=True, kw_only=True)
class _BallFixes:
    """The camera fixes held in a run's ``x, y`` columns and which samples are valid.

    Attributes
    ----------
    seen : ndarray of bool
        A ball position is held (``x, y`` not both 0).
    last_fix : ndarray of int
        Index of the latest new fix at or before each sample (-1: none yet).
    valid : ndarray of bool
        The held fix is usable: not older than ``stale_after``, not in the start-up
        backlog, not reported lost.
    backlog_end : int
        First sample after the start-up replay of queued camera frames (0: none).
    """

    seen: NDArray[np.bool_]
    last_fix: NDArray[np.intp]
    valid: NDArray[np.bool_]
    backlog_end: int


def _ball_lost(events: list[tuple[int, str]], fix_idx: NDArray[np.intp],
               n: int) -> NDArray[np.bool_]:
    """Samples from each ``ball was lost`` message up to (excluding) the next new fix."""
    lost = np.zeros(n, bool)
    for e, msg in events:
        if msg.startswith("ball was lost") and e < n:
            nxt = fix_idx[fix_idx >= e]
            end = int(nxt[0]) if nxt.size else n
            lost[e:end] = True
    return lost


def _ball_fixes(run: RigRun, raw: _RigColumns, *, stale_after: float, drop_backlog: bool,
                notes: list[str]) -> _BallFixes:
    """Find the new camera fixes of a run and the valid samples; explain them in ``notes``.

    A new fix is a held position that differs from the previous sample's (or follows a
    sample without a ball).
    """
    t, x, y = raw.t, raw.x, raw.y
    n = t.shape[0]
    idx = np.arange(n)
    seen = ~((x == 0.0) & (y == 0.0))
    changed = np.ones(n, bool)
    changed[1:] = (x[1:] != x[:-1]) | (y[1:] != y[:-1]) | ~seen[:-1]
    new_fix = seen & changed
    fix_idx = np.nonzero(new_fix)[0]
    backlog_end = _camera_backlog_end(fix_idx, t) if drop_backlog else 0
    last_fix = np.maximum.accumulate(np.where(new_fix, idx, -1))
    has_fix = last_fix >= 0
    age = np.where(has_fix, t - t[np.maximum(last_fix, 0)], np.inf)
    lost = _ball_lost(run.events, fix_idx, n)
    valid = seen & has_fix & (age <= stale_after) & (idx >= backlog_end) & ~lost
    if run.nan_ball:
        notes.append(f"{run.nan_ball} sample(s) log the ball centre as NaN: read as no ball "
                     "(x = y = 0), the line's encoder and torque used")
    if run.ball_off is not None and run.ball_off.any():
        valid &= ~run.ball_off
        notes.append(f"{int(run.ball_off.sum())} sample(s) hold a ball position off the frame: "
                     f"invalid (see meta['read_account'])")
    if backlog_end > 0:
        notes.append(f"camera backlog: fixes before t = {t[min(backlog_end, n - 1)]:.4f} s "
                     f"arrived at the loop rate (frames queued since program start) and are "
                     f"marked invalid")
    if lost.any():
        notes.append(f"'ball was lost' reported; {int(lost.sum())} held sample(s) invalid")
    stale = seen & has_fix & (age > stale_after)
    if stale.any():
        notes.append(f"{int(stale.sum())} sample(s) hold a fix older than {stale_after} s: "
                     f"invalid")
    return _BallFixes(seen=seen, last_fix=last_fix, valid=valid, backlog_end=backlog_end)


def _turn_shift(theta_raw: NDArray[np.float64], rebase_turns: bool,
                conversions: list[str]) -> float:
    """The whole turns ``2 pi k`` nearest to the first ``theta`` (0 unless ``rebase_turns``)."""
    if not rebase_turns:
        return 0.0
    shift = 2.0 * math.pi * round(theta_raw[0] / (2.0 * math.pi))
    if shift:
        conversions.append(f"theta and phi rebased by -2 pi * {round(shift / (2 * math.pi))}"
                           f" = {-shift!r} rad (whole turns; physically identical)")
    return shift


def _theta_resolution(theta_raw: NDArray[np.float64]) -> float:
    """Resolution of the logged ``theta`` [rad] (6 significant digits of its largest value)."""
    magnitude = float(np.max(np.abs(theta_raw)))
    return 10.0 ** (math.floor(math.log10(magnitude)) - 5) if magnitude > 0 else 1e-6


#: An encoder lattice is taken when this share of theta's changes lies within 5 % of a whole
#: number of steps, the step at least three print quanta (:func:`encoder_step`).
ENCODER_LATTICE_SHARE = 0.9


def encoder_step(theta_raw: NDArray[np.float64], printed: float) -> float:
    """The encoder's step [rad] when the logged angle sits on a lattice coarser than its print.

    The step q is the 2nd percentile of theta's changes above half a print quantum (the
    smallest step the encoder takes, one count); it is taken when at least
    :data:`ENCODER_LATTICE_SHARE` of the changes lie within 5 % of a whole number of q and
    q is at least three print quanta (a coarse encoder printed with many digits: 1024 counts
    a turn printed to 1e-7 rad); q is then refined as the changes' sum over their steps'
    count. Else 0: the print is the resolution (a fine encoder, or a
    smooth angle). Measured per recording, never assumed.
    """
    d = np.abs(np.diff(theta_raw[np.isfinite(theta_raw)]))
    d = d[d > 0.5 * printed]
    if d.size < 50:
        return 0.0
    q = float(np.percentile(d, 2))
    if q < 3.0 * printed:
        return 0.0
    k = np.round(d / q)
    on = np.abs(d - k * q) < 0.05 * q
    if float(np.mean(on)) < ENCODER_LATTICE_SHARE:
        return 0.0
    return float(np.sum(d[on]) / np.sum(k[on]))  # refined over every step taken


def phi_pairing_lag(raw_theta: NDArray[np.float64], raw_phi: NDArray[np.float64],
                    x: NDArray[np.float64], y: NDArray[np.float64],
                    dtheta: NDArray[np.float64], new_fix: NDArray[np.bool_],
                    resolution: float, max_lag: int = MAX_PHI_THETA_LAG) -> int | None:
    """The lag L [samples] with which the log's ``phi`` pairs ``theta[k - L] + atan2(x, y)``.

    Tested at the new fixes where the frame turns (``|dtheta| > 1 rad/s``, so that a wrong
    lag shows) and the log's phi agrees with the rule within 0.5 rad at some lag (its
    estimator initialised): the lag whose median absolute residual is smallest, when that
    is within twice theta's print resolution. None when the log's phi does not follow the
    rule (or the frame hardly turns, or too few fixes).
    """
    k = np.nonzero(new_fix & (np.abs(dtheta) > 1.0))[0]
    k = k[k >= max_lag]
    if k.size < 20:
        return None
    psi = np.arctan2(x[k], y[k])
    med = []
    for lag in range(max_lag + 1):
        r = raw_phi[k] - (raw_theta[k - lag] + psi)
        r = (r + np.pi) % (2 * np.pi) - np.pi
        r = r[np.abs(r) < 0.5]
        med.append(float(np.median(np.abs(r))) if r.size > 0.5 * k.size else math.inf)
    best = int(np.argmin(med))
    return best if med[best] <= 2.0 * resolution + 1e-12 else None


def _sensor_timing(raw: _RigColumns, fix_idx: NDArray[np.intp], backlog_end: int,
                   lag: Any) -> dict[str, Any]:
    """What the run's own data say about its timing (module docstring; no rig's constants).

    Line rate, camera fix rate and interval after any backlog, lines per fix, and the
    measured lag of ``dtheta`` (:class:`bfr_model.io.timing.VelocityLag`).
    """
    t = raw.t
    steady = fix_idx[fix_idx >= backlog_end]
    out: dict[str, Any] = {"line_rate_hz": line_rate(t),
                           "line_interval_median_s": float(np.median(np.diff(t)))
                           if t.size > 1 else float("nan"),
                           "fixes": int(fix_idx.size), "backlog_fixes":
                           int(np.count_nonzero(fix_idx < backlog_end)),
                           "velocity_lag": lag.to_json()}
    if steady.size > 2:
        d = np.diff(t[steady])
        out["camera_rate_hz"] = float((steady.size - 1) / (t[steady[-1]] - t[steady[0]]))
        out["fix_interval_median_s"] = float(np.median(d))
        out["lines_per_fix"] = float((steady[-1] - steady[0]) / (steady.size - 1))
    return out


def _rig_log_meta(run: RigRun, t: NDArray[np.float64], *, source: str,
                  conversions: list[str], notes: list[str], shift: float, theta_res: float,
                  backlog_end: int, phi_theta_lag: int, stale_after: float,
                  timing: dict[str, Any]) -> dict[str, Any]:
    """``Recording.meta`` of a converted run: provenance, conversions and rig conventions."""
    n = t.shape[0]
    return {
        "source": source,
        "source_kind": "ntnu_rig_log",
        "conversions": conversions,
        "notes": notes,
        "units": {"phi_rig": "rad", "dphi_rig": "rad/s", "ball_seen": "-"},
        "first_line": int(run.lines[0]),
        "time_origin_s": float(run.time_origin),
        "last_line": int(run.lines[-1]),
        "dropped_duplicates": run.dropped_duplicates,
        "events": [(float(t[min(e, n - 1)]), msg) for e, msg in run.events],
        "theta_turn_shift": shift,
        "theta_resolution": theta_res,
        "camera_backlog_end_t": float(t[min(backlog_end, n - 1)]) if backlog_end else None,
        "sensor_timing": timing,
        "rig_conventions": {
            "theta_sign": 1,
            "torque_sign": 1,
            "xy_frame": "world",
            "phi_theta_lag_samples": int(phi_theta_lag),
            "dtheta_delay_s": timing["velocity_lag"]["lag_s"],
            "dtheta_delay_measured": bool(timing["velocity_lag"]["identified"]),
            "stale_after_s": float(stale_after),
            "doc": "docs/ntnu-rig-conventions.md",
        },
    }


def run_to_recording(run: RigRun, *, source: str = "<rig log>", rebase_turns: bool = True,
                     stale_after: float = 0.1, phi_theta_lag: int | None = None,
                     camera_offset: tuple[float, float] = (0.0, 0.0),
                     drop_backlog: bool = True) -> Recording:
    """Convert one raw run to a :class:`Recording` in our conventions.

    Parameters
    ----------
    run : RigRun
        Raw run from :func:`parse_rig_log`.
    source : str
        Provenance for ``meta["source"]``.
    rebase_turns : bool
        Subtract the whole number of turns ``2 pi k`` nearest to the first ``theta`` from
        ``theta`` and ``phi`` (physically identical; smaller numbers).
    stale_after : float
        A held fix older than this [s] is invalid (normal gaps are <= 11 ms). Also after an
        ``[inf] ball was lost`` message until the next new fix.
    phi_theta_lag : int, optional
        Samples between a fix's arrival and the frame angle paired with it in ``phi``;
        default: measured on the run (:func:`phi_pairing_lag`; the NTNU rig's software uses
        8), 0 when the log's phi does not follow the rule.
    camera_offset : (float, float)
        Camera origin offset ``(cx, cy)`` [m] subtracted from ``x, y`` (default: none; the
        measured offsets are in docs/ntnu-rig-conventions.md).
    drop_backlog : bool
        Mark the start-up replay of queued camera frames invalid.
    """
    raw = _RigColumns.of(run)
    conversions: list[str] = []
    notes: list[str] = []
    if run.time_origin:
        conversions.append(f"t: the run's first stamp {run.time_origin!r} s subtracted (the "
                           f"stamps count from an epoch, beyond {EPOCH_STAMPS:g} s; in double "
                           "precision as read, before any fit; meta['time_origin_s'])")
    if run.nan_dtheta[0]:
        notes.append(f"{run.nan_dtheta[0]} sample(s) log dtheta (the servo's velocity) as "
                     "NaN: a missing velocity sample, the line's angle, torque and camera fix "
                     f"used; theta_dot there {run.nan_dtheta[1]}")
    if run.garbage:
        notes.append(f"{len(run.garbage)} unparseable line(s) among the run's data lines "
                     f"skipped (neither data nor a rig's message), first at line "
                     f"{run.garbage[0]}; not samples: the read is refused past 1 % of the "
                     "lines (see meta['read_account'])")
    fixes = _ball_fixes(run, raw, stale_after=stale_after, drop_backlog=drop_backlog,
                        notes=notes)

    cx, cy = float(camera_offset[0]), float(camera_offset[1])
    bx, by = raw.x - cx, raw.y - cy
    if cx or cy:
        conversions.append(f"subtracted camera offset (cx, cy) = ({cx}, {cy}) m from x, y")
    shift = _turn_shift(raw.theta, rebase_turns, conversions)
    theta = raw.theta - shift
    # the print's resolution, of the values as logged (before any turns were added)
    theta_res = _theta_resolution(raw.theta if run.turns is None else raw.theta - run.turns)
    step = encoder_step(raw.theta, theta_res)
    if step:
        conversions.append(f"theta sits on an encoder lattice of {step:.6g} rad (measured: its "
                           f"changes are whole steps), coarser than its print ({theta_res:g} "
                           "rad): that step is its resolution")
    new_fix = fixes.seen & (np.arange(raw.t.size) == fixes.last_fix)
    fix_idx = np.nonzero(new_fix)[0]
    if phi_theta_lag is None:
        found = phi_pairing_lag(raw.theta, raw.phi, raw.x, raw.y, raw.dtheta,
                                new_fix & (np.arange(raw.t.size) >= fixes.backlog_end),
                                theta_res)
        phi_theta_lag = 0 if found is None else found
        how = ("measured on this run" if found is not None else
               "the log's phi follows theta[k - L] + atan2(x, y) at no lag: L = 0")
    else:
        how = "given"
    lag_src = np.maximum(np.arange(raw.t.shape[0]) - int(phi_theta_lag), 0)
    phi_fix = theta[lag_src] + np.arctan2(bx, by)
    phi = np.where(fixes.valid, phi_fix[np.maximum(fixes.last_fix, 0)], np.nan)
    conversions.append(f"phi recomputed as theta[k - {phi_theta_lag}] + atan2(x, y) at each "
                       f"new fix k and held (the rig's own pairing, L {how}); rig phi kept "
                       "in extra['phi_rig']")
    vlag = velocity_lag(raw.t, raw.theta, raw.dtheta)
    notes.append(f"dtheta: {vlag.note} (measured on this run; not applied by the reader)")
    timing = _sensor_timing(raw, fix_idx, fixes.backlog_end, vlag)
    phi_rig_ours = np.where(fixes.seen, raw.phi - shift, np.nan)
    off = phi_rig_ours - phi
    if run.turns is not None:  # the rig's phi wraps on its own, at other samples than theta
        off = np.remainder(off + math.pi, 2.0 * math.pi) - math.pi
    initialised = np.abs(off) < 0.5
    phi_dot = np.where(fixes.valid & initialised, raw.dphi, np.nan)
    conversions.append("phi_dot = rig dphi where the ball is valid and the rig's phi "
                       "estimator is initialised, else NaN")
    conversions.append("theta, theta_dot (rig dtheta), torque, x, y: rig sign and units "
                       "already match ours (no change)")

    rec = Recording(
        t=raw.t, theta=theta, theta_dot=raw.dtheta, torque=raw.torque, ball_x=bx, ball_y=by,
        ball_valid=fixes.valid, phi=phi, phi_dot=phi_dot,
        extra={"phi_rig": phi_rig_ours, "dphi_rig": raw.dphi,
               "ball_seen": fixes.seen.astype(float)},
        meta=_rig_log_meta(run, raw.t, source=source, conversions=conversions, notes=notes,
                           shift=shift, theta_res=max(theta_res, step),
                           backlog_end=fixes.backlog_end, phi_theta_lag=phi_theta_lag,
                           stale_after=stale_after, timing=timing),
    )
    rec.meta["sample_rate"] = rec.sample_rate()
    rec.meta["camera_fix_rate"] = rec.camera_fix_rate()
    if run.account is not None:
        rec.meta["read_account"] = run.account.to_json()
    return rec


def _g(value: float, digits: int) -> str:
    """``value`` printed as a C++ output stream prints a double (``digits`` significant)."""
    return format(float(value), f".{digits}g")


def format_rig_log(runs: Recording | list[Recording], *, digits: int = 6) -> str:
    r"""Recordings as the text of a rig's terminal log (module docstring).

    Each recording becomes one run: ``[inf] initializing hardware..``, ``[inf] done``, one
    data line per sample, ``[inf] stopped``. ``x, y`` are the held fix (``0, 0`` where no
    valid fix), ``phi`` the recording's ``phi`` (0 without a fix), ``dtheta`` its
    ``theta_dot``, ``dphi`` its ``phi_dot`` (0 where absent). Numbers have ``digits``
    significant digits, as a C++ stream prints them (the NTNU rig: 6), so what a reader gets
    back is quantised like a real log: theta to 1 mrad above 100 rad.

    Parameters
    ----------
    runs : Recording or list of Recording
        The runs, in order (their clocks may restart).
    digits : int
        Significant digits of every number.

    Returns
    -------
    str
        The log's text (lines end in ``\n``).
    """
    recs = [runs] if isinstance(runs, Recording) else list(runs)
    out = ["Script started by bfr_model.io.rig_log.format_rig_log"]
    for rec in recs:
        out += ["[inf] initializing hardware..", "[inf] done"]
        v = rec.ball_valid
        x = np.where(v, rec.ball_x, 0.0)
        y = np.where(v, rec.ball_y, 0.0)
        phi = np.where(v & np.isfinite(rec.phi), rec.phi, 0.0)
        dphi = (np.zeros(rec.n) if rec.phi_dot is None
                else np.where(np.isfinite(rec.phi_dot), rec.phi_dot, 0.0))
        cols = (rec.t, rec.torque, rec.theta, phi, rec.theta_dot, dphi, x, y)
        for row in zip(*(c.tolist() for c in cols), strict=True):
            out.append("[inf] " + ",".join(f"{k}={_g(val, digits)}"
                                           for k, val in zip(KEYS, row, strict=True)))
        out.append("[inf] stopped")
    return "\n".join(out) + "\n"


def write_rig_log(path: str | Path, runs: Recording | list[Recording], *,
                  digits: int = 6) -> Path:
    """Write :func:`format_rig_log` of ``runs`` to ``path`` (a new file); returns the path."""
    p = Path(path)
    p.write_text(format_rig_log(runs, digits=digits))
    return p


def _main(argv: list[str] | None = None) -> int:
    """``python -m bfr_model.io.rig_log FILE...``: print a parse summary per file."""
    ap = argparse.ArgumentParser(prog="python -m bfr_model.io.rig_log",
                                 description="Parse NTNU rig logs and print a JSON summary.")
    ap.add_argument("files", nargs="+", type=Path)
    args = ap.parse_args(argv)
    for f in args.files:
        t0 = time.perf_counter()
        try:
            log = parse_rig_log(f, warn=False)
        except RigLogError as exc:
            print(json.dumps({"file": str(f), "error": str(exc)}))
            continue
        dt = time.perf_counter() - t0
        rec = log.recording()
        out = {"file": f.name, "parse_s": round(dt, 3), "lines": log.n_lines,
               "data_lines": log.n_data, "skipped": log.skipped, "runs": len(log.runs),
               "warnings": log.warnings, **rec.summary()}
        print(json.dumps(out))
    return 0


if __name__ == "__main__":
    raise SystemExit(_main())
