"""Parser of the NTNU rig terminal logs: synthetic malformed input and every shipped log."""

from __future__ import annotations

import os
import re
from pathlib import Path

import numpy as np
import pytest
from bfr_model.io.rig_log import (
    RigLogError,
    RigLogWarning,
    parse_rig_log,
    parse_rig_log_text,
    read_rig_log,
)
from bfr_model.recording import Recording

DATA = Path(os.environ.get("BFR_RIG_DATA", Path(__file__).resolve().parents[1].parent
                           / "shared" / "data" / "ntnu-rig"))
needs_data = pytest.mark.skipif(not DATA.is_dir(),
                                reason=f"NTNU rig logs not found at {DATA} (CI has ../shared "
                                       f"beside the clone; set BFR_RIG_DATA to override)")


def line(t: float, theta: float = 1.0, x: float = 0.01, y: float = 0.08, **kw: float) -> str:
    v = {"t": t, "torque": 0.01, "theta": theta, "phi": theta + np.arctan2(x, y), "dtheta": 0.5,
         "dphi": 0.4, "x": x, "y": y, **kw}
    return "[inf] " + ",".join(f"{k}={v[k]:g}" if isinstance(v[k], float) else f"{k}={v[k]}"
                               for k in ("t", "torque", "theta", "phi", "dtheta", "dphi", "x",
                                         "y")) + "\r"


