"""Statistics of a detection-limit run: both tools scored alike, with intervals.

Per mechanism ``e`` and tool, over every scored case that conceals ``e`` (alone, in a pair
or a triple), with ``x = log10(size / FLOOR[e])`` (``x`` in ``[-1, 1]`` by the draw):

- **detection curve**: the logistic ``P(found) = 1 / (1 + exp(-(a + b x)))`` fitted by
  maximum likelihood (Newton's method, a weak ridge ``b^2 / 200`` that only matters under
  complete separation); the sizes at 50 % and 90 %: ``x_p = (logit p - a) / b``, reported
  as sizes ``FLOOR 10^x_p``; 95 % intervals from the percentile bootstrap over cases. A
  size outside the drawn range is reported as censored (``< 0.1 FLOOR``, ``> 10 FLOOR``).
- **parameter error** ``|fitted - true| / |true - nominal|`` of the cases where ``e`` was
  found, its median per third of a decade of size.

Over the run: the **confusion matrix** (rows: each concealed effect and ``clean``; columns:
the effect itself when found, else the tool's top-1, else ``none``), **pairs and triples
found as such** (the set exactly) and all found (also beyond chance: minus the share of
clean cases on which the tool names the whole set), the **false-positive rate** over the clean
cases (any effect named) with its Wilson 95 % interval, and per model structure (rigid, contact).

Wilson interval (Wilson 1927) of ``k`` successes in ``n``, ``z = 1.96``:
``(p + z^2/2n -+ z sqrt(p(1-p)/n + z^2/4n^2)) / (1 + z^2/n)``, ``p = k/n``.

**Detection beyond chance** per mechanism (informedness, Youden's J; Youden 1950): the
detection rate over the cases that conceal ``e`` minus the rate at which the tool names
``e`` on the clean cases, ``J = p_1 - p_0``. A tool that names ``e`` on every case "finds"
it every time and has ``J = 0``; the raw found counts reward that, ``J`` does not. Its 95 %
interval is Newcombe's hybrid score interval for a difference of independent proportions
(Newcombe 1998, method 10), from the Wilson intervals ``[l_i, u_i]`` of both:
``J - sqrt((p_1 - l_1)^2 + (u_0 - p_0)^2)`` to ``J + sqrt((u_1 - p_1)^2 + (p_0 - l_0)^2)``.
"""

from __future__ import annotations

import itertools
import json
import math
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from bfr_diagnose.effects import EFFECT_NAMES
from bfr_diagnose.limits.cases import FLOOR

__all__ = ["TOOLS", "detection_curve", "load_records", "logistic_fit", "newcombe_difference",
           "summarise", "wilson", "write_report"]

TOOLS = ("bfr", "peer")
_GENERATORS = ("rigid", "contact", "nodes")
Z95 = 1.959963984540054
_RIDGE = 1.0 / 200.0


def wilson(k: int, n: int, z: float = Z95) -> tuple[float, float]:
    """Wilson score interval of a proportion ``k / n`` (module docstring); NaN if n = 0."""
    if n <= 0:
        return float("nan"), float("nan")
    p = k / n
    den = 1.0 + z * z / n
    mid = p + z * z / (2 * n)
    half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n))
    lo = 0.0 if k == 0 else max(0.0, (mid - half) / den)
    hi = 1.0 if k == n else min(1.0, (mid + half) / den)
    return lo, hi


def newcombe_difference(k1: int, n1: int, k0: int, n0: int, z: float = Z95
                        ) -> tuple[float, float, float]:
    """``(p1 - p0, lo, hi)``: a difference of two proportions and its 95 % interval.

    Newcombe's hybrid score interval (module docstring); NaN if either ``n`` is 0.
    """
    if n1 <= 0 or n0 <= 0:
        return float("nan"), float("nan"), float("nan")
    p1, p0 = k1 / n1, k0 / n0
    l1, u1 = wilson(k1, n1, z)
    l0, u0 = wilson(k0, n0, z)
    d = p1 - p0
    return (d, d - math.sqrt((p1 - l1) ** 2 + (u0 - p0) ** 2),
            d + math.sqrt((u1 - p1) ** 2 + (p0 - l0) ** 2))


