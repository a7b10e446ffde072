"""What a reader read and what it could not: one account per read, and the physical gates.

Every reader of :mod:`bfr_model.io` (rig log, CSV, bag) builds one :class:`ReadAccount` per
recording it returns, the same way, and stores it in ``Recording.meta["read_account"]``
(:meth:`ReadAccount.to_json`). The account balances exactly::

    samples_present = samples_used + sum(dropped.values())                          (1)

``samples_present`` counts every sample the source holds or held (a rig log's data lines,
cut and unparseable ones included; a CSV's data rows; a bag's time-base messages, those in
corrupt chunks or past a truncation included, counted from the bag's own indexes or
estimated from the bytes lost and then marked ``exact=False``). ``dropped`` names the cause
of each sample not used:

==================  =========================================================================
cause               meaning
==================  =========================================================================
``corrupt``         a line or chunk that cannot be parsed (flipped bytes, a bad CRC)
``truncated``       cut off at the end of the file (a last line, a chunk, the bag's tail)
``duplicate``       a time stamp equal to the previous kept one (the first is kept)
``out_of_order``    a time stamp before the previous kept one
``out_of_range``    a value no hardware of the design makes (see :class:`Gates`)
``non_finite``      NaN or infinity in a value the sample needs
==================  =========================================================================

``degraded`` counts samples used whose ball fix was excluded (``ball_off_frame``: a ball
position farther from the axis than the frame reaches). The lost fraction is

    lost = (samples_present - samples_used + sum(degraded.values())) / samples_present  (2)

and the one rule of the project (:func:`enforce`): more than :data:`LOSS_LIMIT` lost stops
the read with :class:`PartialReadError` unless the caller allows a partial read (every CLI
that reads recordings: ``--allow-partial``). So does an account whose ``samples_present``
is only an estimate (a bag cut short with neither summary nor metadata.yaml: what followed
the cut is unknown, so the loss cannot be shown to be small). The rule is applied only
there.

``garbage`` counts lines found among a run's data lines (after its first, before its last)
that are neither data nor anything a rig's terminal writes between them (``[inf]`` messages,
``[obs]`` lines, blank lines): unparseable text. They are not samples (nothing says what
they held) and are left out of eq. 1-2, but counted and their first named in ``actions``;
the garbage share ``garbage / (samples_present + garbage)`` is held to the same
:data:`LOSS_LIMIT`. A rig's own stream writes nothing else between its data lines (the
NTNU logs: none in ~220,000 lines), so every such line is damage to the file (a transfer or
disk error, another process writing into the terminal); a few stray ones cost nothing and
are reported, but past 1 % of the lines the file is not what the rig wrote and the read is
refused like a loss of samples (``--allow-partial`` reads it anyway).

``seconds_present`` and ``seconds_used`` are both :func:`covered_seconds` with one hole
limit, that of the samples present, so that ``seconds_used <= seconds_present`` always (a
limit from the used samples alone moves when duplicates are dropped, and counted a hole of
the present samples as covered).

Physical gates (:func:`gate_samples`), the same for every reader, in this order (first
:func:`bfr_model.turns.unwrap_turns`: an encoder reported within one turn, ``[-pi, pi)``
or ``[0, 2 pi)``, is unwrapped to the accumulating angle the formats mean, said in the
account's actions, before step 3 could take its wraps for jumps; the readers use
:attr:`GateResult.theta`):

1. non-finite time, angle, rate or torque: the sample is dropped (``non_finite``);
2. an isolated time stamp ahead of its successor whose removal restores the order is dropped
   (``out_of_order``; a corrupted stamp must not take the rest of the run with it); then
   every stamp not after the latest kept one is dropped (``duplicate`` when equal,
   ``out_of_order`` when before);
3. the frame angle may not move by more than half a turn between two samples (an encoder
   read that often cannot tell the direction; no hardware of the design turns that fast):
   isolated spikes are dropped, and at a lasting jump the longest continuous stretch is kept,
   the rest dropped (``out_of_range``);
4. a rate (``theta_dot``, a logged ball-angle rate) with ``|rate| dt > pi`` (half a turn
   per median sample interval) or a torque
   beyond :attr:`Gates.max_torque` is dropped (``out_of_range``);
5. a ball centre farther from the axis than :attr:`Gates.max_ball_radius` is excluded
   (``degraded["ball_off_frame"]``; the sample's encoder and torque are used).

The bounds of the gates come from the rig's parameter file (:meth:`Gates.from_params`), with
factors wide enough for any rig of the design and any camera calibration: they catch values
no such rig makes (``x = 1e300 m``, ``theta = 1e9 rad``), never a plausible one.

Pure numpy; no ``rclpy``.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from bfr_model.params import RigParams, load_params
from bfr_model.recording import RecordingError
from bfr_model.turns import unwrap_turns

__all__ = [
    "CAUSES",
    "DEGRADED",
    "LOSS_LIMIT",
    "GateResult",
    "Gates",
    "PartialReadError",
    "ReadAccount",
    "account_of",
    "covered_seconds",
    "enforce",
    "gate_samples",
    "hole_limit",
]

#: Causes of a dropped sample, in the order they are reported.
CAUSES = ("corrupt", "truncated", "duplicate", "out_of_order", "out_of_range", "non_finite")
#: Kinds of a used sample with a field excluded.
DEGRADED = ("ball_off_frame",)
#: Largest lost fraction (eq. 2) read without ``allow_partial`` [-].
LOSS_LIMIT = 0.01
#: Factor on the frame's reach (largest contour radius plus the ball radius) [-].
BALL_REACH_FACTOR = 3.0
#: Factor on the actuator's torque limit [-].
TORQUE_FACTOR = 100.0


class PartialReadError(RecordingError):
    """More than :data:`LOSS_LIMIT` of a recording was lost and no partial read was allowed."""


def _counts(pairs: Any, allowed: tuple[str, ...], what: str) -> tuple[tuple[str, int], ...]:
    """``pairs`` (a mapping or pairs) as sorted ``(name, count)`` pairs, zeros left out."""
    items = dict(pairs.items() if hasattr(pairs, "items") else pairs)
    for name, count in items.items():
        if name not in allowed:
            raise ValueError(f"{what}: unknown cause {name!r}; known: {', '.join(allowed)}")
        if int(count) < 0:
            raise ValueError(f"{what}[{name!r}] must be >= 0, got {count}")
    return tuple((name, int(items[name])) for name in allowed if int(items.get(name, 0)) > 0)


@dataclass(frozen=True, kw_only=True)
class ReadAccount:
    """What one read of one recording used against what its source holds (module doc).

    Attributes
    ----------
    source : str
        The file or bag read.
    kind : str
        ``"rig_log"``, ``"csv"`` or ``"bag"``.
    samples_present : int
        Samples the source holds or held [-] (eq. 1).
    samples_used : int
        Samples in the recording [-].
    seconds_present : float
        Time spanned by the samples present [s] (NaN when not known).
    seconds_used : float
        Time covered by the samples used [s]: their span less its holes
        (:func:`covered_seconds`).
    dropped : tuple of (str, int)
        Samples not used, by cause (:data:`CAUSES`); ``samples_present - samples_used``.
    degraded : tuple of (str, int)
        Samples used with a field excluded, by kind (:data:`DEGRADED`).
    actions : tuple of str
        What was done about each problem, where (line, stamp or byte) it first occurred.
    exact : bool
        False when ``samples_present`` is an estimate (a bag cut without an index).
    garbage : int
        Unparseable lines among the data lines [-] (module doc; not samples, not in eq. 1).
    """

    source: str
    kind: str
    samples_present: int
    samples_used: int
    seconds_present: float
    seconds_used: float
    dropped: tuple[tuple[str, int], ...] = ()
    degraded: tuple[tuple[str, int], ...] = ()
    actions: tuple[str, ...] = ()
    exact: bool = True
    garbage: int = 0

    def __post_init__(self) -> None:
        object.__setattr__(self, "dropped", _counts(self.dropped, CAUSES, "dropped"))
        object.__setattr__(self, "degraded", _counts(self.degraded, DEGRADED, "degraded"))
        object.__setattr__(self, "actions", tuple(str(a) for a in self.actions))
        if self.samples_used < 0 or self.samples_present < self.samples_used:
            raise ValueError(f"{self.source}: samples used ({self.samples_used}) must lie in "
                             f"[0, samples present = {self.samples_present}]")
        if self.garbage < 0:
            raise ValueError(f"{self.source}: garbage lines must be >= 0, got {self.garbage}")
        lost = sum(c for _, c in self.dropped)
        if self.samples_present - self.samples_used != lost:
            raise ValueError(f"{self.source}: account does not balance: {self.samples_present}"
                             f" present - {self.samples_used} used != {lost} dropped")

    @property
    def lost(self) -> int:
        """Samples lost or degraded [-] (numerator of eq. 2)."""
        return (self.samples_present - self.samples_used
                + sum(c for _, c in self.degraded))

    @property
    def lost_fraction(self) -> float:
        """Eq. 2 [-] (0 for an empty source)."""
        return self.lost / self.samples_present if self.samples_present else 0.0

    @property
    def garbage_fraction(self) -> float:
        """Unparseable lines among the data lines over those and the samples present [-]."""
        total = self.samples_present + self.garbage
        return self.garbage / total if total else 0.0

    def line(self) -> str:
        """The account in one line (what every CLI prints on stderr)."""
        secs = (f"{self.seconds_used:.3f} of {self.seconds_present:.3f} s"
                if math.isfinite(self.seconds_present) else f"{self.seconds_used:.3f} s")
        approx = "" if self.exact else "~"
        out = (f"read {self.source}: {self.samples_used} of {approx}{self.samples_present} "
               f"samples used, {secs}")
        parts = [f"{c} {name}" for name, c in self.dropped]
        parts += [f"{c} {name} (kept, ball excluded)" for name, c in self.degraded]
        if parts:
            out += f"; {100 * self.lost_fraction:.2f} % lost: " + ", ".join(parts)
        if self.garbage:
            out += (f"; {self.garbage} unparseable line(s) among the data lines "
                    f"({100 * self.garbage_fraction:.2f} % of them)")
        if self.actions:
            out += "; " + "; ".join(self.actions)
        return out

    def to_json(self) -> dict[str, Any]:
        """JSON-ready dict (``meta["read_account"]``, report.md, ``diagnosis.json``)."""
        return {"source": self.source, "kind": self.kind,
                "samples_present": self.samples_present, "samples_used": self.samples_used,
                "seconds_present": (self.seconds_present if math.isfinite(self.seconds_present)
                                    else None),
                "seconds_used": self.seconds_used, "dropped": dict(self.dropped),
                "degraded": dict(self.degraded), "lost_fraction": self.lost_fraction,
                "actions": list(self.actions), "exact": self.exact,
                "garbage": self.garbage}

    @classmethod
    def from_json(cls, d: dict[str, Any]) -> ReadAccount:
        """Inverse of :meth:`to_json`."""
        sp = d.get("seconds_present")
        return cls(source=str(d["source"]), kind=str(d["kind"]),
                   samples_present=int(d["samples_present"]),
                   samples_used=int(d["samples_used"]),
                   seconds_present=float("nan") if sp is None else float(sp),
                   seconds_used=float(d["seconds_used"]), dropped=d.get("dropped", {}),
                   degraded=d.get("degraded", {}), actions=d.get("actions", ()),
                   exact=bool(d.get("exact", True)), garbage=int(d.get("garbage", 0)))

    @classmethod
    def combine(cls, accounts: Iterable[ReadAccount]) -> ReadAccount:
        """One account of several reads of one source (e.g. the runs of one rig log).

        Counts add up; of the actions, the first of each kind is kept (where it first
        happened in the file).
        """
        acc = list(accounts)
        if not acc:
            raise ValueError("combine: no accounts")
        dropped: dict[str, int] = {}
        degraded: dict[str, int] = {}
        for a in acc:
            for k, c in a.dropped:
                dropped[k] = dropped.get(k, 0) + c
            for k, c in a.degraded:
                degraded[k] = degraded.get(k, 0) + c
        label = f" ({len(acc)} runs)" if len(acc) > 1 else ""
        actions: dict[str, str] = {}  # the first of each kind (the runs are in file order)
        for a in acc:
            for x in a.actions:
                actions.setdefault(x.split(":", 1)[0], x)
        return cls(source=acc[0].source + label, kind=acc[0].kind,
                   samples_present=sum(a.samples_present for a in acc),
                   samples_used=sum(a.samples_used for a in acc),
                   seconds_present=sum(a.seconds_present for a in acc),
                   seconds_used=sum(a.seconds_used for a in acc), dropped=dropped,
                   degraded=degraded, actions=list(actions.values()),
                   exact=all(a.exact for a in acc), garbage=sum(a.garbage for a in acc))


def hole_limit(t: NDArray[np.float64], hole: float = 3.0) -> float:
    """The longest interval [s] between samples at times ``t`` that is not a hole.

    ``hole`` times the median positive interval of the sorted finite times (a repeated stamp
    is no interval); infinite (no holes) when there is none.
    """
    t = np.asarray(t, float)
    t = t[np.isfinite(t)]
    d = np.diff(np.sort(t))
    d = d[d > 0]
    return hole * float(np.median(d)) if d.size else math.inf


def covered_seconds(t: NDArray[np.float64], hole: float = 3.0, *,
                    limit: float | None = None) -> float:
    """Time covered by samples at times ``t`` [s]: their span less the holes in it.

    A hole is an interval longer than ``limit`` (default: :func:`hole_limit`, ``hole``
    times the median interval; a corrupt chunk, a run of dropped lines); the seconds used
    by a read do not count it. With one ``limit`` for a set of times and a subset of it, the
    subset never covers more: each of its intervals counted is the sum of the set's
    intervals inside it, each at most as long (:meth:`GateResult.account`).
    """
    t = np.asarray(t, float)
    t = t[np.isfinite(t)]
    if t.size < 2:
        return 0.0
    d = np.diff(np.sort(t))
    lim = hole_limit(t, hole) if limit is None else float(limit)
    return float(np.sum(d[d <= lim]))


def account_of(rec: Any) -> ReadAccount | None:
    """The account stored in a recording's ``meta`` (None when it has none)."""
    d = rec.meta.get("read_account")
    return ReadAccount.from_json(d) if isinstance(d, dict) else None


