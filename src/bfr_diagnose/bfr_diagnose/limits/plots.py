"""Figures of a detection-limit run (PNG files; :func:`plot_all`).

- ``detection.png``: per mechanism, the fraction found in bins of size (points with Wilson
  intervals) and the fitted logistic curve of each tool, 50 % and 90 % sizes marked;
- ``param_error.png``: per mechanism, the parameter error of each found effect against its
  size (log-log);
- ``confusion.png``: both tools' confusion matrices;
- ``rates.png``: false-positive rate on clean cases, exact set per kind, with Wilson
  intervals, the two tools side by side.
"""

from __future__ import annotations

import itertools
import math
from pathlib import Path
from typing import Any

import numpy as np

from bfr_diagnose.effects import EFFECT_NAMES
from bfr_diagnose.limits.cases import FLOOR
from bfr_diagnose.limits.stats import TOOLS, wilson

__all__ = ["plot_all"]

_COLOURS = {"bfr": "tab:blue", "peer": "tab:orange"}
_LABELS = {"bfr": "bfr diagnose", "peer": "PySINDy peer"}


def _found(r: dict[str, Any], tool: str) -> list[str]:
    return [e for e in (r.get(f"{tool}_found") or "").split(";") if e]


def _grid(n: int) -> tuple[int, int]:
    cols = 4
    return math.ceil(n / cols), cols


def _detection(plt: Any, rows: list[dict[str, Any]], summary: dict[str, Any], path: Path
               ) -> Path:
    names = [e for e in EFFECT_NAMES if e in summary["tools"]["bfr"]["mechanisms"]]
    nr, nc = _grid(len(names))
    fig, axes = plt.subplots(nr, nc, figsize=(4.0 * nc, 2.8 * nr), squeeze=False)
    xs = np.linspace(-1.0, 1.0, 200)
    for ax, e in zip(axes.flat, names, strict=False):
        sub = [r for r in rows if e in (r.get("effects") or "").split(";")]
        x = np.array([math.log10(r[f"size_{e}"] / FLOOR[e]) for r in sub])
        edges = np.linspace(-1.0, 1.0, 6)
        for k, tool in enumerate(TOOLS):
            m = summary["tools"][tool]["mechanisms"][e]
            hit = np.array([e in _found(r, tool) for r in sub])
            for lo, hi in itertools.pairwise(edges):
                sel = (x >= lo) & (x <= hi)
                if sel.any():
                    kk, n = int(hit[sel].sum()), int(sel.sum())
                    wl, wh = wilson(kk, n)
                    c = 0.5 * (lo + hi) + (k - 0.5) * 0.04
                    ax.errorbar(10 ** c, kk / n, yerr=[[max(kk / n - wl, 0.0)],
                                                       [max(wh - kk / n, 0.0)]], fmt="o",
                                ms=3, color=_COLOURS[tool], lw=0.8)
            ax.plot(10 ** xs, 1.0 / (1.0 + np.exp(-np.clip(m["a"] + m["b"] * xs, -30, 30))),
                    color=_COLOURS[tool], label=_LABELS[tool])
            for key, ls in (("x50", "--"), ("x90", ":")):
                if -1.0 <= m[key] <= 1.0:
                    ax.axvline(10 ** m[key], color=_COLOURS[tool], ls=ls, lw=0.8)
        ax.set_xscale("log")
        ax.set_ylim(-0.05, 1.05)
        ax.set_title(f"{e} (n={len(sub)})", fontsize=9)
        ax.set_xlabel(f"size / F  (F = {FLOOR[e]:.2g})", fontsize=8)
        ax.set_ylabel("P(found)", fontsize=8)
    for ax in list(axes.flat)[len(names):]:
        ax.axis("off")
    axes.flat[0].legend(fontsize=7)
    fig.suptitle("Detection probability against size (points: binned, Wilson 95 %; lines: "
                 "logistic in log size; dashed 50 %, dotted 90 %)", fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)
    return path


