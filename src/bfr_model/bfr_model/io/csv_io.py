"""The simulator's CSV format, to and from :class:`~bfr_model.recording.Recording`.

Format
------
- Optional comment lines starting with ``#`` (anywhere; blank lines are ignored too). Lines
  of the form ``# key: value`` before the header are metadata; ``value`` is JSON when it
  parses as JSON, else a string.
- One header row naming the columns, comma separated. Required columns (any order):
  ``t, theta, theta_dot, phi, phi_dot, ball_x, ball_y, torque`` [s, rad, rad/s, rad, rad/s,
  m, m, N m]; optional ``kinetic, potential, energy`` [J]; any further columns are kept in
  ``Recording.extra`` (or fill the optional recording fields of the same name).
- One row per sample, numbers in Python/C float syntax; ``nan`` marks a missing value.

``phi`` and ``phi_dot`` are the simulator's **state** (the contact-point angle; ``bfr
simulate`` writes this) unless the metadata says ``# phi_kind: "ball_centre"``. Reading a
contact-angle file puts them into ``phi_true`` / ``phi_dot_true`` and computes the
recording's ``phi`` (ball-centre angle) from ``theta, ball_x, ball_y``, unless a
``phi_ball`` column holds it. A ``ball_valid`` column (0/1) is optional; without it a sample
is valid where ``ball_x`` and ``ball_y`` are finite.

Every data row is accounted for (``meta["read_account"]``, :mod:`bfr_model.io.account`):
rows cut short, with another number of fields or a cell that is not a number, and rows the
physical gates stop are left out and counted by cause with their line.
"""

from __future__ import annotations

import json
import math
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from bfr_model.io.account import Gates, ReadAccount, gate_samples
from bfr_model.recording import OPTIONAL_FIELDS, Recording, RecordingError, ball_centre_angle

__all__ = ["CSV_COLUMNS", "CsvFormatError", "read_csv", "write_csv"]

#: Documented column order of the simulator's CSV.
CSV_COLUMNS = ("t", "theta", "theta_dot", "phi", "phi_dot", "ball_x", "ball_y", "torque",
               "kinetic", "potential", "energy")
REQUIRED_COLUMNS = CSV_COLUMNS[:8]


class CsvFormatError(RecordingError):
    """A CSV recording is malformed; the message names the file, line and column."""


def _meta_value(text: str) -> Any:
    try:
        return json.loads(text)
    except (json.JSONDecodeError, ValueError):
        return text


