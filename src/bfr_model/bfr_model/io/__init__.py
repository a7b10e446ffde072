"""Readers and writers of recordings (pure Python + numpy, no ``rclpy``).

- :mod:`bfr_model.io.rig_log`: the NTNU rig's terminal logs (``[inf] t=...`` lines).
- :mod:`bfr_model.io.csv_io`: the simulator's CSV format.
- :mod:`bfr_model.io.bag`: ROS 2 bags (rosbag2 directory, MCAP storage; sqlite3 read).
- :mod:`bfr_model.io.rig_conventions`: the analysis that inferred the rig logs' conventions.

:func:`read_recording` picks the reader from the path.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from bfr_model.io.bag import read_bag
from bfr_model.io.csv_io import read_csv
from bfr_model.io.rig_log import read_rig_log
from bfr_model.recording import Recording, RecordingError

__all__ = ["read_recording"]


def read_recording(path: str | Path, **options: Any) -> Recording:
    """Read a recording, choosing the reader from the path.

    ``*.txt``: NTNU rig log; ``*.csv``: simulator CSV; a directory, ``*.mcap`` or
    ``*.db3``: ROS 2 bag.

    Parameters
    ----------
    path : str or Path
        The file or bag directory.
    **options
        Passed to the reader.

    Raises
    ------
    RecordingError
        If the kind of file is not recognised (the readers raise their own errors, all
        subclasses of ValueError).
    """
    p = Path(path)
    suffix = p.suffix.lower()
    if suffix == ".txt":
        return read_rig_log(p, **options)
    if suffix == ".csv":
        return read_csv(p, **options)
    if p.is_dir() or suffix in (".mcap", ".db3"):
        return read_bag(p, **options)
    raise RecordingError(f"{p}: unknown recording kind (expected .txt rig log, .csv, or a "
                         f"ROS 2 bag directory / .mcap / .db3)")