def _param_error(plt: Any, rows: list[dict[str, Any]], summary: dict[str, Any], path: Path
                 ) -> Path:
    names = [e for e in EFFECT_NAMES if e in summary["tools"]["bfr"]["mechanisms"]]
    nr, nc = _grid(len(names))
    fig, axes = plt.subplots(nr, nc, figsize=(4.0 * nc, 2.8 * nr), squeeze=False)
    for ax, e in zip(axes.flat, names, strict=False):
        for tool in TOOLS:
            pts = [(r[f"size_{e}"] / FLOOR[e], r.get(f"{tool}_err_{e}")) for r in rows
                   if e in _found(r, tool) and e in (r.get("effects") or "").split(";")]
            pts = [(s, v) for s, v in pts if v is not None and np.isfinite(v) and v > 0]
            if pts:
                s, v = np.array(pts).T
                ax.scatter(s, v, s=6, color=_COLOURS[tool], label=_LABELS[tool], alpha=0.7)
        ax.axhline(0.2, color="grey", lw=0.6, ls="--")
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_title(e, fontsize=9)
        ax.set_xlabel("size / F", fontsize=8)
        ax.set_ylabel("|fit - true| / |true - nominal|", fontsize=7)
    for ax in list(axes.flat)[len(names):]:
        ax.axis("off")
    axes.flat[0].legend(fontsize=7)
    fig.suptitle("Parameter error of the effects found against their size (dashed: 20 %)",
                 fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)
    return path


def _confusion(plt: Any, summary: dict[str, Any], path: Path) -> Path:
    fig, axes = plt.subplots(1, 2, figsize=(15, 6.5))
    for ax, tool in zip(axes, TOOLS, strict=True):
        conf = summary["tools"][tool]["confusion"]
        rlab = list(conf)
        clab = list(next(iter(conf.values())))
        m = np.array([[conf[r][c] for c in clab] for r in rlab], float)
        norm = m / np.maximum(m.sum(axis=1, keepdims=True), 1.0)
        ax.imshow(norm, cmap="Blues", vmin=0, vmax=1)
        for i in range(len(rlab)):
            for j in range(len(clab)):
                if m[i, j]:
                    ax.text(j, i, int(m[i, j]), ha="center", va="center", fontsize=6,
                            color="white" if norm[i, j] > 0.6 else "black")
        ax.set_xticks(range(len(clab)), clab, rotation=75, fontsize=7)
        ax.set_yticks(range(len(rlab)), rlab, fontsize=7)
        ax.set_xlabel("named (the effect itself when found, else top-1)")
        ax.set_ylabel("concealed")
        ax.set_title(_LABELS[tool])
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)
    return path


def _rates(plt: Any, summary: dict[str, Any], path: Path) -> Path:
    keys = [("false_positive", "false positive\n(clean)"), ("exact_single", "exact\nsingle"),
            ("exact_pair", "exact\npair"), ("exact_triple", "exact\ntriple"),
            ("exact_rigid", "exact\nrigid truth"), ("exact_contact", "exact\ncontact truth")]
    fig, ax = plt.subplots(figsize=(9, 3.5))
    for k, tool in enumerate(TOOLS):
        s = summary["tools"][tool]
        xs = np.arange(len(keys)) + (k - 0.5) * 0.35
        v = np.nan_to_num(np.array([s[key]["rate"] for key, _ in keys], float))
        lo = np.nan_to_num(np.array([s[key]["lo"] for key, _ in keys], float), nan=0.0)
        hi = np.nan_to_num(np.array([s[key]["hi"] for key, _ in keys], float), nan=0.0)
        ax.bar(xs, v, width=0.35, color=_COLOURS[tool], label=_LABELS[tool])
        ax.errorbar(xs, v, yerr=[np.clip(v - lo, 0, None), np.clip(hi - v, 0, None)],
                    fmt="none", color="k", lw=0.8)
    ax.set_xticks(range(len(keys)), [lab for _, lab in keys], fontsize=8)
    ax.set_ylim(0, 1.05)
    ax.set_ylabel("fraction (Wilson 95 %)")
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)
    return path


def plot_all(out: Path, rows: list[dict[str, Any]], summary: dict[str, Any]) -> list[Path]:
    """Write the figures (module docstring) into ``out``; the paths."""
    import matplotlib  # noqa: PLC0415 - matplotlib for plots

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # noqa: PLC0415 - matplotlib for plots

    scored = [r for r in rows if r.get("status") == "ok"]
    return [_detection(plt, scored, summary, out / "detection.png"),
            _param_error(plt, scored, summary, out / "param_error.png"),
            _confusion(plt, summary, out / "confusion.png"),
            _rates(plt, summary, out / "rates.png")]
