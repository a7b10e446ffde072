"""``bfr bench`` section ``read``: peak memory and speed of the streaming rig-log reader.

A large rig log is made by concatenating the runs of the real NTNU logs
(``$BFR_RIG_DATA``, default ``../shared/data/ntnu-rig`` beside the checkout) until it
reaches ``read_mb`` megabytes (200 MB; 20 MB with ``--quick``), each file's text after an
``[inf] initializing hardware..`` marker so that every copy is a run of its own (its
truncated last line becomes a partial line mid-file: one ``corrupt`` line per copy, in the
account). ``bfr read BIG.txt --allow-partial`` reads it as ``bfr diagnose`` does (every run
parsed, gated and converted to a recording) in a subprocess; its peak resident memory is the
child's ``ru_maxrss`` (:func:`bfr_tools.bench.diagnosis.run_measured`). The same command on
one real log (2 MB) gives the fixed amount (interpreter, numpy, the readers' imports).

- ``read.log_peak_mib``: peak RSS reading the large log [MiB]; budget: 600 MiB for 200 MB
  (issue 15).
- ``read.log_peak_per_input``: (peak - fixed) / input size [-]; budget: < 2 (issue 15:
  under twice the input plus a fixed amount).
- ``read.log_mb_per_s``: input megabytes read per second of wall time.
"""

from __future__ import annotations

import os
import sys
import tempfile
from pathlib import Path

from bfr_tools.bench import common
from bfr_tools.bench.common import BenchOptions, Budget, Figure, FigureSpec, Progress, not_measured
from bfr_tools.bench.diagnosis import run_measured

__all__ = ["SPECS", "make_big_log", "run"]

SPECS: list[FigureSpec] = [
    FigureSpec("read.log_peak_mib", "bfr read, 200 MB rig log: peak memory (RSS)", "MiB",
               Budget("<", 600.0, "issue 15")),
    FigureSpec("read.log_peak_per_input", "bfr read: (peak - fixed) / input size", "",
               Budget("<", 2.0, "issue 15")),
    FigureSpec("read.log_fixed_mib", "bfr read, one 2 MB log: peak memory (the fixed part)",
               "MiB"),
    FigureSpec("read.log_mb_per_s", "bfr read, 200 MB rig log: input MB per second", ""),
]


def make_big_log(path: Path, target_bytes: int, data: Path) -> int:
    """Concatenate the real logs' text (each after a restart marker) up to ``target_bytes``.

    Returns the size written [B].
    """
    texts = [f.read_bytes() for f in sorted(data.glob("*.txt"))]
    if not texts:
        raise FileNotFoundError(f"no rig logs in {data}")
    size = 0
    with path.open("wb") as fh:
        while size < target_bytes:
            for t in texts:
                chunk = b"\n[inf] initializing hardware..\n" + t
                fh.write(chunk)
                size += len(chunk)
                if size >= target_bytes:
                    break
    return size


def run(opts: BenchOptions, say: Progress) -> list[Figure]:
    """Measure the ``read`` section (module docstring)."""
    data = common.rig_data_dir()
    if not data.is_dir():
        return [not_measured(s, f"no NTNU rig logs at {data} (set BFR_RIG_DATA)")
                for s in SPECS]
    mb = 20 if opts.quick else 200
    vals: dict[str, list[float]] = {s.key: [] for s in SPECS}
    cmd = [sys.executable, "-m", "bfr_tools.cli", "read", "--allow-partial"]
    env = dict(os.environ)
    with tempfile.TemporaryDirectory(prefix="bfr-bench-read-") as d:
        big = Path(d) / "big.txt"
        say(f"read: writing a {mb} MB rig log from the real logs' runs")
        size = make_big_log(big, mb * 1_000_000, data)
        small = sorted(data.glob("*.txt"))[0]
        for rep in range(opts.repeats):
            say(f"read: bfr read on {small.name} and on the {size / 1e6:.0f} MB log, repeat "
                f"{rep + 1}/{opts.repeats}")
            _, fixed, code0 = run_measured([*cmd, str(small)], env, Path(d) / "o0",
                                           Path(d) / "e0", 300.0)
            wall, peak, code = run_measured([*cmd, str(big)], env, Path(d) / "o1",
                                            Path(d) / "e1", 1800.0)
            if code != 0 or code0 != 0:
                err = (Path(d) / "e1").read_text()[-400:]
                return [not_measured(s, f"bfr read exited {code}: {err}") for s in SPECS]
            vals["read.log_peak_mib"].append(peak)
            vals["read.log_fixed_mib"].append(fixed)
            vals["read.log_peak_per_input"].append(
                (peak - fixed) * 2**20 / (size - small.stat().st_size))
            vals["read.log_mb_per_s"].append(size / 1e6 / wall)
        account = (Path(d) / "e1").read_text().strip().splitlines()[-1][:300]
    note = (f"{size / 1e6:.0f} MB log of the real logs' runs; {opts.repeats} repeat(s); "
            f"wall times noisy on a shared machine; account: {account}")
    return [Figure(s, vals[s.key], note=note) for s in SPECS]