def logistic_fit(x: NDArray[np.float64], y: NDArray[np.float64], iters: int = 50
                 ) -> tuple[float, float]:
    """``(a, b)`` of ``P(y=1) = 1/(1+exp(-(a + b x)))`` by penalised Newton (docstring)."""
    X = np.column_stack([np.ones_like(x), x])
    beta = np.zeros(2)
    pen = np.diag([0.0, 2.0 * _RIDGE])
    for _ in range(iters):
        eta = np.clip(X @ beta, -30.0, 30.0)
        p = 1.0 / (1.0 + np.exp(-eta))
        g = X.T @ (y - p) - pen @ beta
        H = (X * (p * (1 - p))[:, None]).T @ X + pen + 1e-9 * np.eye(2)
        step = np.linalg.solve(H, g)
        beta = beta + step
        if np.max(np.abs(step)) < 1e-10:
            break
    return float(beta[0]), float(beta[1])


def _x_at(a: float, b: float, p: float) -> float:
    """``x`` where the curve reaches ``p`` (inf/-inf when it never does in the right way)."""
    if b <= 1e-9:
        return math.inf if a < math.log(p / (1 - p)) else -math.inf
    return (math.log(p / (1 - p)) - a) / b


def detection_curve(x: NDArray[np.float64], hit: NDArray[np.bool_], n_boot: int,
                    rng: np.random.Generator) -> dict[str, Any]:
    """Logistic fit, x50 and x90 with percentile-bootstrap 95 % intervals (docstring)."""
    y = hit.astype(float)
    a, b = logistic_fit(x, y)
    out: dict[str, Any] = {"n": int(x.size), "hits": int(y.sum()), "a": a, "b": b}
    boots = {0.5: [], 0.9: []}
    for _ in range(n_boot):
        i = rng.integers(0, x.size, x.size)
        ab = logistic_fit(x[i], y[i])
        for p, vals in boots.items():
            vals.append(_x_at(*ab, p))
    for (p, vals), key in zip(boots.items(), ("x50", "x90"), strict=True):
        # censored values (never reached in the right way) kept as far outside the range
        v = np.clip(np.array(vals), -9.0, 9.0) if vals else np.array([np.nan])
        out[key] = _x_at(a, b, p)
        out[f"{key}_lo"] = float(np.percentile(v, 2.5)) if n_boot else float("nan")
        out[f"{key}_hi"] = float(np.percentile(v, 97.5)) if n_boot else float("nan")
    return out


def load_records(*outs: Path) -> list[dict[str, Any]]:
    """Every case record of one or more runs, by run and index."""
    rows = []
    for out in outs:
        rows += sorted((json.loads(p.read_text()) for p in (out / "cases").glob("case_*.json")),
                       key=lambda r: r["index"])
    return rows


def _found(r: dict[str, Any], tool: str) -> list[str]:
    f = r.get(f"{tool}_found") or ""
    return [e for e in f.split(";") if e]


def _truth(r: dict[str, Any]) -> list[str]:
    return [e for e in (r.get("effects") or "").split(";") if e]


def _rate(flags: list[bool]) -> dict[str, Any]:
    k, n = int(sum(flags)), len(flags)
    lo, hi = wilson(k, n)
    return {"k": k, "n": n, "rate": k / n if n else float("nan"), "lo": lo, "hi": hi}


def _confusion(rows: list[dict[str, Any]], tool: str) -> dict[str, dict[str, int]]:
    cols = [*EFFECT_NAMES, "none"]
    conf = {r: dict.fromkeys(cols, 0) for r in [*EFFECT_NAMES, "clean"]}
    for r in rows:
        found = _found(r, tool)
        top = found[0] if found else "none"
        truth = _truth(r)
        if not truth:
            conf["clean"][top] += 1
        for e in truth:
            conf[e][e if e in found else top] += 1
    return conf


