"""``bfr bench``: the command runs and reports every figure with its budget and met flag.

No assertion on the speed values themselves: speed lives in the bench, not in tests
(DEVELOPERS.md). The bench runs as a subprocess of this interpreter (the workspace's
environment), in quick mode, for the in-process sections.
"""

from __future__ import annotations

import json
import math
import subprocess
import sys

import pytest
from bfr_tools.bench import camera as bench_camera
from bfr_tools.bench import sim as bench_sim
from bfr_tools.bench.common import Budget, Figure, FigureSpec, fmt_value, not_measured
from bfr_tools.cli import SUBCOMMANDS

from bfr_tools import bench


@pytest.fixture(scope="module")
def quick_result() -> dict:
    """``bfr bench --quick --json --only sim,camera`` run once for the module."""
    proc = subprocess.run(
        [sys.executable, "-m", "bfr_tools.cli", "bench", "--quick", "--json", "--only",
         "sim,camera"], capture_output=True, text=True, timeout=300, check=False)
    assert proc.returncode == 0, proc.stderr[-3000:]
    assert "[bench" in proc.stderr  # progress lines go to stderr
    return json.loads(proc.stdout)


def test_quick_json_reports_every_figure_with_budget_and_met(quick_result: dict) -> None:
    figs = quick_result["figures"]
    keys = [f["key"] for f in figs]
    assert keys == [s.key for s in bench_sim.SPECS + bench_camera.SPECS]
    for f in figs:
        assert set(f) >= {"key", "label", "unit", "median", "min", "max", "budget", "met",
                          "status", "note"}
        if f["status"] == "measured":
            assert f["min"] <= f["median"] <= f["max"]
            assert all(math.isfinite(v) for v in f["values"])
        else:
            assert f["status"].startswith("not measured: ") and f["median"] is None
        if f["budget"] is not None:
            assert f["budget"]["op"] in (">=", "<", "==", "<=", ">")
            assert f["budget"]["text"]
            assert f["met"] in ((True, False) if f["status"] == "measured" else (None,))
        else:
            assert f["met"] is None
    by_key = {f["key"]: f for f in figs}
    # the budgets of these sections are all present
    assert by_key["sim.rigid_rtf_chunked"]["budget"]["value"] == 50.0
    assert by_key["sim.rigid_rtf_node"]["budget"]["value"] == 50.0
    assert by_key["sim.contact_rtf_bumps"]["budget"]["value"] == 2.0
    assert by_key["camera.detect_ms_roi"]["budget"] == {
        "op": "<", "value": 1.0, "text": "< 1 ms", "source": "issue 9"}
    # the rigid model and the camera always measure (the contact model may lack a row visit)
    for key in ("sim.rigid_rtf_chunked", "sim.rigid_rtf_rk45_chunked",
                "sim.rigid_ratio_dop853_chunked", "camera.render_ms", "camera.detect_ms_roi"):
        assert by_key[key]["status"] == "measured", by_key[key]
    b = quick_result["budgets"]
    assert b["total"] == sum(f["budget"] is not None for f in figs)
    assert b["met"] + len(b["missed"]) + len(b["not_measured"]) == b["total"]


def test_quick_json_has_machine_info(quick_result: dict) -> None:
    m = quick_result["machine"]
    assert m["cores"] >= 1
    assert len(m["load_average_start"]) == 3 and len(m["load_average_end"]) == 3
    assert m["versions"]["python"] and m["versions"]["numpy"]
    assert quick_result["options"]["sections"] == ["sim", "camera"]


def test_table_lists_figures_and_budgets(quick_result: dict) -> None:
    text = bench.format_table(quick_result)
    assert "budget" in text and "met" in text and "load average" in text
    for f in quick_result["figures"]:
        assert f["label"][:40] in text
    assert "budgets:" in text


def test_figure_statistics_and_budget() -> None:
    spec = FigureSpec("x.rate", "a rate", "x", Budget(">=", 50.0))
    f = Figure(spec, [40.0, 60.0, 80.0])
    assert (f.minimum, f.median, f.maximum) == (40.0, 60.0, 80.0)
    assert f.met is True
    assert Figure(spec, [10.0, 20.0, 90.0]).met is False
    missing = not_measured(spec, "node suite missing")
    assert missing.met is None and missing.median is None
    assert missing.to_json()["status"] == "not measured: node suite missing"
    assert Figure(FigureSpec("y", "no budget", "ms"), [1.0]).met is None
    assert fmt_value(512.3, "x") == "512 x" and fmt_value(0.5, "ms") == "0.5 ms"
    assert bench.json_safe({"a": [float("nan"), 1.0], "b": math.inf}) == {"a": [None, 1.0],
                                                                          "b": None}


def test_help_and_bad_arguments() -> None:
    with pytest.raises(SystemExit) as exc:
        bench.main(["--help"])
    assert exc.value.code == 0
    with pytest.raises(SystemExit) as exc:
        bench.main(["--only", "nonsense"])
    assert exc.value.code == 2
    with pytest.raises(SystemExit) as exc:
        bench.main(["--repeats", "0"])
    assert exc.value.code == 2


def test_registered_in_cli() -> None:
    assert SUBCOMMANDS["bench"][:2] == ("bfr_tools.bench", "main")