def enforce(account: ReadAccount, allow_partial: bool, limit: float = LOSS_LIMIT) -> None:
    """The one rule: more than ``limit`` lost (eq. 2) stops the read unless allowed.

    Raises
    ------
    PartialReadError
        One line: the account and how to read anyway.
    """
    if allow_partial:
        return
    if not account.exact:
        raise PartialReadError(f"{account.line()}; the source's end is missing and nothing "
                               f"says how many samples it held: refused (--allow-partial uses "
                               f"what was read)")
    if account.garbage_fraction > limit:
        raise PartialReadError(f"{account.line()}; more than {100 * limit:g} % of the lines "
                               f"among the data are unparseable: refused (--allow-partial "
                               f"uses what was read)")
    if account.lost_fraction <= limit:
        return
    raise PartialReadError(f"{account.line()}; more than {100 * limit:g} % lost: refused "
                           f"(--allow-partial uses what was read)")


# -- physical gates -------------------------------------------------------------------------
@dataclass(frozen=True, kw_only=True)
class Gates:
    """Bounds of the physical gates (module doc).

    Attributes
    ----------
    max_ball_radius : float
        Largest distance of a ball centre from the axis [m].
    max_torque : float
        Largest magnitude of a torque command [N m].
    max_angle_step : float
        Largest change of the frame angle between two samples [rad].
    """

    max_ball_radius: float
    max_torque: float
    max_angle_step: float = math.pi

    def __post_init__(self) -> None:
        for name in ("max_ball_radius", "max_torque", "max_angle_step"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0):
                raise ValueError(f"Gates.{name} must be positive and finite, got {v}")

    @classmethod
    def from_params(cls, params: RigParams | None = None) -> Gates:
        """Bounds from a rig's parameters (default: rig.yaml) with the module's factors."""
        p = params if params is not None else _default_params()
        c = p.frame.contour
        reach = c.a + abs(c.b) + float(np.sum(np.abs(c.harmonic_cos)) +
                                        np.sum(np.abs(c.harmonic_sin))) + p.ball.radius
        return cls(max_ball_radius=BALL_REACH_FACTOR * reach,
                   max_torque=TORQUE_FACTOR * p.actuator.torque_limit)


