"""``bfr limits`` with the node suite as one more truth (``run --truth nodes``).

:mod:`bfr_diagnose.limits` runs the offline truths (rigid and contact models). Here a case's
truth is the emulated rig itself: ``bfr rig --lockstep --record DIR`` runs the simulator,
camera, controller and recorder nodes as processes over DDS (their own ROS domain), the
simulator with the case's concealed effects as node parameters, the controller with its
orbit speed and Riccati weights, and records a ROS 2 bag; the bag is read back with
:func:`bfr_model.io.read_recording`, as a user's bag is. The node suite's camera (rendered
images, the ball detector) and its timing are its own: the case's drawn sensor conventions
do not apply (``sensors_applied`` false in the table). Effects are the scalar ones
(:data:`bfr_diagnose.limits.cases.SCALAR_EFFECTS`). A case costs about 10x an offline one
(90 s wall for 10 s here, with other work on the machine).

Example::

    scripts/bfr limits run --truth nodes --seed 5 --cases 20 --out runs/limits-nodes
"""

from __future__ import annotations

import json
import subprocess
import sys
import tempfile
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from bfr_diagnose.limits import cli as limits_cli
from bfr_diagnose.limits.cases import LimitCase
from bfr_diagnose.limits.generate import controller_config
from bfr_model.io import read_recording
from bfr_model.params import RigParams
from bfr_model.recording import Recording

__all__ = ["main", "record_with_nodes"]


def _value(v: Any) -> str:
    """A node parameter's value on the command line (``name:=value``)."""
    if isinstance(v, (tuple, list)):
        return "[" + ",".join(repr(float(x)) for x in v) + "]"
    return repr(float(v))


def record_with_nodes(case: LimitCase, base: RigParams, duration: float
                      ) -> tuple[list[Recording], dict[str, Any]]:
    """The case recorded from the node suite (module docstring)."""
    del base  # the nodes read rig.yaml themselves
    ctrl = controller_config(case)
    params = [f"simulator:{k}:={_value(v)}" for k, v in case.changes.items()]
    params += [f"controller:orbit.mean_phi_dot:={ctrl.orbit.mean_phi_dot!r}",
               f"controller:riccati.q_y:={ctrl.riccati.q_y!r}",
               f"controller:riccati.q_y_dot:={ctrl.riccati.q_y_dot!r}"]
    with tempfile.TemporaryDirectory(prefix="bfr_limits_nodes_") as tmp:
        bag = Path(tmp) / "bag"
        cmd = [sys.executable, "-m", "bfr_tools.rig", "--lockstep", "--duration",
               str(duration), "--record", str(bag), "--domain", "auto", "--log-dir",
               str(Path(tmp) / "log"), "--json", *(a for p in params for a in ("-p", p))]
        res = subprocess.run(cmd, capture_output=True, text=True, check=False,
                             stdin=subprocess.DEVNULL)
        if res.returncode != 0:
            last = (res.stderr.strip().splitlines() or ["no message"])[-1]
            raise RuntimeError(f"bfr rig exited {res.returncode}: {last}")
        summary = json.loads(res.stdout.strip().splitlines()[-1])
        rec = read_recording(bag)
    loop = {"ball_rolling": bool(summary.get("kept_rolling")),
            "mean_phi_dot": summary.get("mean_phi_dot", float("nan")),
            "rms_torque": float("nan")}
    return [rec], loop


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``bfr limits`` (:mod:`bfr_diagnose.limits.cli`, plus ``--truth nodes``)."""
    return limits_cli.main(list(argv) if argv is not None else None,
                           recorders={"nodes": record_with_nodes})


if __name__ == "__main__":  # pragma: no cover
    raise SystemExit(main())
