"""Two limits runs' case tables side by side on the cases both scored (model truth only).

Usage: ``python compare_runs.py OLD/table.csv NEW/table.csv`` (the ``table.csv`` that
``bfr limits report`` writes). Prints the false positives on clean cases, the exact sets with
the cases gained and lost (exact two-sided McNemar test), and per mechanism bfr's found
count and detection beyond chance J (found rate minus the rate it names the mechanism on
clean cases), each for both runs.
"""

from __future__ import annotations

import csv
import math
import sys


def _load(path: str) -> dict[int, dict[str, str]]:
    with open(path, newline="") as fh:
        rows = [r for r in csv.DictReader(fh)
                if r["generator"] != "nodes" and r["status"] == "ok"]
    return {int(r["index"]): r for r in rows}


def _true(x: str) -> bool:
    return x in ("True", "true", "1")


def _sized(r: dict[str, str], m: str) -> bool:
    return r.get("size_" + m) not in ("", "0", "0.0", "nan", None)


def main(argv: list[str]) -> int:
    """Print the comparison (module docstring)."""
    a, b = _load(argv[0]), _load(argv[1])
    common = sorted(set(a) & set(b))
    print(f"scored: old {len(a)}, new {len(b)}, both {len(common)}")
    for name, run in (("old", a), ("new", b)):
        clean = [run[i] for i in common if run[i]["n_effects"] == "0"]
        fp = sum(1 for r in clean if r["bfr_found"])
        exact = sum(_true(run[i]["bfr_exact"]) for i in common)
        print(f"{name}: false positives {fp}/{len(clean)}; exact {exact}/{len(common)}")
    gained = sum(1 for i in common if _true(b[i]["bfr_exact"]) and not _true(a[i]["bfr_exact"]))
    lost = sum(1 for i in common if _true(a[i]["bfr_exact"]) and not _true(b[i]["bfr_exact"]))
    n = gained + lost
    p = (min(1.0, 2.0 * sum(math.comb(n, j) for j in range(min(gained, lost) + 1)) / 2 ** n)
         if n else 1.0)
    print(f"exact sets gained {gained}, lost {lost}, McNemar p = {p:.2f}")
    mechs = sorted(c[len("bfr_hit_"):] for c in next(iter(b.values())) if c.startswith("bfr_hit_"))
    for m in mechs:
        out = []
        for run in (a, b):
            eff = [run[i] for i in common if _sized(run[i], m)]
            clean = [run[i] for i in common if run[i]["n_effects"] == "0"]
            found = sum(_true(r["bfr_hit_" + m]) for r in eff)
            named = sum(1 for r in clean if m in r["bfr_found"].split(";"))
            j = 100.0 * (found / len(eff) - named / len(clean)) if eff and clean else math.nan
            out.append(f"{found}/{len(eff)} J {j:+.0f}")
        print(f"{m:24s} old {out[0]:16s} new {out[1]}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