def _all_found_beyond_chance(sub: list[dict[str, Any]], clean: list[dict[str, Any]],
                             tool: str, n_boot: int, rng: np.random.Generator
                             ) -> dict[str, Any]:
    """All of a case's effects found, minus the chance of naming them all on a clean case.

    Informedness of a set (module docstring): ``J = mean_i [S_i found] - mean_i c(S_i)``
    over the cases ``i`` with the set ``S_i``, ``c(S)`` the share of clean cases on which the
    tool names every effect of ``S``; 95 % percentile bootstrap over both kinds of case.
    """
    if not sub or not clean:
        return {"rate": float("nan"), "lo": float("nan"), "hi": float("nan"), "n": len(sub)}
    hit = np.array([set(_truth(r)) <= set(_found(r, tool)) for r in sub], float)
    named = [set(_found(r, tool)) for r in clean]
    sets = [set(_truth(r)) for r in sub]
    # chance[i, j]: clean case j names every effect of case i's set
    chance = np.array([[s <= f for f in named] for s in sets], float)

    def j_of(i: NDArray[np.int_], k: NDArray[np.int_]) -> float:
        return float(hit[i].mean() - chance[np.ix_(i, k)].mean())

    j = j_of(np.arange(len(sub)), np.arange(len(clean)))
    boots = [j_of(rng.integers(0, len(sub), len(sub)), rng.integers(0, len(clean), len(clean)))
             for _ in range(n_boot)]
    lo, hi = (np.percentile(boots, [2.5, 97.5]) if boots else (float("nan"),) * 2)
    return {"rate": j, "lo": float(lo), "hi": float(hi), "n": len(sub)}


def _tool_summary(rows: list[dict[str, Any]], tool: str, n_boot: int,
                  rng: np.random.Generator) -> dict[str, Any]:
    clean = [r for r in rows if not _truth(r)]
    s: dict[str, Any] = {
        "false_positive": _rate([bool(_found(r, tool)) for r in clean]),
        "exact": _rate([bool(r.get(f"{tool}_exact")) for r in rows]),
        "confusion": _confusion(rows, tool)}
    for kind in ("clean", "single", "pair", "triple"):
        s[f"exact_{kind}"] = _rate([bool(r.get(f"{tool}_exact")) for r in rows
                                    if r["kind"] == kind])
    for gen in _GENERATORS:
        sub = [r for r in rows if r["generator"] == gen]
        s[f"false_positive_{gen}"] = _rate([bool(_found(r, tool)) for r in sub
                                            if not _truth(r)])
        s[f"exact_{gen}"] = _rate([bool(r.get(f"{tool}_exact")) for r in sub])
    # named beside the truth: effects named that were not concealed, per effect case
    extra = [len(set(_found(r, tool)) - set(_truth(r))) for r in rows if _truth(r)]
    s["extra_per_effect_case"] = float(np.mean(extra)) if extra else float("nan")
    for kind in ("pair", "triple"):
        sub = [r for r in rows if r["kind"] == kind]
        s[f"{kind}_all_found"] = _rate([set(_truth(r)) <= set(_found(r, tool)) for r in sub])
        s[f"{kind}_all_found_beyond_chance"] = _all_found_beyond_chance(sub, clean, tool,
                                                                        n_boot, rng)
    mech: dict[str, Any] = {}
    for e in EFFECT_NAMES:
        sub = [r for r in rows if e in _truth(r)]
        if not sub:
            continue
        x = np.array([math.log10(r[f"size_{e}"] / FLOOR[e]) for r in sub])
        hit = np.array([e in _found(r, tool) for r in sub])
        m = detection_curve(x, hit, n_boot, rng)
        m["detection"] = _rate(list(hit))
        m["false_positive_clean"] = fp = _rate([e in _found(r, tool) for r in clean])
        j, j_lo, j_hi = newcombe_difference(int(hit.sum()), len(hit), fp["k"], fp["n"])
        m["informedness"] = {"rate": j, "lo": j_lo, "hi": j_hi}
        errs = np.array([r.get(f"{tool}_err_{e}", np.nan) for r in sub], float)
        ok = hit & np.isfinite(errs)
        m["param_error_median"] = float(np.median(errs[ok])) if ok.any() else float("nan")
        m["param_error_n"] = int(ok.sum())
        bins = np.linspace(-1.0, 1.0, 7)
        m["param_error_by_size"] = [
            {"x_lo": float(lo), "x_hi": float(hi), "n": int((ok & (x >= lo) & (x < hi)).sum()),
             "median": (float(np.median(errs[ok & (x >= lo) & (x < hi)]))
                        if (ok & (x >= lo) & (x < hi)).any() else None)}
            for lo, hi in itertools.pairwise(bins)]
        mech[e] = m
    s["mechanisms"] = mech
    return s


