"""Shared pieces of ``bfr bench``: figures, budgets, options, progress lines.

A :class:`Figure` is one measured quantity: the values of its repeats (the table shows their
median with min and max, so the machine's noise is visible), its unit, its budget (if the
issue sets one) and whether the median meets it. A figure that could not be measured
carries the reason instead of a number (``status = "not measured: ..."``), never a made-up
value.
"""

from __future__ import annotations

import math
import os
import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from bfr_model.io.rig_conventions import default_data_dir

__all__ = [
    "BenchOptions",
    "Budget",
    "Figure",
    "FigureSpec",
    "Progress",
    "Section",
    "fmt_value",
    "rig_data_dir",
    "timed",
]

#: Comparison operators a budget may use.
_OPS: dict[str, Callable[[float, float], bool]] = {
    ">=": lambda v, t: v >= t,
    ">": lambda v, t: v > t,
    "<=": lambda v, t: v <= t,
    "<": lambda v, t: v < t,
    "==": lambda v, t: v == t,
}


@dataclass(frozen=True)
class Budget:
    """A budget: ``median <op> value`` [unit of the figure].

    Attributes
    ----------
    op : str
        One of ``>=, >, <=, <, ==``.
    value : float
        Threshold, in the figure's unit.
    source : str
        Where the budget comes from (``"issue 9"``, ``"camera-eval target"``).
    """

    op: str
    value: float
    source: str = "issue 9"

    def met(self, value: float | None) -> bool | None:
        """Whether ``value`` meets the budget (None if there is no value)."""
        if value is None or not math.isfinite(value):
            return None
        return bool(_OPS[self.op](value, self.value))

    def text(self, unit: str) -> str:
        """Human-readable budget, e.g. ``>= 50 x``."""
        return f"{self.op} {fmt_value(self.value, unit)}"


@dataclass(frozen=True)
class FigureSpec:
    """What a section promises to measure (so that a failed section still lists it).

    Attributes
    ----------
    key : str
        Stable identifier (``"sim.rigid_rtf_node"``), used in the JSON output.
    label : str
        One-line description for the table.
    unit : str
        ``"x"`` (real-time factor), ``"ms"``, ``"s"``, ``"Hz"``, ``"MiB"``, ``"count"``,
        ``"%"`` or ``""`` (a ratio).
    budget : Budget, optional
        The budget, if any.
    """

    key: str
    label: str
    unit: str
    budget: Budget | None = None


@dataclass
class Figure:
    """A measured figure (values of the repeats) or the reason it is missing.

    Attributes
    ----------
    spec : FigureSpec
        Key, label, unit, budget.
    values : list of float
        One value per repeat (or per window).
    status : str
        ``"measured"`` or ``"not measured: <reason>"``.
    note : str
        Context shown under the table (settings, tolerances, what was counted).
    extra : dict
        Further machine-readable detail for the JSON output.
    """

    spec: FigureSpec
    values: list[float] = field(default_factory=list)
    status: str = "measured"
    note: str = ""
    extra: dict[str, Any] = field(default_factory=dict)

    @property
    def measured(self) -> bool:
        """Whether the figure has at least one finite value."""
        return self.status == "measured" and any(math.isfinite(v) for v in self.values)

    def _finite(self) -> list[float]:
        return [float(v) for v in self.values if math.isfinite(v)]

    @property
    def median(self) -> float | None:
        """Median of the repeats (None when not measured)."""
        v = self._finite()
        return float(np.median(v)) if v and self.measured else None

    @property
    def minimum(self) -> float | None:
        """Smallest repeat."""
        v = self._finite()
        return float(min(v)) if v and self.measured else None

    @property
    def maximum(self) -> float | None:
        """Largest repeat."""
        v = self._finite()
        return float(max(v)) if v and self.measured else None

    @property
    def met(self) -> bool | None:
        """Whether the median meets the budget (None: no budget or not measured)."""
        if self.spec.budget is None or not self.measured:
            return None
        return self.spec.budget.met(self.median)

    def to_json(self) -> dict[str, Any]:
        """JSON-ready dictionary of the figure."""
        b = self.spec.budget
        return {
            "key": self.spec.key,
            "label": self.spec.label,
            "unit": self.spec.unit,
            "median": self.median,
            "min": self.minimum,
            "max": self.maximum,
            "repeats": len(self._finite()) if self.measured else 0,
            "values": [float(v) for v in self.values] if self.measured else [],
            "budget": None if b is None else {"op": b.op, "value": b.value,
                                              "text": b.text(self.spec.unit),
                                              "source": b.source},
            "met": self.met,
            "status": self.status,
            "note": self.note,
            **({"extra": self.extra} if self.extra else {}),
        }