def _jsonable(value: Any) -> Any:
    if isinstance(value, float) and not math.isfinite(value):
        return str(value)
    if isinstance(value, dict):
        return {str(k): _jsonable(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_jsonable(v) for v in value]
    if isinstance(value, (np.floating, np.integer, np.bool_)):
        return _jsonable(value.item())
    return value


def write_csv(path: str | Path, rec: Recording, *, meta: bool = True,
              precision: int = 17) -> None:
    """Write a recording in the simulator's CSV format.

    With ground truth (``rec.has_truth``) the ``phi``/``phi_dot`` columns hold the
    contact-point state (``phi_true``/``phi_dot_true``) and the ball-centre ``phi`` goes to
    a ``phi_ball`` column; otherwise they hold ``phi``/``phi_dot`` and the metadata says
    ``phi_kind: "ball_centre"``. Other optional arrays and ``extra`` become extra columns;
    ``ball_valid`` is written as 0/1.

    Parameters
    ----------
    path : str or Path
        Output file.
    rec : Recording
        The recording.
    meta : bool
        Write ``rec.meta`` as ``# key: json`` comment lines.
    precision : int
        Significant digits (17 round-trips float64 exactly).
    """
    n = len(rec)
    nan = np.full(n, np.nan)
    cols: dict[str, np.ndarray] = {"t": rec.t, "theta": rec.theta, "theta_dot": rec.theta_dot}
    truth = rec.has_truth
    if truth:
        cols["phi"] = rec.phi_true  # type: ignore[assignment]
        cols["phi_dot"] = rec.phi_dot_true if rec.phi_dot_true is not None else nan
    else:
        cols["phi"] = rec.phi
        cols["phi_dot"] = rec.phi_dot if rec.phi_dot is not None else nan
    cols.update(ball_x=rec.ball_x, ball_y=rec.ball_y, torque=rec.torque)
    for name in ("kinetic", "potential", "energy"):
        value = getattr(rec, name)
        cols[name] = value if value is not None else nan
    cols["ball_valid"] = rec.ball_valid.astype(float)
    if truth:
        cols["phi_ball"] = rec.phi
        if rec.phi_dot is not None:
            cols["phi_dot_ball"] = rec.phi_dot
    for name in OPTIONAL_FIELDS:
        value = getattr(rec, name)
        if value is not None and name not in cols and name not in (
                "phi_dot", "phi_true", "phi_dot_true"):
            cols[name] = value
    for name, value in rec.extra.items():
        key = name if name not in cols else f"extra_{name}"
        cols[key] = value
    header_meta = dict(rec.meta)
    header_meta["phi_kind"] = "contact" if truth else "ball_centre"
    fmt = f"%.{precision}g"
    data = np.column_stack(list(cols.values()))
    p = Path(path)
    with p.open("w", encoding="utf-8", newline="\n") as fh:
        if meta:
            for key, value in header_meta.items():
                fh.write(f"# {key}: {json.dumps(_jsonable(value), default=str)}\n")
        fh.write(",".join(cols) + "\n")
        np.savetxt(fh, data, delimiter=",", fmt=fmt)


@dataclass(frozen=True, kw_only=True)
class _CsvTable:
    """The text cells of a CSV recording, with the metadata read before its header.

    Attributes
    ----------
    meta : dict
        ``# key: value`` lines before the header (values parsed as JSON when they are).
    header : list of str
        Column names.
    header_line : int
        1-based line number of the header.
    rows : list of list of str
        Cells of each data row, as many as header columns.
    row_lines : list of int
        1-based line number of each row.
    lost : dict of str to list of int
        Line numbers of data rows that could not be used, per account cause (``truncated``:
        the last line cut short; ``corrupt``: another number of fields or a cell that is not
        a number).
    """

    meta: dict[str, Any]
    header: list[str]
    header_line: int
    rows: list[list[str]]
    row_lines: list[int]
    lost: dict[str, list[int]]


def _read_text(p: Path) -> str:
    """The file's text (undecodable bytes replaced); a read failure as :class:`CsvFormatError`."""
    try:
        return p.read_text(encoding="utf-8", errors="replace")
    except OSError as exc:
        raise CsvFormatError(f"{p}: cannot read: {exc}") from exc


def _split_table(p: Path, text: str) -> _CsvTable:
    """Split the text into metadata, header and rows; blank and comment lines are skipped.

    A row with another number of fields than the header is not used: ``truncated`` when it
    is the last line and shorter, else ``corrupt`` (counted in :attr:`_CsvTable.lost`).

    Raises
    ------
    CsvFormatError
        No header.
    """
    meta: dict[str, Any] = {}
    header: list[str] | None = None
    header_line = 0
    rows: list[list[str]] = []
    row_lines: list[int] = []
    lost: dict[str, list[int]] = {}
    lines = text.split("\n")
    if lines and lines[-1] == "":
        lines.pop()
    last = max((i for i, ln in enumerate(lines) if ln.strip()), default=-1)
    for i, raw in enumerate(lines):
        line = raw.strip()
        if not line:
            continue
        if line.startswith("#") and not (header is not None
                                         and line.count(",") == len(header) - 1):
            if header is None and ":" in line:
                key, _, value = line[1:].partition(":")
                meta[key.strip()] = _meta_value(value.strip())
            continue
        if header is None:
            header = [c.strip() for c in line.split(",")]
            header_line = i + 1
            continue
        cells = line.split(",")
        if len(cells) != len(header):
            cause = "truncated" if i == last and len(cells) < len(header) else "corrupt"
            lost.setdefault(cause, []).append(i + 1)
            continue
        rows.append(cells)
        row_lines.append(i + 1)
    if header is None:
        raise CsvFormatError(f"{p}: no header row (file is empty or only comments)")
    return _CsvTable(meta=meta, header=header, header_line=header_line, rows=rows,
                     row_lines=row_lines, lost=lost)


def _check_columns(p: Path, table: _CsvTable) -> None:
    """Check for unique column names, the required columns and at least one row.

    Raises
    ------
    CsvFormatError
        Duplicate or missing columns, or no data rows.
    """
    header, header_line = table.header, table.header_line
    dup = sorted({c for c in header if header.count(c) > 1})
    if dup:
        raise CsvFormatError(f"{p}:{header_line}: duplicate column(s) {dup}")
    missing = [c for c in REQUIRED_COLUMNS if c not in header]
    if missing:
        raise CsvFormatError(f"{p}:{header_line}: missing required column(s) {missing}; "
                             f"found {header}")
    if not table.rows:
        raise CsvFormatError(f"{p}: no data rows after the header (line {header_line})")


def _columns(p: Path, table: _CsvTable) -> dict[str, np.ndarray]:
    """The rows as float columns by name.

    A row with a cell that is not a number is left out and counted ``corrupt`` in
    ``table.lost`` (with its line).

    Raises
    ------
    CsvFormatError
        No row holds numbers only.
    """
    try:
        data = np.array(table.rows, dtype=np.float64)
    except ValueError:
        good = []
        for k, cells in enumerate(table.rows):
            try:
                good.append([float(c) for c in cells])
            except ValueError:
                table.lost.setdefault("corrupt", []).append(table.row_lines[k])
                table.row_lines[k] = -1
        kept = [ln for ln in table.row_lines if ln >= 0]
        table.row_lines[:] = kept
        table.lost["corrupt"].sort()
        if not good:
            raise CsvFormatError(f"{p}: no data row holds numbers only (first bad line "
                                 f"{table.lost['corrupt'][0]})") from None
        data = np.array(good, dtype=np.float64)
    return {name: data[:, j] for j, name in enumerate(table.header)}


def _phi_fields(col: dict[str, np.ndarray], valid: np.ndarray, kind: str) -> dict[str, Any]:
    """The recording's angle fields from the ``phi, phi_dot`` columns of kind ``kind``.

    ``"contact"``: the columns are the simulator's state, read into ``phi_true,
    phi_dot_true`` with ``theta, theta_dot, ball_x, ball_y`` as ground truth; ``phi`` is the
    ``phi_ball`` column or the ball-centre angle where valid, ``phi_dot`` the
    ``phi_dot_ball`` column if any. ``"ball_centre"``: they are ``phi`` and ``phi_dot``
    (None when all NaN).
    """
    if kind != "contact":
        return {"phi": col["phi"],
                "phi_dot": None if np.all(np.isnan(col["phi_dot"])) else col["phi_dot"]}
    out: dict[str, Any] = {"phi_true": col["phi"], "phi_dot_true": col["phi_dot"]}
    if "phi_ball" in col:
        out["phi"] = col["phi_ball"]
    else:
        out["phi"] = np.where(valid, ball_centre_angle(col["theta"], col["ball_x"],
                                                       col["ball_y"], near=col["phi"]),
                              np.nan)
    if "phi_dot_ball" in col:
        out["phi_dot"] = col["phi_dot_ball"]
    for name in ("theta", "theta_dot", "ball_x", "ball_y"):
        out[f"{name}_true"] = col[name].copy()
    return out


def _recording_fields(col: dict[str, np.ndarray], header: list[str],
                      kind: str) -> tuple[dict[str, Any], dict[str, np.ndarray]]:
    """Keyword arguments of :class:`Recording` from the columns, and the ``extra`` arrays.

    Columns not read as a state, ball or energy field fill the optional recording field of
    their name, else go to ``extra`` (an ``extra_`` prefix removed).
    """
    if "ball_valid" in col:
        valid = col["ball_valid"] != 0
    else:
        valid = np.isfinite(col["ball_x"]) & np.isfinite(col["ball_y"])
    kwargs: dict[str, Any] = {name: col[name] for name in
                              ("t", "theta", "theta_dot", "torque", "ball_x", "ball_y")}
    kwargs["ball_valid"] = valid
    kwargs.update(_phi_fields(col, valid, kind))
    used = {*REQUIRED_COLUMNS, "ball_valid", "kinetic", "potential", "energy"}
    if kind == "contact":
        used |= {"phi_ball", "phi_dot_ball"} & col.keys()
    for name in ("kinetic", "potential", "energy"):
        if name in col and not np.all(np.isnan(col[name])):
            kwargs[name] = col[name]
    extra: dict[str, np.ndarray] = {}
    for name in header:
        if name in used:
            continue
        if name in OPTIONAL_FIELDS:
            kwargs[name] = col[name]
        else:
            short = name[len("extra_"):] if name.startswith("extra_") else name
            # write_csv prefixes an extra whose name is a column's; undo only that
            extra[short if short not in col and short not in extra else name] = col[name]
    return kwargs, extra


def _csv_meta(meta: dict[str, Any], p: Path, kind: str,
              col: dict[str, np.ndarray]) -> dict[str, Any]:
    """``Recording.meta``: the file's metadata with provenance and the conversion made."""
    meta_out = dict(meta)
    meta_out.pop("phi_kind", None)
    conv = meta_out.get("conversions", [])
    conversions = [conv] if isinstance(conv, str) else list(conv) if isinstance(
        conv, list) else [str(conv)]
    meta_out["conversions"] = conversions
    meta_out["source"] = str(p)
    meta_out.setdefault("source_kind", "csv")
    meta_out["csv_phi_kind"] = kind
    if kind == "contact" and "phi_ball" not in col:
        conversions.append("csv: phi/phi_dot columns (contact-point state) read into "
                           "phi_true/phi_dot_true; phi = theta + atan2(ball_x, ball_y)")
    return meta_out


def _gated(p: Path, table: _CsvTable, col: dict[str, np.ndarray],
           gates: Gates | None) -> tuple[dict[str, np.ndarray], ReadAccount]:
    """The columns of the samples the physical gates keep, and the read's account."""
    g = gate_samples(col["t"], col["theta"], col["theta_dot"], col["torque"], col["ball_x"],
                     col["ball_y"], rates=(col["phi_dot"],), gates=gates)
    lines = table.row_lines
    account = g.account(source=str(p), kind="csv", t=col["t"], lines=lines, lost=table.lost,
                        unit="row")
    if not g.keep.any():
        raise CsvFormatError(f"{p}: no row passed the checks: {account.line()}")
    out = {k: v[g.keep] for k, v in {**col, "theta": g.theta}.items()}
    if g.ball_off.any():
        off = g.ball_off[g.keep]
        if "ball_valid" in out:
            out["ball_valid"] = np.where(off, 0.0, out["ball_valid"])
        out["ball_x"] = np.where(off, np.nan, out["ball_x"])
        out["ball_y"] = np.where(off, np.nan, out["ball_y"])
    table.row_lines[:] = [ln for ln, k in zip(lines, g.keep, strict=True) if k]
    return out, account


def read_csv(path: str | Path, *, phi_kind: str | None = None,
             gates: Gates | None = None) -> Recording:
    """Read a CSV recording (see the module doc for the format).

    Every data row is accounted for (``meta["read_account"]``, a
    :class:`~bfr_model.io.account.ReadAccount`): rows cut short, with another number of
    fields, a cell that is not a number, or stopped by the physical gates
    (:func:`bfr_model.io.account.gate_samples`: non-finite, repeated or out-of-order
    stamps, values no hardware makes) are left out and counted by cause.

    Parameters
    ----------
    path : str or Path
        The CSV file.
    phi_kind : {"contact", "ball_centre"}, optional
        Override the meaning of the ``phi`` column (default: the ``phi_kind`` metadata,
        else ``"contact"`` as ``bfr simulate`` writes).
    gates : Gates, optional
        Bounds of the physical gates (default: from rig.yaml).

    Raises
    ------
    CsvFormatError
        Missing file, no header, missing required columns, no usable row, or invalid
        recording data (the message names the line and column).
    """
    p = Path(path)
    table = _split_table(p, _read_text(p))
    _check_columns(p, table)
    kind = phi_kind or table.meta.get("phi_kind", "contact")
    if kind not in ("contact", "ball_centre"):
        raise CsvFormatError(f"{p}: phi_kind must be 'contact' or 'ball_centre', got {kind!r}")
    col, account = _gated(p, table, _columns(p, table), gates)
    kwargs, extra = _recording_fields(col, table.header, kind)
    meta = _csv_meta(table.meta, p, kind, col)
    try:
        rec = Recording(extra=extra, meta=meta, **kwargs)
    except RecordingError as exc:
        msg = str(exc)
        # Name the file line for sample-indexed errors.
        m = re.search(r"sample (\d+)", msg)
        where = f"{p}:{table.row_lines[int(m.group(1))]}" if m and int(m.group(1)) < len(
            table.row_lines) else str(p)
        raise CsvFormatError(f"{where}: {msg}") from exc
    rec.meta.setdefault("sample_rate", rec.sample_rate())
    rec.meta["read_account"] = account.to_json()
    return rec