def summarise(rows: list[dict[str, Any]], n_boot: int = 400, seed: int = 0) -> dict[str, Any]:
    """Both tools' statistics over the scored cases (module docstring)."""
    scored = [r for r in rows if r.get("status") == "ok"]
    status: dict[str, int] = {}
    for r in rows:
        key = str(r.get("status", "?"))
        if key.startswith(("simulation failed", "diagnosis failed")):
            key = key.split(":", 1)[0]
        status[key] = status.get(key, 0) + 1
    rng = np.random.default_rng(seed)
    out: dict[str, Any] = {
        "records": len(rows), "scored": len(scored), "status": status,
        "clean_scored": sum(1 for r in scored if not _truth(r)),
        "by_generator": {g: sum(1 for r in scored if r["generator"] == g)
                         for g in _GENERATORS},
        "by_kind": {k: sum(1 for r in scored if r["kind"] == k)
                    for k in ("clean", "single", "pair", "triple")},
        "by_writer": {w: sum(1 for r in scored if r["writer"] == w) for w in ("rig_log", "bag")},
        "floor": FLOOR, "bootstrap": n_boot,
        "tools": {t: _tool_summary(scored, t, n_boot, rng) for t in TOOLS}}
    for t in TOOLS:
        times = [r.get(f"t_{t}") for r in scored if r.get(f"t_{t}") is not None]
        out["tools"][t]["median_time_s"] = float(np.median(times)) if times else float("nan")
    sims = [r["t_sim"] for r in rows if r.get("t_sim") is not None]
    out["median_sim_s"] = float(np.median(sims)) if sims else float("nan")
    return out


def _size_text(e: str, m: dict[str, Any], key: str) -> str:
    """A 50 %/90 % size with its interval, censored to the drawn range."""
    def fmt(x: float) -> str:
        if math.isnan(x):
            return "n/a"
        if x > 1.0:
            return "> 10 F"
        if x < -1.0:
            return "< 0.1 F"
        return f"{FLOOR[e] * 10 ** x:.2g}"

    return f"{fmt(m[key])} [{fmt(m[key + '_lo'])}, {fmt(m[key + '_hi'])}]"


def _pct(r: dict[str, Any]) -> str:
    if not r["n"]:
        return "n/a"
    return f"{100 * r['rate']:.0f} % [{100 * r['lo']:.0f}, {100 * r['hi']:.0f}] (n={r['n']})"