def rig_data_dir() -> Path:
    """The real rig's logs: ``$BFR_RIG_DATA``, else the checkout's neighbour.

    The neighbour is ``../shared/data/ntnu-rig``
    (:func:`bfr_model.io.rig_conventions.default_data_dir`).
    """
    env = os.environ.get("BFR_RIG_DATA")
    return Path(env) if env else default_data_dir()


def not_measured(spec: FigureSpec, reason: str) -> Figure:
    """A figure that could not be measured, with the reason."""
    return Figure(spec, [], status=f"not measured: {reason}")


@dataclass(frozen=True)
class BenchOptions:
    """Options shared by the sections (from the command line).

    Attributes
    ----------
    repeats : int
        Repeats of each in-process measurement (sim, camera).
    quick : bool
        Short horizons and few frames (for tests); the figures are noisier.
    frames : int
        Camera frames per repeat.
    loop_duration : float
        Measured time of the DDS closed loop [s].
    loop_windows : int
        The loop's measured time is split into this many windows (its "repeats").
    loop_separate : bool
        The loop's camera and controller as two processes (``bfr rig --loop separate``)
        instead of composed in one (``bfr rig --realtime``'s default).
    diagnose_repeats : int
        Runs of ``bfr diagnose`` (each about a minute or more).
    diagnose_duration : float
        Length of the recording diagnosed [s].
    blindtest_cases : int
        Cases of the ``bfr blindtest`` run that is timed.
    keep : str or None
        Folder to keep the intermediate files in (recording, logs); temporary if None.
    profile : str or None
        Folder for cProfile output of the node processes (loop) and of ``bfr diagnose``;
        the figures measured under the profiler are slower than without it.
    """

    repeats: int = 5
    quick: bool = False
    frames: int = 100
    loop_duration: float = 30.0
    loop_windows: int = 3
    loop_separate: bool = False
    diagnose_repeats: int = 1
    diagnose_duration: float = 60.0
    blindtest_cases: int = 2
    keep: str | None = None
    profile: str | None = None


class Progress:
    """Progress lines on stderr, prefixed with the elapsed time."""

    def __init__(self, quiet: bool = False) -> None:
        self.t0 = time.perf_counter()
        self.quiet = quiet

    def __call__(self, msg: str) -> None:
        """Print one progress line."""
        if not self.quiet:
            print(f"[bench {time.perf_counter() - self.t0:6.1f} s] {msg}", file=sys.stderr,
                  flush=True)


@dataclass(frozen=True)
class Section:
    """A section of the bench: its name, what it measures and how.

    Attributes
    ----------
    name : str
        Name used by ``--only`` / ``--skip``.
    title : str
        One line for the help text.
    specs : sequence of FigureSpec
        Every figure it reports, in order.
    run : callable
        ``run(options, progress) -> list[Figure]``.
    """

    name: str
    title: str
    specs: Sequence[FigureSpec]
    run: Callable[[BenchOptions, Progress], list[Figure]]


def timed(fn: Callable[[], Any]) -> tuple[float, Any]:
    """Wall time [s] of one call of ``fn`` and its result."""
    t0 = time.perf_counter()
    out = fn()
    return time.perf_counter() - t0, out


def fmt_value(v: float | None, unit: str) -> str:
    """Format a value with its unit for the table."""
    if v is None or not math.isfinite(v):
        return "-"
    if unit == "x":
        if abs(v) >= 100:
            return f"{v:.0f} x"
        if abs(v) >= 10:
            return f"{v:.1f} x"
        return f"{v:.3g} x"
    if unit == "":
        return f"{v:.3g}"
    if unit == "count":
        return f"{v:.0f}"
    if unit == "%":
        return f"{v:.2f} %"
    if unit in ("ms", "s", "Hz", "MiB"):
        if abs(v) >= 100:
            return f"{v:.0f} {unit}"
        if abs(v) >= 10:
            return f"{v:.1f} {unit}"
        return f"{v:.3g} {unit}"
    return f"{v:.4g} {unit}"