def body(n: int = 20, t0: float = 4.0) -> list[str]:
    return [line(t0 + 0.001 * i, theta=1.0 + 0.002 * i, x=0.01 + 0.001 * (i // 5))
            for i in range(n)]


NOISE = [
    "Script started on fre 26 mar 2021 12:12:54",
    "\x1b]0;butterfly@nuc: ~\x07\x1b[01;32mbutterfly@nuc\x1b[00m:\x1b[01;34m~\x1b[00m$ ./o\r"
    "verturn.sh\r",
    "[ 13%] Built target cppmisc\r",
    "[inf] initializing hardware..\r",
    "[inf] done\r",
]


def test_clean_log_with_noise() -> None:
    text = "\n".join([*NOISE, *body(), "[obs] z=1,w=2\r", "", "[inf] stopped\r"]) + "\n"
    log = parse_rig_log_text(text, "mem")
    assert log.n_data == 20 and len(log.runs) == 1
    assert log.skipped == {"terminal": 3, "info": 3, "obs": 1, "empty": 1}
    assert log.warnings == []
    rec = log.recording()
    assert len(rec) == 20
    assert rec.meta["source_kind"] == "ntnu_rig_log" and rec.meta["skipped"] == log.skipped
    assert np.all(np.diff(rec.t) > 0)


def test_data_line_behind_escape_codes_and_carriage_return_is_recovered() -> None:
    rows = body(5)
    rows[2] = "\x1b[K\x1b[A\rgarbage typed\r" + rows[2]
    log = parse_rig_log_text("\n".join(rows) + "\n")
    assert log.n_data == 5 and log.skipped == {}


def test_truncated_final_line_is_a_warning() -> None:
    text = "\n".join(body(10)) + "\n[inf] t=4.0101,torque=0.01,theta=1.0"
    log = parse_rig_log_text(text, "mem")
    assert log.n_data == 10
    assert log.skipped == {"truncated_final": 1}
    assert log.warnings and "mem:11: truncated final line" in log.warnings[0]


def test_truncated_final_line_warns_from_file(tmp_path: Path) -> None:
    p = tmp_path / "log.txt"
    p.write_text("\n".join(body(10)) + "\n[inf] t=4.01")
    with pytest.warns(RigLogWarning, match="log.txt:11: truncated final line"):
        rec = read_rig_log(p)
    assert len(rec) == 10


@pytest.mark.parametrize("end", ["\r", "\n", "\r\n"])
def test_cr_lf_and_crlf_line_ends_read_alike(tmp_path: Path, end: str) -> None:
    """A log with CR-only line ends (old Mac style) reads as its LF and CRLF twins: no
    'truncated final line', every sample, the same account; the CR read is said."""
    noise = [n for n in NOISE if "\r" not in n.rstrip("\r")]  # no terminal overwrite
    rows = [r.rstrip("\r") for r in [*noise, *body(30), "[inf] stopped"]]
    text = end.join(rows) + end
    p = tmp_path / "log.txt"
    p.write_bytes(text.encode())
    for log in (parse_rig_log(p), parse_rig_log_text(text, str(p))):
        assert log.warnings == [] and log.n_data == 30 and log.n_lines == len(rows)
        assert log.skipped == {"terminal": 2, "info": 3}
        rec = log.recording()
        assert rec.n == 30 and rec.meta["read_account"]["dropped"] == {}
        said = [c for c in rec.meta["conversions"] if "carriage return" in c]
        assert bool(said) == (end == "\r"), rec.meta["conversions"]


def test_data_lines_joined_by_a_carriage_return_are_each_read() -> None:
    """Two data lines joined by CR (an LF lost, or CR line ends inside an LF file): a
    terminal's overwrite had shown the second only, and the first was lost uncounted."""
    rows = body(10)
    rows[4:6] = [rows[4] + "\x0b" + rows[5]]  # the LF after line 5 became a VT
    log = parse_rig_log_text("\n".join(rows) + "\n", "mem")
    assert log.n_data == 10 and log.runs[0].account.samples_used == 10


def test_partial_line_mid_file_is_skipped_with_warning() -> None:
    rows = body(10)
    rows.insert(5, "[inf] t=4.0045,torque=0.0")
    log = parse_rig_log_text("\n".join(rows) + "\n", "mem")
    assert log.n_data == 10 and log.skipped == {"partial": 1}
    assert "mem:6: partial data line" in log.warnings[0]


def test_two_runs_split_at_restart_marker() -> None:
    text = "\n".join([*NOISE, *body(10), "[inf] stopped\r", *NOISE[3:], *body(30, t0=4.0)])
    log = parse_rig_log_text(text + "\n")
    assert [len(r) for r in log.runs] == [10, 30]
    assert len(log.recording()) == 30  # default: the longest run
    assert len(log.recording(run=0)) == 10
    assert log.recording(run=-1).meta["run"] == 1
    with pytest.raises(RigLogError, match="run 5 requested but the log holds 2"):
        log.recording(run=5)


def test_duplicate_timestamps_dropped_or_rejected() -> None:
    rows = body(10)
    rows[4] = line(4.003, theta=9.0)  # same t as row 3, different data (print rounding)
    log = parse_rig_log_text("\n".join(rows) + "\n", "mem")
    assert log.skipped == {"duplicate_time": 1} and len(log.runs[0]) == 9
    with pytest.raises(RigLogError, match=r"mem:5: duplicate timestamp t=4.003 \(same as line 4"):
        parse_rig_log_text("\n".join(rows) + "\n", "mem", duplicates="error")


def test_ball_lost_event_invalidates_held_fix() -> None:
    rows = body(40)
    rows.insert(22, "[inf] ball was lost\r")
    rec = parse_rig_log_text("\n".join(rows) + "\n").recording()
    assert rec.ball_valid[:22].all()
    # held fix invalid after the message until the next new fix (x changes every 5 samples)
    assert not rec.ball_valid[22:25].any() and rec.ball_valid[25:].all()


def test_no_ball_and_stale_fix_are_invalid() -> None:
    rows = [line(4.0 + 0.001 * i, x=0.0, y=0.0) for i in range(50)]
    rows += [line(4.05 + 0.001 * i, x=0.02, y=0.08) for i in range(200)]  # one fix, held
    rec = parse_rig_log_text("\n".join(rows) + "\n").recording(stale_after=0.1)
    assert not rec.ball_valid[:50].any()
    assert rec.ball_valid[50:150].all() and not rec.ball_valid[152:].any()
    assert rec.camera_fix_rate() != rec.camera_fix_rate()  # NaN: a single fix


@pytest.mark.parametrize(("text", "message"), [
    ("", "file is empty"),
    ("   \n\r\n", "file is empty"),
    ("\n".join(NOISE) + "\n", r"no data lines .* skipped info: 2, terminal: 3"),
])
def test_malformed_input_errors(text: str, message: str) -> None:
    with pytest.raises(RigLogError, match=message):
        parse_rig_log_text(text, "mem")


@pytest.mark.parametrize(("text", "cause", "count", "warning"), [
    ("\n".join([*body(3), "[inf] t=4.1,torque=0.01,theta=1,dtheta=0,dphi=0,x=0,y=0",
                *body(3, 4.2)]), "corrupt", 1, r"mem:4: malformed data line skipped: missing "
                                                r"key\(s\) 'phi'"),
    ("\n".join([*body(3), line(4.1, theta=float("nan")), *body(3, 4.2)]), "non_finite", 1,
     None),
    ("\n".join([*body(3), line(4.1, dtheta=float("inf")), *body(3, 4.2)]), "non_finite", 1,
     None),
    ("\n".join([*body(3), line(4.1).replace("theta=1", "theta=1.0.2"), *body(3, 4.2)]),
     "corrupt", 1, r"mem:4: value of 'theta' is not a number: '1.0.2'"),
    ("\n".join([*body(5), *body(5, 3.0)]), "out_of_order", 5, None),
    ("\n".join([*body(3), line(4.1).replace("dphi=", "dpsi="), *body(3, 4.2)]), "corrupt", 1,
     r"mem:4: malformed data line skipped: missing key\(s\) 'dphi'"),
    ("\n".join([*body(3), line(4.1, theta=1e9), *body(3, 4.2)]), "out_of_range", 1, None),
])
def test_bad_lines_are_accounted(text: str, cause: str, count: int,
                                 warning: str | None) -> None:
    """A bad data line is left out, counted by cause and named; the rest is read."""
    log = parse_rig_log_text(text, "mem")
    acc = log.runs[0].account
    assert dict(acc.dropped) == {cause: count}
    assert acc.samples_present == acc.samples_used + count == log.recording().n + count
    line_no = 4 if cause != "out_of_order" else 6
    assert any(a.startswith(cause) and f"line {line_no}" in a for a in acc.actions)
    if warning is not None:
        assert any(re.search(warning, w) for w in log.warnings)


@pytest.mark.parametrize(("bad", "found", "what"), [
    (line(4.1).replace("\r", ",z=3\r"), 9, "unknown key(s) 'z'"),
    (line(4.1).replace(",dphi=0.4", ""), 7, "missing key(s) 'dphi'"),
    (line(4.1).replace("\r", ",x=0.02\r"), 9, "keys out of order or repeated"),
])
def test_extra_or_missing_field_names_the_counts_and_the_line(bad: str, found: int,
                                                              what: str) -> None:
    """A line with a field too many or too few says how many were expected and found, and
    where: in the warning and in the account's action."""
    log = parse_rig_log_text("\n".join([*body(3), bad, *body(3, 4.2)]) + "\n", "mem")
    expect = f"{found} field(s) found where 8 expected"
    assert any(w.startswith("mem:4: malformed data line skipped: ") and what in w
               and expect in w for w in log.warnings), log.warnings
    (action,) = log.runs[0].account.actions
    assert action.startswith("corrupt: 1 line(s) skipped, first at line 4 (malformed: ")
    assert expect in action and what in action


def test_seconds_used_never_exceed_seconds_present_with_duplicated_stamps() -> None:
    """Lines 2 and 1 ms apart, every other stamp repeated, and one 4 ms pause: the repeats
    halve the present samples' median interval, and a hole limit from each set alone had
    counted the pause as covered by the used samples only (used > present by 4 ms)."""
    t, rows = 4.0, []
    for i in range(200):
        t += 0.004 if i == 100 else (0.002 if i % 2 else 0.001)
        rows.append(line(round(t, 4), theta=1.0 + 0.002 * i))
        if i % 2:
            rows.append(rows[-1])  # the stamp repeated (a second loop step in one quantum)
    acc = parse_rig_log_text("\n".join(rows) + "\n", "mem").runs[0].account
    assert dict(acc.dropped) == {"duplicate": 100} and acc.samples_used == 200
    assert acc.seconds_used <= acc.seconds_present
    assert acc.seconds_used == pytest.approx(acc.seconds_present, abs=1e-9)  # no time lost


@pytest.mark.parametrize("x", [1e300, float("inf")])
def test_ball_off_the_frame_is_excluded_not_dropped(x: float) -> None:
    rows = body(20)
    rows[7] = line(4.007, theta=1.014, x=x, y=0.08)
    rec = parse_rig_log_text("\n".join(rows) + "\n", "mem").recording()
    acc = rec.meta["read_account"]
    assert acc["samples_used"] == 20 and acc["degraded"] == {"ball_off_frame": 1}
    assert not rec.ball_valid[7] and rec.ball_valid[8:].all()


def test_events_after_a_restart_marker_belong_to_the_next_run() -> None:
    text = "\n".join([*body(10), "[inf] initializing hardware..", "[inf] ball was lost",
                      *body(10, 1.0)]) + "\n"
    log = parse_rig_log_text(text, "mem")
    assert len(log.runs) == 2
    assert log.runs[0].events == [] and log.runs[1].events == [(0, "ball was lost")]


def test_missing_file(tmp_path: Path) -> None:
    with pytest.raises(RigLogError, match="cannot read"):
        parse_rig_log(tmp_path / "none.txt")


# -- the shipped logs -----------------------------------------------------------------------
#: file -> (lines, data lines, runs, skipped counts, camera fix rate [Hz] or None)
EXPECTED = {
    "Actually_worked": (28692, 28686, 1, {"terminal": 3, "info": 2, "truncated_final": 1,
                                          "duplicate_time": 35}, 165.0),
    "fin": (19977, 19974, 1, {"empty": 2, "truncated_final": 1, "duplicate_time": 33}, 165.0),
    "friction_v_ref_1": (41450, 41423, 1, {"terminal": 24, "info": 2, "truncated_final": 1,
                                           "duplicate_time": 17}, None),
    "sin_wave_001_5_ball_center": (36771, 36764, 1, {"terminal": 3, "info": 3,
                                                     "truncated_final": 1,
                                                     "duplicate_time": 19}, None),
    "step_response_tau_001": (27674, 27626, 6, {"terminal": 30, "info": 17,
                                                "truncated_final": 1}, None),
}


@needs_data
@pytest.mark.parametrize("name", sorted(EXPECTED))
def test_shipped_log(name: str) -> None:
    n_lines, n_data, n_runs, skipped, cam = EXPECTED[name]
    log = parse_rig_log(DATA / f"{name}.txt", warn=False)
    assert (log.n_lines, log.n_data, len(log.runs)) == (n_lines, n_data, n_runs)
    assert log.skipped == skipped
    assert len(log.warnings) == 1 and "truncated final line" in log.warnings[0]
    rec = log.recording()
    assert np.all(np.diff(rec.t) > 0)
    mean_rate = (len(rec) - 1) / rec.duration
    assert 915.0 < mean_rate < 928.0  # the control loop, ~921 Hz
    assert abs(np.max(np.abs(rec.torque)) - 0.1) < 1e-12 or np.max(np.abs(rec.torque)) < 0.1
    if cam is None:
        assert rec.valid_fraction() < 0.001
    else:
        assert rec.camera_fix_rate() == pytest.approx(cam, abs=0.5)
        assert rec.valid_fraction() > 0.95
        assert rec.meta["camera_backlog_end_t"] is not None
        assert np.abs(rec.theta[0]) < np.pi  # whole turns rebased
        assert rec.phi_dot is not None and np.isfinite(rec.phi_dot).mean() > 0.9


@needs_data
def test_step_response_runs_are_full_steps() -> None:
    log = parse_rig_log(DATA / "step_response_tau_001.txt", warn=False)
    for run in log.runs:
        t = run.column("t")
        assert t[0] == pytest.approx(5.0, abs=0.01) and t[-1] > 9.9
        assert np.all(run.column("torque") == 0.01)
        assert np.all(run.column("x") == 0) and np.all(run.column("y") == 0)


@needs_data
def test_fin_phi_estimator_jump_does_not_leak() -> None:
    """fin.txt logs phi ~0.07 (atan2 only) until the rig's estimator adds theta (~1005)."""
    log = parse_rig_log(DATA / "fin.txt", warn=False)
    raw_phi = log.runs[0].column("phi")
    assert raw_phi[0] < 1.0 and raw_phi[-1] > 1000.0
    rec = log.recording()
    v = rec.ball_valid
    assert np.all(np.abs(np.diff(rec.phi[v])) < 0.2)  # no ~1000 rad jump in our phi
    assert np.nanmax(np.abs(rec.phi)) < 50.0


# -- any rig of the design: timing measured on each run, never assumed ---------------------


def _synthetic_run(rate: float, fix_every: int, duration: float = 8.0, lag: float = 0.0,
                   pair: int = 0, backlog: int = 0, t0: float = 4.0) -> Recording:
    """A Recording as a rig logging at ``rate`` Hz with a fix every ``fix_every`` lines.

    The frame turns with a varying speed; ``dtheta`` is its exact rate ``lag`` seconds late;
    the log's phi pairs theta ``pair`` lines earlier; ``backlog`` fixes replayed one per
    line at the start.
    """
    t = t0 + np.arange(int(duration * rate)) / rate
    th = 300.0 + 2.0 * (t - t0) + 0.3 * np.sin(3.0 * (t - t0))

    def rate_of(tt: np.ndarray) -> np.ndarray:
        return 2.0 + 0.9 * np.cos(3.0 * (tt - t0))

    k = np.arange(t.size)
    fix = (k // fix_every) * fix_every
    if backlog:
        fix[:backlog] = k[:backlog]
    ang = 0.05 * np.sin(2.0 * t[fix])
    bx, by = 0.09 * np.sin(ang), 0.09 * np.cos(ang)
    phi = th[np.maximum(fix - pair, 0)] + ang
    return Recording(t=t, theta=th, theta_dot=rate_of(t - lag), torque=0.01 * np.sin(t),
                     ball_x=bx, ball_y=by, ball_valid=np.ones(t.size, bool), phi=phi)


@pytest.mark.parametrize("rate,fix_every", [(156.0, 1), (1000.0, 6), (300.0, 2)])
def test_any_line_rate_and_ratio_of_lines_to_fixes(tmp_path: Path, rate: float,
                                                   fix_every: int) -> None:
    """A log at 156 lines per second with a fix on every line keeps every fix (no start-up
    'backlog' invented); other rates and ratios too; the written text reads back."""
    from bfr_model.io.rig_log import write_rig_log  # noqa: PLC0415 - local to these tests

    rec = _synthetic_run(rate, fix_every)
    f = write_rig_log(tmp_path / "run.txt", rec)
    back = read_rig_log(f, warn=False)
    assert back.n == rec.n
    new = back.new_fix_mask()
    assert new.sum() == pytest.approx(rec.n / fix_every, abs=2)
    assert back.ball_valid.mean() > 0.99
    st = back.meta["sensor_timing"]
    assert st["line_rate_hz"] == pytest.approx(rate, rel=1e-3)
    assert st["lines_per_fix"] == pytest.approx(fix_every, rel=1e-2)
    assert st["backlog_fixes"] == 0
    np.testing.assert_allclose(back.theta, rec.theta - 2 * np.pi * 48, atol=1e-3)


def test_start_up_backlog_found_on_the_fixes_own_intervals(tmp_path: Path) -> None:
    from bfr_model.io.rig_log import write_rig_log  # noqa: PLC0415 - local to these tests

    rec = _synthetic_run(900.0, 6, backlog=600)
    back = read_rig_log(write_rig_log(tmp_path / "b.txt", rec), warn=False)
    assert back.meta["sensor_timing"]["backlog_fixes"] == pytest.approx(600, abs=7)
    assert not back.ball_valid[:590].any() and back.ball_valid[700:].all()


@needs_data
@pytest.mark.parametrize("keep", [2, 3, 6])
def test_start_up_backlog_of_a_log_under_twice_the_cameras_rate(tmp_path: Path,
                                                               keep: int) -> None:
    """fin.txt with every 2nd / 3rd / 6th line (461 / 307 / 154 lines a second, the camera
    165 Hz). At 307 the replay's fixes come one per line and the camera's one per 1.86: no
    interval under half of the median, and a probe's diagnosis had read the start-up replay
    as 0.9 s of valid fixes (camera scale 1.07, a contour and bumps): its end is found
    within two lines of the whole log's. At 154 every line brings a new fix, replayed or
    not: the times cannot show a backlog and none is assumed."""
    whole = read_rig_log(DATA / "fin.txt", warn=False)
    lines = (DATA / "fin.txt").read_text(errors="replace").splitlines()
    data = [k for k, ln in enumerate(lines) if "t=" in ln]
    kept = set(data[::keep])
    (tmp_path / "d.txt").write_text(
        "\n".join(ln for k, ln in enumerate(lines) if k in kept or "t=" not in ln) + "\n")
    back = read_rig_log(tmp_path / "d.txt", warn=False)
    end = back.meta["camera_backlog_end_t"]
    if keep < 6:
        dt = keep * float(np.median(np.diff(whole.t)))
        assert abs(end - whole.meta["camera_backlog_end_t"]) < 2 * dt, end
        assert back.ball_valid.mean() == pytest.approx(whole.ball_valid.mean(), abs=0.002)
    else:
        assert end is None and back.meta["sensor_timing"]["backlog_fixes"] == 0


@pytest.mark.parametrize("lag,pair", [(0.0, 0), (0.004, 3), (0.009, 8)])
def test_velocity_lag_and_phi_pairing_measured_per_run(tmp_path: Path, lag: float,
                                                       pair: int) -> None:
    """The lag of dtheta and the lines by which phi pairs theta are measured on each run
    (the NTNU rig's 6.4 ms and 8 lines are facts of that rig, not of the format)."""
    from bfr_model.io.rig_log import write_rig_log  # noqa: PLC0415 - local to these tests

    rec = _synthetic_run(1000.0, 5, lag=lag, pair=pair)
    back = read_rig_log(write_rig_log(tmp_path / "l.txt", rec), warn=False)
    vl = back.meta["sensor_timing"]["velocity_lag"]
    assert vl["identified"]
    assert vl["lag_s"] == pytest.approx(lag, abs=3e-4)
    assert back.meta["rig_conventions"]["phi_theta_lag_samples"] == pair


def test_several_short_runs_all_read(tmp_path: Path) -> None:
    from bfr_model.io.rig_log import write_rig_log  # noqa: PLC0415 - local to these tests

    runs = [_synthetic_run(900.0, 6, duration=0.7, t0=5.0) for _ in range(4)]
    log = parse_rig_log(write_rig_log(tmp_path / "s.txt", runs), warn=False)
    assert len(log.runs) == 4
    assert [len(r) for r in log.runs] == [r.n for r in runs]


def _lattice_log(counts: int, digits: int, n: int = 3000) -> str:
    """A rig log whose frame turns smoothly, its angle on ``counts`` steps a turn printed with
    ``digits`` significant digits (1 kHz lines, the ball seen throughout)."""
    t = 4.0 + 0.001 * np.arange(n)
    q = 2 * np.pi / counts
    theta = q * np.round((0.3 + 1.5 * np.sin(1.3 * (t - 4.0))) / q)
    return "\n".join("[inf] " + ",".join(
        f"{k}={v:.{digits}g}" for k, v in (("t", ti), ("torque", 0.01), ("theta", th),
                                           ("phi", th + 0.12), ("dtheta", 0.5), ("dphi", 0.4),
                                           ("x", 0.01), ("y", 0.08)))
        for ti, th in zip(t, theta, strict=True)) + "\n"


@pytest.mark.parametrize(("counts", "digits", "expected"), [
    (1024, 8, 2 * np.pi / 1024),   # a coarse encoder printed finely: its step, measured
    (4096, 8, 2 * np.pi / 4096),
    (65536, 6, None),              # a fine encoder: the print (6 digits) is the resolution
])
def test_encoder_lattice_is_measured_not_assumed(counts: int, digits: int,
                                                 expected: float | None) -> None:
    """The angle's resolution is the coarser of its print and the encoder's lattice, which the
    reader measures from the angle's changes (whole steps) and reports: a 1024-count encoder
    printed to 8 digits is not a 1e-7 rad one (that had made a clean recording's frame row
    6x its noise)."""
    log = parse_rig_log_text(_lattice_log(counts, digits))
    rec = log.recording(0)
    lattice = [c for c in rec.meta["conversions"] if "encoder lattice" in c]
    if expected is None:
        assert not lattice and rec.meta["theta_resolution"] == pytest.approx(1e-5)
    else:
        assert lattice and rec.meta["theta_resolution"] == pytest.approx(expected, rel=1e-6)


@needs_data
def test_ntnu_logs_are_read_at_their_print_resolution() -> None:
    """On the shipped logs no encoder lattice coarser than the print is seen."""
    for path in sorted(DATA.glob("*.txt")):
        rec = parse_rig_log(path, warn=False).recording(0)
        assert not [c for c in rec.meta["conversions"] if "encoder lattice" in c], path
        assert rec.meta["theta_resolution"] in (1e-3, 1e-2), path


def test_nan_frame_velocity_keeps_the_line() -> None:
    """A NaN in the servo's velocity column is a missing velocity sample: the line's angle,
    torque and camera fix are used, theta_dot is filled between its neighbours, and the
    notes and the account say how many and how."""
    rows = [line(4.0 + 0.001 * i, theta=1.0 + 0.002 * i, x=0.01 + 0.001 * (i // 5),
                 dtheta=0.5 + 0.01 * i) for i in range(40)]
    rows[10] = line(4.010, theta=1.02, x=0.012, dtheta=float("nan"), torque=0.03)
    rec = parse_rig_log_text("\n".join(rows) + "\n", "mem").recording(0)
    assert rec.n == 40 and rec.meta["read_account"]["dropped"] == {}
    assert rec.theta[10] == pytest.approx(1.02 - 2 * np.pi * 0) and rec.torque[10] == 0.03
    assert rec.new_fix_mask()[10] and rec.ball_x[10] == pytest.approx(0.012)
    assert rec.theta_dot[10] == pytest.approx(0.6)  # between 0.59 and 0.61
    assert any(n.startswith("1 sample(s) log dtheta (the servo's velocity) as NaN")
               and "interpolated linearly" in n for n in rec.meta["notes"])
    assert any(a.startswith("velocity_missing: 1 line(s)") and a.endswith("line 11")
               for a in rec.meta["read_account"]["actions"])


def test_nan_ball_and_rig_estimates_keep_the_line() -> None:
    """A camera that logs "no ball" as NaN, and NaN in the rig's own phi and dphi: the line's
    encoder and torque are kept (a frame-only recording whose camera writes NaN had lost every
    sample), the NaN fix reads as no ball, said in the notes."""
    lines = body(40)
    lines[10] = line(4.010, theta=1.02, x=float("nan"), y=float("nan"))
    lines[20] = line(4.020, theta=1.04, phi=float("nan"), dphi=float("nan"))
    log = parse_rig_log_text("\n".join(NOISE + lines) + "\n")
    rec = log.recording(0)
    assert rec.n == 40
    assert any("NaN: read as no ball" in n for n in rec.meta["notes"])
    assert np.all(np.isfinite(rec.theta)) and np.all(np.isfinite(rec.torque))


def test_epoch_stamps_read_as_the_same_log_from_zero(tmp_path: Path) -> None:
    """Stamps counting from the Unix epoch (t0 = 1.7e9 s) are rebased to the run's first
    stamp as they are read: the preprocessed timing (fix times on the grid, the camera
    clock, the frame's rate, the velocity lag) is that of the same log starting at 0 to
    well under 1 us (before: fix times 1.5 us apart, theta_dot 7e-4 rad/s). Through a whole
    diagnosis (a clean closed-loop recording, camera 12 ms late) the fitted camera latency
    moved by 0.604 ms at t0 = 1.7e9 s before, and moves by 12 ns now."""
    from bfr_diagnose.preprocess import PrepConfig, prepare  # noqa: PLC0415 - diagnosis level
    from bfr_model.io.rig_log import write_rig_log  # noqa: PLC0415 - local to these tests

    out = []
    for t0 in (0.0, 1.7e9):
        rec = _synthetic_run(900.0, 6, duration=6.0, lag=0.004, pair=3, t0=t0)
        back = read_rig_log(write_rig_log(tmp_path / f"{t0:.0f}.txt", rec, digits=17),
                            warn=False)
        assert back.t[0] == 0.0 and back.meta["time_origin_s"] == t0
        assert any("first stamp" in c for c in back.meta["conversions"]) == (t0 > 0)
        out.append((back, prepare(back, PrepConfig(), latency0=0.0)))
    (r0, p0), (r1, p1) = out
    np.testing.assert_allclose(p1.fixes.tf - p1.t[0], p0.fixes.tf - p0.t[0], rtol=0,
                               atol=1e-7)
    np.testing.assert_allclose(p1.theta_dot, p0.theta_dot, rtol=0, atol=1e-5)
    assert p1.info["camera_clock"]["period_s"] == pytest.approx(
        p0.info["camera_clock"]["period_s"], rel=1e-8)
    lag0 = r0.meta["sensor_timing"]["velocity_lag"]["lag_s"]
    assert r1.meta["sensor_timing"]["velocity_lag"]["lag_s"] == pytest.approx(lag0, abs=1e-6)


def _dialect_line(std: str, form: str, k: int) -> str:
    """``std`` (a data line of the NTNU rig's form) in another logger's form ``form``."""
    fields = dict(f.split("=", 1) for f in std.strip().removeprefix("[inf] ").split(","))
    order = list(fields)
    if form == "reordered":
        order = ["t", "x", "y", "theta", "dtheta", "phi", "dphi", "torque"]
    elif form == "extra_mid":
        fields["mode"], order = "2", ["t", "mode", *order[1:]]
    elif form == "extra_end":
        fields["u_ref"], order = f"{0.5 + k:g}", [*order, "u_ref"]
    sep = ", " if form == "spaces" else ","
    text = sep.join(f"{key}={fields[key]}" for key in order)
    prefix = {"none": "", "dbg": "[dbg] ",
              "stamped": f"2021-05-01 18:05:{19 + k // 1000:02d}.{k % 1000:03d} INFO "
              }.get(form, "[inf] ")
    return prefix + text + "\r"


@pytest.mark.parametrize("form", ["reordered", "extra_mid", "extra_end", "spaces", "none",
                                  "dbg", "stamped"])
def test_another_loggers_form_is_read_by_key_and_said(tmp_path: Path, form: str) -> None:
    """Another rig's logger: another tag or a time stamp before the fields, the keys in
    another order, spaces after the commas, fields of its own. Read by key into the same
    numbers as the NTNU rig's form; the recording says which form it read and which fields
    it did not use. Every run and its marker kept (two runs, clock restarting)."""
    runs = [body(300), body(200, t0=1.0)]
    std = "\n".join([*NOISE, *runs[0], "[inf] initializing hardware..\r", *runs[1]]) + "\n"
    k = iter(range(10 ** 6))
    other = "\n".join([*NOISE, *(_dialect_line(s, form, next(k)) for s in runs[0]),
                       "[inf] initializing hardware..\r",
                       *(_dialect_line(s, form, next(k)) for s in runs[1])]) + "\n"
    path = tmp_path / "other.txt"
    path.write_text(other)
    ref = parse_rig_log_text(std, "mem")
    for log in (parse_rig_log(path), parse_rig_log_text(other, "mem")):
        assert len(log.runs) == 2 and log.warnings == []
        for a, b in zip(log.runs, ref.runs, strict=True):
            np.testing.assert_array_equal(a.data, b.data)
        (said,) = log.conversions
        assert "read by key" in said
        assert ("mode" in said) is (form == "extra_mid")
        assert ("field(s) not used: u_ref" in said) is (form == "extra_end")
        assert ("time stamp" in said) is (form == "stamped")
    rec = read_rig_log(path, run=0)
    assert said in rec.meta["conversions"] and len(rec) == 300


def test_another_loggers_damaged_lines_are_accounted() -> None:
    """In another logger's form a damaged line is lost and counted as in the rig's: a value
    that is not a number, a field missing, the file's last line cut short."""
    lines = [_dialect_line(s, "extra_mid", 0) for s in body(40)]
    lines[10] = lines[10].replace("theta=", "theta=x", 1)
    lines[20] = lines[20].replace(",dphi=0.4", "")
    lines[-1] = lines[-1][:30]
    log = parse_rig_log_text("\n".join(lines) + "\n", "mem")
    acc = log.runs[0].account
    assert dict(acc.dropped) == {"corrupt": 2, "truncated": 1}
    assert acc.samples_used == 37
    assert any("mem:11: value of 'theta' is not a number" in w for w in log.warnings)
    assert any(w.startswith("mem:21: malformed data line skipped: fields t,mode,torque")
               for w in log.warnings), log.warnings
    assert any("mem:40: truncated final line" in w for w in log.warnings), log.warnings


def test_the_rig_form_stays_the_rule_beside_a_few_other_lines() -> None:
    """A log mostly in the NTNU rig's form is read by it; a few lines of another form among
    them are damaged lines (counted), not a reason to read the log otherwise."""
    lines = body(50)
    lines[5] = _dialect_line(lines[5], "reordered", 0)
    log = parse_rig_log_text("\n".join(lines) + "\n", "mem")
    assert log.conversions == [] and log.runs[0].account.samples_used == 49
    assert dict(log.runs[0].account.dropped) == {"corrupt": 1}


def test_a_loggers_form_read_through_its_edges() -> None:
    """The rig's form behind colour codes is the rig's (not "another form"); data lines of
    another form joined by a carriage return are each read; a time stamp that looked
    constant over the first 5000 lines and changes later is still a prefix (a second
    reader found: the colour codes named as another form, a joined line lost uncounted, 500
    lines of a new minute lost as malformed)."""
    rows = body(200)
    coloured = "\n".join(f"\x1b[32m{r.rstrip(chr(13))}\x1b[0m" for r in rows) + "\n"
    log = parse_rig_log_text(coloured, "mem")
    assert log.conversions == [] and log.runs[0].account.samples_used == 200
    other = [_dialect_line(r, "dbg", k).rstrip("\r") for k, r in enumerate(rows)]
    joined = [*other[:50], other[50] + "\r" + other[51], *other[52:]]
    log = parse_rig_log_text("\n".join(joined) + "\n", "mem")
    assert log.n_data == 200 and log.runs[0].account.samples_used == 200
    many = body(6000)
    stamped = [f"2021-05-01 18:0{5 + (k >= 5500)} INFO " + r.strip().removeprefix("[inf] ")
               for k, r in enumerate(many)]
    log = parse_rig_log_text("\n".join(stamped) + "\n", "mem")
    assert log.n_data == 6000 and "prefix '2021-05-01 18:05 INFO '" in log.conversions[0]


def test_a_log_at_the_cameras_rate_whose_camera_later_slows_has_no_backlog() -> None:
    """One new fix per line at the camera's rate, then the camera slower (or the ball lost
    for 3 s and then seen on every other line): no start-up replay, however the second half
    paces the fixes (a second reader's cases: 1502 and 1500 fixes had been dropped)."""
    from bfr_model.io.timing import camera_backlog_end  # noqa: PLC0415 - the rule under test

    line = 1 / 154
    first = np.arange(1200) * line
    assert camera_backlog_end(np.r_[first, first[-1] + np.cumsum(np.full(1183, 1.7 * line))],
                              line_period=line) == 0
    first = np.arange(1500) * line
    assert camera_backlog_end(np.r_[first, first[-1] + 3.0 + np.arange(520) * 2 * line],
                              line_period=line) == 0