_PARAMS_CACHE: list[RigParams] = []


def _default_params() -> RigParams:
    if not _PARAMS_CACHE:
        _PARAMS_CACHE.append(load_params())
    return _PARAMS_CACHE[0]


@dataclass(frozen=True, kw_only=True)
class GateResult:
    """Which samples the gates keep and why the others go.

    Attributes
    ----------
    keep : ndarray of bool
        Samples kept.
    ball_off : ndarray of bool
        Kept samples whose ball fix is excluded (off the frame).
    dropped : dict of str to int
        Samples dropped by cause.
    first : dict of str to int
        Index (into the input) of the first sample dropped or excluded per cause.
    theta : ndarray or None
        The frame angle as used [rad]: the input's, with
        :func:`bfr_model.turns.unwrap_turns` applied.
    wraps : int
        Wraps of a within-a-turn encoder undone (the first at ``first["wrapped"]``).
    """

    keep: NDArray[np.bool_]
    ball_off: NDArray[np.bool_]
    dropped: dict[str, int] = field(default_factory=dict)
    first: dict[str, int] = field(default_factory=dict)
    theta: NDArray[np.float64] | None = None
    wraps: int = 0

    def actions(self, where: Callable[[int], str]) -> list[str]:
        """One phrase per cause: what was done and where it first happened."""
        what = {"non_finite": "dropped (NaN or infinite value)",
                "duplicate": "dropped (stamp repeats the previous; first kept)",
                "out_of_order": "dropped (stamp before the previous)",
                "out_of_range": "dropped (value no hardware makes)"}
        out = [f"{k}: {what[k]}, first at {where(self.first[k])}"
               for k in CAUSES if k in self.dropped and k in what]
        if self.ball_off.any():
            out.append(f"ball_off_frame: ball fix excluded, first at "
                       f"{where(self.first['ball_off_frame'])}")
        if self.wraps:
            out.append(f"theta: reported within one turn; {self.wraps} wrap(s) undone (the "
                       f"angle accumulates over turns), first at "
                       f"{where(self.first['wrapped'])}")
        return out

    def account(self, *, source: str, kind: str, t: NDArray[np.float64],
                lines: Sequence[int] | NDArray[np.int64], lost: Mapping[str, Sequence[int]],
                unit: str, details: Mapping[str, str] | None = None,
                garbage: Sequence[int] = ()) -> ReadAccount:
        """The read's account: the gates' drops plus what the parser skipped before them.

        Parameters
        ----------
        source, kind : str
            As in :class:`ReadAccount`.
        t : ndarray
            Stamps of the samples the gates saw [s].
        lines : sequence of int
            Line number of each of those samples (where drops are reported).
        lost : mapping of str to sequence of int
            Lines skipped by the parser before the gates, by cause (their line numbers).
        unit : str
            What a skipped line is called in the actions ("line", "row").
        details : mapping of str to str, optional
            What was wrong with the first line of each cause in ``lost`` (e.g. "9 fields
            where 8 expected"), added to its action.
        garbage : sequence of int
            Line numbers of the unparseable lines among the data lines (module doc).
        """
        details = details or {}
        dropped = dict(self.dropped)
        for cause, where in lost.items():
            dropped[cause] = dropped.get(cause, 0) + len(where)
        actions = self.actions(lambda i: f"line {lines[i]}")
        actions += [f"{cause}: {len(where)} {unit}(s) skipped, first at line {where[0]}"
                    + (f" ({details[cause]})" if details.get(cause) else "")
                    for cause, where in lost.items()]
        if len(garbage):
            actions.append(f"garbage: {len(garbage)} unparseable {unit}(s) among the data "
                           f"{unit}s skipped (not samples), first at line {garbage[0]}")
        tp = t[np.isfinite(t)]
        limit = hole_limit(tp)  # one limit for both: used <= present (module doc)
        return ReadAccount(
            source=source, kind=kind,
            samples_present=len(lines) + sum(len(w) for w in lost.values()),
            samples_used=int(self.keep.sum()),
            seconds_present=covered_seconds(tp, limit=limit),
            seconds_used=covered_seconds(t[self.keep], limit=limit),
            dropped=dropped, degraded={"ball_off_frame": int(self.ball_off.sum())},
            actions=actions, garbage=len(garbage))