def report_markdown(summary: dict[str, Any]) -> str:
    """The side-by-side tables of ``report.md`` (and the README's)."""
    b, p = summary["tools"]["bfr"], summary["tools"]["peer"]
    lines = [f"{summary['scored']} scored cases of {summary['records']} "
             f"({summary['clean_scored']} clean; truth: rigid model "
             f"{summary['by_generator']['rigid']}, contact model "
             f"{summary['by_generator']['contact']}, node suite "
             f"{summary['by_generator']['nodes']}; rig logs "
             f"{summary['by_writer']['rig_log']}, bags {summary['by_writer']['bag']}); "
             "not scored: " + (", ".join(f"{v} {k}" for k, v in summary["status"].items()
                                          if k != "ok") or "none") + ".", "",
             "| figure | bfr diagnose | PySINDy peer |", "| --- | --- | --- |"]
    rows = [("false positives on clean cases", "false_positive"),
            ("... rigid truth", "false_positive_rigid"),
            ("... contact-model truth", "false_positive_contact"),
            ("... node-suite truth (bags)", "false_positive_nodes"),
            ("exact set, all cases", "exact"), ("exact set, single effects", "exact_single"),
            ("pairs found as pairs (exact)", "exact_pair"),
            ("triples found as triples (exact)", "exact_triple"),
            ("pairs: both found", "pair_all_found"), ("triples: all found", "triple_all_found"),
            ("exact set, rigid truth", "exact_rigid"),
            ("exact set, contact-model truth", "exact_contact"),
            ("exact set, node-suite truth (bags)", "exact_nodes")]
    for label, key in rows:
        lines.append(f"| {label} | {_pct(b[key])} | {_pct(p[key])} |")
        if key.endswith("_all_found"):
            lines.append(f"| ... beyond chance (J: minus naming them all on a clean case) | "
                         f"{_diff(b[key + '_beyond_chance'])} | "
                         f"{_diff(p[key + '_beyond_chance'])} |")
    lines.append(f"| effects named beside the truth, per effect case | "
                 f"{b['extra_per_effect_case']:.2f} | {p['extra_per_effect_case']:.2f} |")
    lines += ["", "Per mechanism (F = the effect's reference size FLOOR = 10 x its reporting "
              "floor; sizes drawn log-uniform in [0.1, 10] F; intervals: bootstrap 95 %):", "",
              "| mechanism | F | bfr: found | bfr: 50 % size | bfr: 90 % size | "
              "bfr: param err | peer: found | peer: 50 % size | peer: 90 % size | "
              "peer: param err | peer: named on clean |",
              "| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |"]
    for e in EFFECT_NAMES:
        if e not in b["mechanisms"]:
            continue
        mb, mp = b["mechanisms"][e], p["mechanisms"][e]

        def pe(m: dict[str, Any]) -> str:
            return "n/a" if not m["param_error_n"] else f"{100 * m['param_error_median']:.0f} %"

        lines.append(
            f"| {e} | {FLOOR[e]:.2g} | {mb['hits']}/{mb['n']} | {_size_text(e, mb, 'x50')} | "
            f"{_size_text(e, mb, 'x90')} | {pe(mb)} | {mp['hits']}/{mp['n']} | "
            f"{_size_text(e, mp, 'x50')} | {_size_text(e, mp, 'x90')} | {pe(mp)} | "
            f"{_pct(mp['false_positive_clean'])} |")
    lines += ["", "Per mechanism, detection beyond chance (informedness J = found rate minus the "
              "rate the tool names the mechanism on clean cases; Newcombe 95 % intervals; a "
              "tool that names a mechanism on every case has J = 0):", "",
              "| mechanism | bfr: found | bfr: named on clean | bfr: J | peer: found | "
              "peer: named on clean | peer: J |", "| --- | --- | --- | --- | --- | --- | --- |"]
    for e in EFFECT_NAMES:
        if e not in b["mechanisms"]:
            continue
        mb, mp = b["mechanisms"][e], p["mechanisms"][e]
        lines.append(
            f"| {e} | {_pct(mb['detection'])} | {_pct(mb['false_positive_clean'])} | "
            f"{_diff(mb['informedness'])} | {_pct(mp['detection'])} | "
            f"{_pct(mp['false_positive_clean'])} | {_diff(mp['informedness'])} |")
    return "\n".join(lines)


def _diff(r: dict[str, Any]) -> str:
    """A difference of proportions in percentage points with its interval."""
    if math.isnan(r["rate"]):
        return "n/a"
    return f"{100 * r['rate']:+.0f} [{100 * r['lo']:+.0f}, {100 * r['hi']:+.0f}]"


def write_table(out: Path, rows: list[dict[str, Any]]) -> list[Path]:
    """The per-case table: Parquet (pyarrow) and CSV, one row per case, every column."""
    import csv  # noqa: PLC0415 - only for the table

    cols: list[str] = []
    for r in rows:
        cols += [k for k in r if k not in cols]
    files = []
    try:
        import pyarrow as pa  # noqa: PLC0415 - optional dependency (Parquet)
        import pyarrow.parquet as pq  # noqa: PLC0415 - optional dependency (Parquet)
    except ImportError:
        pa = None
    if pa is not None:
        table = pa.Table.from_pylist([{c: r.get(c) for c in cols} for r in rows])
        pq.write_table(table, out / "table.parquet")
        files.append(out / "table.parquet")
    with (out / "table.csv").open("w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=cols)
        w.writeheader()
        for r in rows:
            w.writerow({c: r.get(c, "") for c in cols})
    files.append(out / "table.csv")
    return files


def write_report(out: Path, rows: list[dict[str, Any]], summary: dict[str, Any],
                 figs: list[Path] | None = None) -> list[Path]:
    """table.parquet/.csv, summary.json and report.md (showing ``figs``); the files written."""
    files = write_table(out, rows)
    (out / "summary.json").write_text(json.dumps(summary, indent=1, default=float))
    files.append(out / "summary.json")
    figs = list(figs or [])
    md = ["# Detection limits: bfr diagnose beside PySINDy", "", report_markdown(summary), ""]
    md += [f"![{f.stem}]({f.name})" for f in figs]
    (out / "report.md").write_text("\n".join(md) + "\n")
    files.append(out / "report.md")
    return files
