"""The simulator CSV format: round trips and clear errors."""

from __future__ import annotations

from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
from bfr_model.io.csv_io import CSV_COLUMNS, CsvFormatError, read_csv, write_csv
from bfr_model.recording import Recording


def rig_like(n: int = 300) -> Recording:
    t = 4.0 + np.arange(n) * 1.1e-3
    theta = 0.3 * np.sin(3 * t)
    held = (np.arange(n) // 6) * 6
    valid = np.ones(n, bool)
    valid[50:80] = False
    bx, by = 0.01 * np.cos(t[held]), 0.085 + 0.001 * np.sin(t[held])
    return Recording(t=t, theta=theta, theta_dot=0.9 * np.cos(3 * t), torque=np.full(n, 0.02),
                     ball_x=bx, ball_y=by, ball_valid=valid,
                     phi=theta[held] + np.arctan2(bx, by), phi_dot=np.full(n, 0.5),
                     extra={"phi_rig": np.linspace(0, 1, n)},
                     meta={"source": "x.txt", "source_kind": "ntnu_rig_log",
                           "conversions": ["none"], "rig_conventions": {"theta_sign": 1}})


def sim_like(n: int = 200) -> Recording:
    t = np.arange(n) * 1e-3
    theta, phi_c = 0.5 * t, 0.1 + 2.0 * t
    ang = phi_c - theta + 0.005
    ball = 0.1 * np.c_[np.sin(ang), np.cos(ang)]
    x = np.c_[theta, phi_c, np.full(n, 0.5), np.full(n, 2.0), np.zeros(n), np.zeros(n)]
    return Recording.from_sim(SimpleNamespace(t=t, x=x, u=np.zeros(n), ball=ball,
                                              kinetic=np.full(n, 1e-3),
                                              potential=np.full(n, 2e-3), info={}))


def test_round_trip_rig_like(tmp_path: Path) -> None:
    rec = rig_like()
    path = tmp_path / "r.csv"
    write_csv(path, rec)
    back = read_csv(path)
    assert rec.differences(back, rtol=0, atol=0) == []
    assert back.meta["rig_conventions"] == {"theta_sign": 1}
    assert back.meta["source"] == str(path)
    assert back.meta["csv_phi_kind"] == "ball_centre"
    header = next(ln for ln in path.read_text().splitlines() if not ln.startswith("#"))
    assert header.split(",")[:11] == list(CSV_COLUMNS)


def test_round_trip_simulation_with_truth(tmp_path: Path) -> None:
    rec = sim_like()
    path = tmp_path / "s.csv"
    write_csv(path, rec)
    back = read_csv(path)
    assert rec.differences(back, rtol=0, atol=0) == []
    # the phi column holds the contact-point state
    lines = [ln for ln in path.read_text().splitlines() if not ln.startswith("#")]
    header = lines[0].split(",")
    table = np.loadtxt(lines[1:], delimiter=",")
    assert np.array_equal(table[:, header.index("phi")], rec.phi_true)


def test_reads_simulator_format_without_extras(tmp_path: Path) -> None:
    """The bare documented format, as bfr simulate writes it (%.12g, no comments)."""
    rec = sim_like()
    data = np.column_stack([rec.t, rec.theta, rec.theta_dot, rec.phi_true, rec.phi_dot_true,
                            rec.ball_x, rec.ball_y, rec.torque, rec.kinetic, rec.potential,
                            rec.energy])
    path = tmp_path / "sim.csv"
    np.savetxt(path, data, delimiter=",", header=",".join(CSV_COLUMNS), comments="",
               fmt="%.12g")
    back = read_csv(path)
    assert np.allclose(back.phi_true, rec.phi_true)
    assert np.allclose(back.phi, rec.phi, atol=1e-9)  # ball-centre angle recomputed
    assert back.ball_valid.all() and back.has_truth
    assert np.allclose(back.energy, 3e-3)


def write_text(tmp_path: Path, text: str) -> Path:
    p = tmp_path / "bad.csv"
    p.write_text(text)
    return p


HEADER = "t,theta,theta_dot,phi,phi_dot,ball_x,ball_y,torque"


@pytest.mark.parametrize(("text", "message"), [
    ("", "no header row"),
    ("# only: comments\n", "no header row"),
    ("t,theta,phi\n0,0,0\n", r"missing required column\(s\) \['theta_dot', 'phi_dot'"),
    (HEADER + "\n", "no data rows"),
    (HEADER + ",t\n", "duplicate column"),
    (HEADER + "\nnan,0,0,0,0,0,0,0\n", r"bad.csv: no row passed the checks: .*1 non_finite"),
])
def test_errors(tmp_path: Path, text: str, message: str) -> None:
    with pytest.raises(CsvFormatError, match=message):
        read_csv(write_text(tmp_path, text))


GOOD = "0,0,0,0,0,0,0,0\n0.1,0,0,0,0,0,0,0\n0.2,0,0,0,0,0,0,0\n"


@pytest.mark.parametrize(("text", "cause", "line"), [
    (HEADER + "\n" + GOOD + "0.3,0,0,abc,0,0,0,0\n", "corrupt", 5),
    (HEADER + "\n" + GOOD + "0.3,0,0,0", "truncated", 5),
    (HEADER + "\n" + GOOD + "0.3,0,0,0,0,0,0,0,9\n", "corrupt", 5),
    (HEADER + "\n" + GOOD + "0.2,0,0,0,0,0,0,0\n", "duplicate", 5),
    (HEADER + "\n" + GOOD + "0.1,0,0,0,0,0,0,0\n0.4,0,0,0,0,0,0,0\n", "out_of_order", 5),
    (HEADER + "\n" + GOOD + "nan,0,0,0,0,0,0,0\n", "non_finite", 5),
    (HEADER + "\n" + GOOD + "0.3,1e9,0,0,0,0,0,0\n", "out_of_range", 5),
])
def test_bad_rows_are_accounted(tmp_path: Path, text: str, cause: str, line: int) -> None:
    """A bad row is left out and counted by cause, naming its line; the rest is read."""
    rec = read_csv(write_text(tmp_path, text))
    acc = rec.meta["read_account"]
    assert acc["samples_used"] == len(rec) == acc["samples_present"] - 1
    assert acc["dropped"] == {cause: 1}
    assert any(a.startswith(cause) and f"line {line}" in a for a in acc["actions"])


def test_extra_prefix_is_removed_only_where_written(tmp_path: Path) -> None:
    """``extra_x`` is ``x`` unless a column ``x`` exists (no silent collision)."""
    rec = read_csv(write_text(tmp_path, HEADER + ",extra_a,extra_t,b\n" + "".join(
        f"{0.1 * k},0,0,0,0,0,0,0,1,2,3\n" for k in range(3))))
    assert sorted(rec.extra) == ["a", "b", "extra_t"]


def test_string_conversions_meta_stays_one_entry(tmp_path: Path) -> None:
    rec = read_csv(write_text(tmp_path, '# conversions: "one step"\n' + HEADER + "\n" + GOOD))
    assert rec.meta["conversions"][0] == "one step"


def test_missing_file(tmp_path: Path) -> None:
    with pytest.raises(CsvFormatError, match="cannot read"):
        read_csv(tmp_path / "nope.csv")