def _first_of(mask: NDArray[np.bool_], index: NDArray[np.intp]) -> int | None:
    return int(index[np.argmax(mask)]) if mask.any() else None


def _drop(keep: NDArray[np.bool_], idx: NDArray[np.intp], mask: NDArray[np.bool_],
          cause: str, dropped: dict[str, int], first: dict[str, int]) -> None:
    """Drop the samples ``idx[mask]`` (indices into the input) for ``cause``."""
    if not mask.any():
        return
    keep[idx[mask]] = False
    dropped[cause] = dropped.get(cause, 0) + int(mask.sum())
    i = _first_of(mask, idx)
    if i is not None and (cause not in first or i < first[cause]):
        first[cause] = i


def _time_gate(t: NDArray[np.float64], keep: NDArray[np.bool_], dropped: dict[str, int],
               first: dict[str, int]) -> None:
    """Step 2 of the module doc: isolated stamps ahead of time, then order and repeats."""
    idx = np.nonzero(keep)[0]
    tk = t[idx]
    if tk.size >= 3:
        ahead = np.zeros(tk.size, bool)
        ahead[1:-1] = (tk[1:-1] > tk[2:]) & (tk[:-2] < tk[2:])
        ahead[0] = tk[0] > tk[1] and (tk.size < 3 or tk[1] < tk[2])
        _drop(keep, idx, ahead, "out_of_order", dropped, first)
        idx = np.nonzero(keep)[0]
        tk = t[idx]
    if tk.size < 2:
        return
    prev = np.maximum.accumulate(tk)[:-1]
    later = tk[1:]
    dup = np.r_[False, later == prev]
    back = np.r_[False, later < prev]
    _drop(keep, idx, dup, "duplicate", dropped, first)
    _drop(keep, idx, back, "out_of_order", dropped, first)


