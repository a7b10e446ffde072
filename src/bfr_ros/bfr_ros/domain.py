"""A ROS domain id of this process's own, so that runs on one machine never see each other.

DDS participants in one ``ROS_DOMAIN_ID`` discover each other; two rigs, a rig and a test run,
or two test processes on one machine must not share one. Every bfr process that starts nodes
(``bfr rig``, ``bfr bench``, the test suite) claims an id here: an exclusive ``flock`` on
``<tmp>/bfr-ros-domain-<id>.lock``, held for the rest of the process's life, so a claim ends
with the process however it ends.
"""

from __future__ import annotations

import atexit
import fcntl
import os
import tempfile
from pathlib import Path
from typing import IO

__all__ = ["DOMAIN_IDS", "claim_domain_id"]

#: Domain ids usable with Fast DDS' default ports on Linux: 0..101 (0 is everyone's default).
DOMAIN_IDS = range(1, 102)

_claim: tuple[int, IO[str]] | None = None


def claim_domain_id() -> int:
    """Claim a ROS domain id that no other process on this machine has claimed.

    The search starts at a pid-dependent id. The same id is returned on every call in one
    process.

    Returns
    -------
    int
        The domain id.

    Raises
    ------
    RuntimeError
        If every id in 1..101 is taken.
    """
    global _claim  # noqa: PLW0603 - one claim per process
    if _claim is not None:
        return _claim[0]
    n = len(DOMAIN_IDS)
    start = os.getpid() % n
    for k in range(n):
        domain = DOMAIN_IDS[(start + k) % n]
        handle = (Path(tempfile.gettempdir()) / f"bfr-ros-domain-{domain}.lock").open("a")
        try:
            fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            handle.close()
            continue
        _claim = (domain, handle)
        atexit.register(handle.close)
        return domain
    raise RuntimeError("no free ROS_DOMAIN_ID in 1..101 on this machine")
