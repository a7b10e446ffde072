"""``bfr camera-eval``: the table and its JSON form (a few frames; figures, not speed)."""

from __future__ import annotations

import json

import pytest

from bfr_tools import camera_eval as evaluate


def test_json_has_every_figure_with_its_target(capsys: pytest.CaptureFixture[str]) -> None:
    status = evaluate.main(["--frames", "4", "--json", "--repeat", "1",
                            "--conditions", "clean,noise_blur,ball_free"])
    assert status == 0
    res = json.loads(capsys.readouterr().out)
    clean = res["conditions"]["clean"]
    for key in ("detection_rate", "error_px_median", "error_px_p99", "error_mm_median",
                "error_mm_p99", "render_ms", "detect_ms_roi", "detect_ms_full"):
        assert key in clean
    assert clean["detection_rate"] == 1.0
    assert clean["error_px_median"] < 0.1  # the target holds on these frames too
    free = res["conditions"]["ball_free"]
    assert free["false_detections_full"] == 0 and free["false_detections_roi"] == 0
    rows = {(r["condition"], r["metric"]): r for r in res["rows"]}
    assert rows[("clean", "error_px_median")]["target"] == "< 0.1 px"
    assert rows[("clean", "error_px_p99")]["met"] is True
    assert rows[("noise_blur", "error_px_median")]["target"] == "< 0.5 px"
    assert rows[("ball_free", "false_detections_full")]["met"] is True
    assert rows[("clean", "detect_ms_roi")]["target"] == "< 1 ms"
    assert rows[("clean", "render_ms")]["target"] == "< 2 ms"
    # the run is seeded: the same frames give the same errors
    evaluate.main(["--frames", "4", "--json", "--repeat", "1", "--conditions", "clean"])
    again = json.loads(capsys.readouterr().out)["conditions"]["clean"]
    assert again["error_px_median"] == clean["error_px_median"]


def test_table_and_example_images(tmp_path, capsys: pytest.CaptureFixture[str]) -> None:  # noqa: ANN001
    out_dir = tmp_path / "examples"
    args = ["--frames", "2", "--repeat", "1", "--conditions", "occluded", "--out-dir",
            str(out_dir)]
    assert evaluate.main(args) == 0
    out = capsys.readouterr().out
    assert "position error, median" in out and "detect time with ROI, median" in out
    assert (out_dir / "occluded.png").is_file()
    assert (out_dir / "occluded_annotated.png").is_file()
    # an existing folder is refused in one line and left as it was; --force replaces it
    (out_dir / "mine.txt").write_text("keep")
    assert evaluate.main(args) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "--force" in err, err
    assert (out_dir / "mine.txt").read_text() == "keep"
    assert evaluate.main([*args, "--force"]) == 0
    assert not (out_dir / "mine.txt").exists() and (out_dir / "occluded.png").is_file()
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]  # no temporaries


def test_usage_errors() -> None:
    with pytest.raises(SystemExit):
        evaluate.main(["--conditions", "sunny"])
    with pytest.raises(SystemExit):
        evaluate.main(["--frames", "0"])


def test_registered_in_the_bfr_command_line() -> None:
    from bfr_tools.cli import SUBCOMMANDS, load_subcommand  # noqa: PLC0415

    assert SUBCOMMANDS["camera-eval"][:2] == ("bfr_tools.camera_eval", "main")
    assert load_subcommand("camera-eval") is evaluate.main