def _angle_gate(theta: NDArray[np.float64], keep: NDArray[np.bool_], step: float,
                dropped: dict[str, int], first: dict[str, int]) -> None:
    """Step 3 of the module doc: spikes, then the longest stretch without a jump."""
    idx = np.nonzero(keep)[0]
    th = theta[idx]
    if th.size >= 2:
        jump = np.abs(np.diff(th)) > step
        spike = np.zeros(th.size, bool)
        if th.size >= 3:
            spike[1:-1] = jump[:-1] & jump[1:] & (np.abs(th[2:] - th[:-2]) <= step)
        spike[0] = jump[0] and (th.size < 3 or not jump[1])
        spike[-1] = spike[-1] or (jump[-1] and (th.size < 3 or not jump[-2]))
        _drop(keep, idx, spike, "out_of_range", dropped, first)
        idx = np.nonzero(keep)[0]
        th = theta[idx]
    if th.size < 2:
        return
    cut = np.nonzero(np.abs(np.diff(th)) > step)[0] + 1
    if cut.size:
        edges = np.r_[0, cut, th.size]
        k = int(np.argmax(np.diff(edges)))
        outside = np.ones(th.size, bool)
        outside[edges[k]:edges[k + 1]] = False
        _drop(keep, idx, outside, "out_of_range", dropped, first)


def gate_samples(t: NDArray[np.float64], theta: NDArray[np.float64],
                 theta_dot: NDArray[np.float64], torque: NDArray[np.float64],
                 ball_x: NDArray[np.float64] | None = None,
                 ball_y: NDArray[np.float64] | None = None, *,
                 others: Iterable[NDArray[np.float64]] = (),
                 rates: Iterable[NDArray[np.float64]] = (),
                 gates: Gates | None = None) -> GateResult:
    """Apply the physical gates (module doc, steps 1-5) to one run's samples.

    Parameters
    ----------
    t, theta, theta_dot, torque : ndarray, shape (n,)
        Time [s], frame angle [rad], rate [rad/s], torque [N m] as read.
    ball_x, ball_y : ndarray, optional
        Ball centre [m] where a fix is held (NaN or absent where none).
    others : iterable of ndarray
        Further columns that must be finite for a sample to be kept.
    rates : iterable of ndarray
        Further angle rates [rad/s] held to the rate bound of step 4 (NaN passes).
    gates : Gates, optional
        The bounds (default: :meth:`Gates.from_params` of rig.yaml).

    Returns
    -------
    GateResult
    """
    g = gates if gates is not None else Gates.from_params()
    n = t.shape[0]
    keep = np.ones(n, bool)
    dropped: dict[str, int] = {}
    first: dict[str, int] = {}
    theta, wrapped = unwrap_turns(theta, t, theta_dot)
    if wrapped.size:
        first["wrapped"] = int(wrapped[0])
    all_idx = np.arange(n)
    finite = np.isfinite(t) & np.isfinite(theta) & np.isfinite(theta_dot) & np.isfinite(torque)
    for col in others:
        finite &= np.isfinite(col)
    _drop(keep, all_idx, ~finite, "non_finite", dropped, first)
    _time_gate(t, keep, dropped, first)
    _angle_gate(theta, keep, g.max_angle_step, dropped, first)
    idx = np.nonzero(keep)[0]
    if idx.size >= 2:
        dt = float(np.median(np.diff(t[idx])))
        with np.errstate(invalid="ignore", over="ignore"):
            fast = np.abs(theta_dot[idx]) * dt > g.max_angle_step
            for r in rates:
                fast |= np.abs(r[idx]) * dt > g.max_angle_step
    else:
        fast = np.zeros(idx.size, bool)
    _drop(keep, idx, fast | (np.abs(torque[idx]) > g.max_torque), "out_of_range", dropped,
          first)
    ball_off = np.zeros(n, bool)
    if ball_x is not None and ball_y is not None:
        with np.errstate(over="ignore", invalid="ignore"):
            r = np.hypot(ball_x, ball_y)
        ball_off = keep & np.isfinite(r) & (r > g.max_ball_radius)
        ball_off |= keep & (np.isinf(ball_x) | np.isinf(ball_y))
        if ball_off.any():
            first["ball_off_frame"] = int(np.argmax(ball_off))
    return GateResult(keep=keep, ball_off=ball_off, dropped=dropped, first=first, theta=theta,
                      wraps=int(wrapped.size))
